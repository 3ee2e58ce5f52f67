// Replay driver for the fuzz targets in an ordinary (g++, no libFuzzer) build, so CI exercises them cheaply:
//   gaia_fuzz_<name> CORPUS_DIR_OR_FILE... [--seconds N] [--seed S] [--max-iters N]
// (a) runs every corpus file through LLVMFuzzerTestOneInput; (b) for N seconds, runs deterministic mutations of
// the corpus (seeded, so "seed S, iteration I" reproduces a failure). Before a crash or an escaped exception
// ends the process, the input being run is written to replay-crash-<name>.bin in the working directory.
#include <algorithm>
#include <csignal>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

using Bytes = std::vector<uint8_t>;

// What the handlers need, kept in globals: the input now running and where to save it.
Bytes g_current;
std::string g_label = "corpus";  // file name or "seed S iteration I"
char g_crash_path[512] = "replay-crash.bin";
unsigned g_hang_seconds = 20;

// Async-signal-safe enough for a dying process: write(2) only.
void save_current() {
  int fd = ::open(g_crash_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd >= 0) {
    size_t off = 0;
    while (off < g_current.size()) {
      ssize_t n = ::write(fd, g_current.data() + off, g_current.size() - off);
      if (n <= 0) break;
      off += static_cast<size_t>(n);
    }
    ::close(fd);
  }
  const char* parts[] = {"gaia fuzz replay: failing input (", g_label.c_str(), ") written to ", g_crash_path, "\n"};
  for (const char* s : parts) (void)!::write(2, s, std::strlen(s));
}

void on_signal(int sig) {
  if (sig == SIGALRM) (void)!::write(2, "gaia fuzz replay: input ran too long (hang)\n", 44);
  save_current();
  std::signal(sig, SIG_DFL);
  if (sig == SIGALRM) std::_Exit(124);
  std::raise(sig);
}

void on_terminate() {
  if (auto e = std::current_exception()) {
    try {
      std::rethrow_exception(e);
    } catch (const std::exception& x) {
      std::fprintf(stderr, "gaia fuzz replay: uncaught exception: %s\n", x.what());
    } catch (...) {
      std::fprintf(stderr, "gaia fuzz replay: uncaught non-std exception\n");
    }
  }
  save_current();
  std::signal(SIGABRT, SIG_DFL);  // already saved; the abort handler need not say it again
  std::abort();
}

void run(const Bytes& in, std::string label) {
  g_current = in;
  g_label = std::move(label);
  ::alarm(g_hang_seconds);
  LLVMFuzzerTestOneInput(g_current.data(), g_current.size());
  ::alarm(0);
}

Bytes read_bytes(const std::filesystem::path& p) {
  std::ifstream f(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

// One random edit of the kinds that break parsers: bit flips, boundary values, inserts, deletes, truncation,
// duplicated ranges, splices with another corpus entry, and ASCII digit runs (lengths and shapes in text headers).
void mutate(Bytes& b, const std::vector<Bytes>& corpus, std::mt19937_64& rng) {
  auto pick = [&](size_t n) { return n ? static_cast<size_t>(rng() % n) : 0; };
  static const uint64_t kInteresting[] = {0, 1, 0x7f, 0x80, 0xff, 0x7fff, 0xffff, 0x7fffffff, 0xffffffff,
                                          0x7fffffffffffffffull, 0xffffffffffffffffull, 0x8000000000000000ull};
  static const char* kTokens[] = {"0", "-1", "18446744073709551615", "99999999999999999999", "1e400", "nan",
                                  "\"", ",", "\n", "[", "]", "{", "}", ":", "'", "(", ")", "null", "\xff"};
  switch (rng() % 9) {
    case 0:
      if (!b.empty()) b[pick(b.size())] ^= static_cast<uint8_t>(1u << (rng() % 8));
      break;
    case 1:
      if (!b.empty()) b[pick(b.size())] = static_cast<uint8_t>(rng());
      break;
    case 2: {  // a little-endian boundary value of width 1, 2, 4 or 8
      const uint64_t v = kInteresting[pick(std::size(kInteresting))];
      const size_t w = size_t(1) << (rng() % 4), at = pick(b.size() + 1);
      for (size_t i = 0; i < w; ++i) {
        if (at + i < b.size()) b[at + i] = static_cast<uint8_t>(v >> (8 * i));
      }
      break;
    }
    case 3: b.insert(b.begin() + static_cast<std::ptrdiff_t>(pick(b.size() + 1)), static_cast<uint8_t>(rng())); break;
    case 4:
      if (!b.empty()) {
        const size_t at = pick(b.size()), n = 1 + pick(std::min<size_t>(16, b.size() - at));
        b.erase(b.begin() + static_cast<std::ptrdiff_t>(at), b.begin() + static_cast<std::ptrdiff_t>(at + n));
      }
      break;
    case 5: b.resize(pick(b.size() + 1)); break;
    case 6:
      if (!b.empty()) {  // duplicate a range (repeated rows, nested brackets)
        const size_t at = pick(b.size()), n = 1 + pick(std::min<size_t>(64, b.size() - at));
        const Bytes piece(b.begin() + static_cast<std::ptrdiff_t>(at), b.begin() + static_cast<std::ptrdiff_t>(at + n));
        b.insert(b.begin() + static_cast<std::ptrdiff_t>(pick(b.size() + 1)), piece.begin(), piece.end());
      }
      break;
    case 7: {  // splice: our head, another entry's tail
      const Bytes& o = corpus[pick(corpus.size())];
      const size_t cut = pick(b.size() + 1), from = pick(o.size() + 1);
      b.resize(cut);
      b.insert(b.end(), o.begin() + static_cast<std::ptrdiff_t>(from), o.end());
      break;
    }
    default: {
      const char* t = kTokens[pick(std::size(kTokens))];
      b.insert(b.begin() + static_cast<std::ptrdiff_t>(pick(b.size() + 1)), t, t + std::strlen(t));
    }
  }
  if (b.size() > (1u << 16)) b.resize(1u << 16);  // keep inputs small, as libFuzzer's -max_len would
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 0;
  uint64_t seed = 1, max_iters = UINT64_MAX;
  std::vector<std::filesystem::path> inputs;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if ((a == "--seconds" || a == "--seed" || a == "--max-iters") && i + 1 < argc) {
      const char* v = argv[++i];
      if (a == "--seconds") seconds = std::atof(v);
      else if (a == "--seed") seed = std::strtoull(v, nullptr, 10);
      else max_iters = std::strtoull(v, nullptr, 10);
    } else if (!a.empty() && a[0] == '-') {
      std::fprintf(stderr, "usage: %s CORPUS_DIR_OR_FILE... [--seconds N] [--seed S] [--max-iters N]\n", argv[0]);
      return 2;
    } else {
      inputs.push_back(a);
    }
  }
  std::snprintf(g_crash_path, sizeof g_crash_path, "replay-crash-%s.bin",
                std::filesystem::path(argv[0]).filename().c_str());
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // progress lines survive a crash
  std::set_terminate(on_terminate);
  // The handlers run on their own stack, so a stack overflow (deep recursion in a parser) is reported too.
  static std::vector<char> alt(1 << 16);
  stack_t ss{};
  ss.ss_sp = alt.data();
  ss.ss_size = alt.size();
  sigaltstack(&ss, nullptr);
  for (int sig : {SIGSEGV, SIGABRT, SIGFPE, SIGBUS, SIGILL, SIGALRM}) {
    struct sigaction sa {};
    sa.sa_handler = on_signal;
    sa.sa_flags = SA_ONSTACK;
    sigaction(sig, &sa, nullptr);
  }

  // (a) the corpus, in a fixed (sorted) order
  std::vector<std::filesystem::path> files;
  for (const auto& p : inputs) {
    if (std::filesystem::is_directory(p)) {
      for (const auto& e : std::filesystem::directory_iterator(p))
        if (e.is_regular_file()) files.push_back(e.path());
    } else if (std::filesystem::is_regular_file(p)) {
      files.push_back(p);
    } else {
      std::fprintf(stderr, "gaia fuzz replay: %s: no such file or directory\n", p.c_str());
      return 2;
    }
  }
  std::sort(files.begin(), files.end());
  std::vector<Bytes> corpus;
  for (const auto& f : files) {
    corpus.push_back(read_bytes(f));
    run(corpus.back(), f.string());
  }
  std::printf("gaia fuzz replay: %zu corpus files ok\n", corpus.size());
  if (corpus.empty()) corpus.emplace_back();

  // (b) seeded mutations for a bounded time; iteration i depends only on the seed, never on the clock
  std::mt19937_64 rng(seed);
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  uint64_t it = 0;
  for (; it < max_iters && seconds > 0 && std::chrono::steady_clock::now() < end; ++it) {
    Bytes b = corpus[rng() % corpus.size()];
    const int edits = 1 + static_cast<int>(rng() % 8);
    for (int e = 0; e < edits; ++e) mutate(b, corpus, rng);
    run(b, "seed " + std::to_string(seed) + " iteration " + std::to_string(it));
  }
  std::printf("gaia fuzz replay: %llu mutated inputs ok (seed %llu)\n", static_cast<unsigned long long>(it),
              static_cast<unsigned long long>(seed));
  return 0;
}
