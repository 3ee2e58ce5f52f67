#include "gaia/text/sentencepiece.h"

#ifndef _GNU_SOURCE
#define _GNU_SOURCE  // dlmopen
#endif
#include <dlfcn.h>

#include <mutex>

#include "gaia/core/error.h"

namespace gaia::text {

namespace {

struct Module {
  void* (*load)(const char*, char*, size_t) = nullptr;
  void (*free)(void*) = nullptr;
  void (*info)(void*, int64_t*) = nullptr;
  int64_t (*encode)(void*, const char*, int64_t*, int64_t, char*, size_t) = nullptr;
  int (*train)(const char*, char*, size_t) = nullptr;
};

// Beside the running binary (gaia, gaia_tests, the benches), else where the build put it.
fs::path module_path() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec && fs::exists(exe.parent_path() / "libgaia_spm.so")) return exe.parent_path() / "libgaia_spm.so";
#ifdef GAIA_SPM_MODULE
  return GAIA_SPM_MODULE;
#else
  return "libgaia_spm.so";
#endif
}

const Module& module() {
  static Module m;
  static std::once_flag once;
  static std::string error;
  std::call_once(once, [] {
    const fs::path p = module_path();
    // A link namespace of its own: SentencePiece and everything it loads see none of LibTorch's libraries.
    void* h = dlmopen(LM_ID_NEWLM, p.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!h) {
      error = fmt::format("SentencePiece (T5's tokenizer) is not available: {} ({}); build gaia with "
                          "libsentencepiece-dev installed", p.string(), dlerror());
      return;
    }
    m.load = reinterpret_cast<decltype(m.load)>(dlsym(h, "gaia_spm_load"));
    m.free = reinterpret_cast<decltype(m.free)>(dlsym(h, "gaia_spm_free"));
    m.info = reinterpret_cast<decltype(m.info)>(dlsym(h, "gaia_spm_info"));
    m.encode = reinterpret_cast<decltype(m.encode)>(dlsym(h, "gaia_spm_encode"));
    m.train = reinterpret_cast<decltype(m.train)>(dlsym(h, "gaia_spm_train"));
    if (!m.load || !m.free || !m.info || !m.encode || !m.train) {
      error = fmt::format("{}: not gaia's SentencePiece module (a function is missing)", p.string());
      m = Module{};
    }
  });
  if (!m.load) fail("{}", error);
  return m;
}

}  // namespace

SentencePiece::SentencePiece(const fs::path& model) : path_(model) {
  if (!fs::exists(model)) fail("{}: no such SentencePiece model", model.string());
  const Module& m = module();
  char err[512] = {0};
  handle_ = m.load(model.c_str(), err, sizeof err);
  if (!handle_) fail("{}: not a SentencePiece model ({})", model.string(), err);
  int64_t info[4];
  m.info(handle_, info);
  size_ = info[0];
  pad_ = info[1];
  eos_ = info[2];
  unk_ = info[3];
}

SentencePiece::~SentencePiece() {
  if (handle_) module().free(handle_);
}

std::vector<int64_t> SentencePiece::encode(const std::string& text) const {
  const Module& m = module();
  std::vector<int64_t> ids(text.size() + 8);  // pieces are at least a byte, but for a few specials
  char err[512] = {0};
  for (;;) {
    const int64_t n = m.encode(handle_, text.c_str(), ids.data(), int64_t(ids.size()), err, sizeof err);
    if (n < 0) fail("{}: cannot encode '{}' ({})", path_.string(), text, err);
    if (n <= int64_t(ids.size())) {
      ids.resize(size_t(n));
      return ids;
    }
    ids.resize(size_t(n));
  }
}

void SentencePiece::train(const std::string& flags) {
  char err[512] = {0};
  if (module().train(flags.c_str(), err, sizeof err) != 0) fail("SentencePiece training failed: {}", err);
}

}  // namespace gaia::text
