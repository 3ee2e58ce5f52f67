#pragma once
// Shared test helpers: a scratch directory per test, running the gaia binary, and locating the real clips.
// The test files compile in batches (GAIA_UNITY_BUILD): a helper two files need lives here, and a file's own helpers
// (and `using` lines) must not clash with another file's names.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <cstdio>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/core/error.h"
#include "gaia/core/fs.h"
#ifndef GAIA_NO_VIDEO
#include "gaia/synth/synth.h"
#endif

namespace gaia::test {

// A fresh directory under the system temp dir, removed when the object dies.
struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() / ("gaia-test-" + unique_suffix() + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  fs::path operator/(const std::string& s) const { return path / s; }
};

// Two float computations of one quantity that sum in another order or on other kernels (another batch size, a
// cache against one causal square, AVX2 against AVX-512) agree to within the unit roundoff u of their dtype times
// the length n of the longest reduction behind each value (the n*u of the standard error bound of a sum), times the
// size of the values (`scale`) and the number of such reductions stacked one on another (`depth`: layers).
// Bit-equality is asserted only where the same kernels see the same shapes.
inline constexpr double kFloat32Roundoff = 0x1p-24, kBf16Roundoff = 0x1p-8;
inline double sum_tolerance(double roundoff, long long n, double scale, int depth = 1) {
  return roundoff * double(n) * scale * double(depth);
}

// The device the model tests run on: GAIA_TEST_DEVICE (cpu, cuda, cuda:N; scripts/gpu-check.sh sets cuda), else
// the CPU.
inline std::string device_name() {
  const char* d = std::getenv("GAIA_TEST_DEVICE");
  return d && *d ? d : "cpu";
}

#ifndef GAIA_NO_VIDEO
// Episodes first .. first + count - 1 of a small procedural dataset (32x64 by default, the tiny config's size).
inline void synth_dataset(const fs::path& dir, int count, double seconds, int first = 0, int height = 32, int width = 64) {
  synth::SynthOptions o;
  o.height = height;
  o.width = width;
  o.seconds = seconds;
  o.seed = 5;
  for (int e = first; e < first + count; ++e) synth::write_episode(dir, o, e);
}
#endif

// A path quoted for the shell command lines run_gaia takes.
inline std::string q(const fs::path& p) { return "'" + p.string() + "'"; }

// The test tiers (ctest labels, set in CMakeLists.txt): a test that runs the gaia binary lives in a suite named
// *Cli (label cli) or *Slow (label slow); every other suite is label unit, so `ctest -L unit` never spawns it.
inline bool may_run_binary() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  if (!info) return true;  // a global environment
  const std::string s = info->test_suite_name();
  auto ends = [&](const std::string& suffix) {
    return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
  };
  return ends("Cli") || ends("Slow");
}

struct RunResult {
  int status = -1;
  std::string output;  // stdout and stderr together
};

// Runs a shell command line and captures what it prints (add 2>&1 for stderr) and its exit code.
inline RunResult run_shell(const std::string& cmd) {
  RunResult r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  std::array<char, 4096> buf{};
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) r.output.append(buf.data(), n);
  int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

// `'gaia' ARGS` for a shell command line (a test that wraps the binary: ulimit, unshare).
inline std::string gaia_command(const std::string& args) {
  if (!may_run_binary())
    ADD_FAILURE() << "a unit test runs the gaia binary: move it to a suite named *Cli or *Slow (see test_util.h)";
  return std::string("'") + GAIA_BINARY + "' " + args;
}

// Runs `gaia ARGS` through the shell and captures its output (stdout and stderr together) and exit code.
inline RunResult run_gaia(const std::string& args) { return run_shell(gaia_command(args) + " 2>&1"); }

// The message of the gaia::Error that f throws, or "" if it throws none.
inline std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// One number per line of a metrics.jsonl (training runs write one JSON object per step): the field `key` of each.
inline std::vector<double> jsonl_numbers(const fs::path& metrics, const std::string& key) {
  std::vector<double> out;
  std::istringstream in(read_file(metrics));
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) out.push_back(nlohmann::json::parse(line).at(key).get<double>());
  return out;
}

inline fs::path source_dir() { return fs::path(GAIA_SOURCE_DIR); }

// A directory that `build` fills once and every test process then shares read-only (a trained tiny tokenizer, a
// token dataset): ctest runs each test in its own process, and rebuilding such inputs in each was most of the
// suite's time. The first process to ask builds it under an exclusive lock while the others wait; it is built again
// when the gaia binary is newer than it. Tests write their outputs elsewhere (a TempDir).
inline fs::path shared_fixture(const std::string& name, const std::function<void(const fs::path&)>& build) {
  const fs::path root = GAIA_TEST_FIXTURE_DIR;
  fs::create_directories(root);
  const fs::path dir = root / name, stamp = dir / ".built-for";
  struct stat st{};
  const std::string binary = ::stat(GAIA_BINARY, &st) == 0 ? std::to_string(st.st_mtim.tv_sec) + "." +
                                                                std::to_string(st.st_mtim.tv_nsec) + " " + std::to_string(st.st_size)
                                                          : "none";
  const int fd = ::open((root / (name + ".lock")).c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0644);
  if (fd < 0 || ::flock(fd, LOCK_EX) != 0) throw std::runtime_error("cannot lock the test fixture " + dir.string());
  struct Unlock {
    int fd;
    ~Unlock() { ::close(fd); }  // closing drops the lock
  } unlock{fd};
  if (fs::exists(stamp) && read_file(stamp) == binary) return dir;
  fs::remove_all(dir);
  fs::create_directories(dir);
  build(dir);
  write_file_atomic(stamp, binary);
  return dir;
}

// The shared real driving clips live beside the repository (../shared/data/real); GAIA_REAL_DATA overrides.
inline fs::path real_data_dir() {
  if (const char* env = std::getenv("GAIA_REAL_DATA")) return env;
  for (fs::path p = source_dir(); !p.empty() && p != p.root_path(); p = p.parent_path())
    if (fs::exists(p / "shared" / "data" / "real")) return p / "shared" / "data" / "real";
  return {};
}

// A config of the repository's configs/ (tiny.yaml, ...).
inline Config config(const std::string& name) { return Config::load(source_dir() / "configs" / name); }

// ||a - b|| / ||b||: how far a computation is from its peer's.
inline double rel_err(const torch::Tensor& a, const torch::Tensor& b) {
  return ((a - b).norm() / (b.norm() + 1e-12)).item<double>();
}

// How many times `needle` occurs in `hay` (overlapping occurrences counted).
inline int occurrences(const std::string& hay, const std::string& needle) {
  int n = 0;
  for (size_t at = hay.find(needle); at != std::string::npos; at = hay.find(needle, at + 1)) ++n;
  return n;
}

// Exactly one line that starts with "gaia: error:" and names `what`; exit status `status` (any non-zero if 0).
inline void expect_one_error_line(const RunResult& r, const std::string& what, int status = 0) {
  if (status) {
    EXPECT_EQ(r.status, status) << r.output;
  }
  EXPECT_NE(r.status, 0) << r.output;
  EXPECT_EQ(r.output.rfind("gaia: error: ", 0), 0u) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_NE(r.output.find(what), std::string::npos) << "wanted '" << what << "' in: " << r.output;
}

}  // namespace gaia::test
