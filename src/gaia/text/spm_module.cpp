// libgaia_spm: Debian's SentencePiece behind a C interface, loaded by text/sentencepiece.cpp with dlopen. Debian's
// libsentencepiece carries its own protobuf (3.14) and exports its symbols, while LibTorch loads the system
// libprotobuf (3.21): linked into one program the two bind to each other's functions and it crashes at start-up.
// Loaded into a link namespace of its own (dlmopen), SentencePiece keeps to its own copy. Only plain C data crosses
// the boundary; what the module allocates, it frees.
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include <sentencepiece_processor.h>
#include <sentencepiece_trainer.h>

namespace {
void put_error(const std::string& what, char* err, size_t n) {
  if (err && n) {
    std::strncpy(err, what.c_str(), n - 1);
    err[n - 1] = '\0';
  }
}
}  // namespace

extern "C" {

// A loaded model, or null with the reason in err.
void* gaia_spm_load(const char* model, char* err, size_t n) {
  auto* sp = new sentencepiece::SentencePieceProcessor();
  if (const auto st = sp->Load(model); !st.ok()) {
    put_error(st.ToString(), err, n);
    delete sp;
    return nullptr;
  }
  return sp;
}

void gaia_spm_free(void* sp) { delete static_cast<sentencepiece::SentencePieceProcessor*>(sp); }

// [pieces, pad id, </s> id, unknown id]
void gaia_spm_info(void* h, int64_t out[4]) {
  auto* sp = static_cast<sentencepiece::SentencePieceProcessor*>(h);
  out[0] = sp->GetPieceSize();
  out[1] = sp->pad_id();
  out[2] = sp->eos_id();
  out[3] = sp->unk_id();
}

// The ids of `text`: their count (written up to `cap` of them), or -1 with the reason in err.
int64_t gaia_spm_encode(void* h, const char* text, int64_t* ids, int64_t cap, char* err, size_t n) {
  std::vector<int> v;
  if (const auto st = static_cast<sentencepiece::SentencePieceProcessor*>(h)->Encode(text, &v); !st.ok()) {
    put_error(st.ToString(), err, n);
    return -1;
  }
  for (size_t i = 0; i < v.size() && int64_t(i) < cap; ++i) ids[i] = v[i];
  return int64_t(v.size());
}

// spm_train's flags in one string ("--input=... --model_prefix=..."): 0, or -1 with the reason in err.
int gaia_spm_train(const char* args, char* err, size_t n) {
  if (const auto st = sentencepiece::SentencePieceTrainer::Train(args); !st.ok()) {
    put_error(st.ToString(), err, n);
    return -1;
  }
  return 0;
}

}  // extern "C"
