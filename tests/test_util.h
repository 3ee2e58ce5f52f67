#pragma once
// Shared test helpers: a scratch directory per test, running the gaia binary, and locating the real clips.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gaia/core/error.h"
#include "gaia/core/fs.h"
#include "gaia/synth/synth.h"

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

// Episodes first .. first + count - 1 of a small procedural dataset (32x64 by default, the tiny config's size).
inline void synth_dataset(const fs::path& dir, int count, double seconds, int first = 0, int height = 32, int width = 64) {
  synth::SynthOptions o;
  o.height = height;
  o.width = width;
  o.seconds = seconds;
  o.seed = 5;
  for (int e = first; e < first + count; ++e) synth::write_episode(dir, o, e);
}

struct RunResult {
  int status = -1;
  std::string output;  // stdout and stderr together
};

// Runs `gaia ARGS` through the shell and captures its output and exit code.
inline RunResult run_gaia(const std::string& args) {
  std::string cmd = std::string("'") + GAIA_BINARY + "' " + args + " 2>&1";
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

// The shared real driving clips live beside the repository (../shared/data/real); GAIA_REAL_DATA overrides.
inline fs::path real_data_dir() {
  if (const char* env = std::getenv("GAIA_REAL_DATA")) return env;
  for (fs::path p = source_dir(); !p.empty() && p != p.root_path(); p = p.parent_path())
    if (fs::exists(p / "shared" / "data" / "real")) return p / "shared" / "data" / "real";
  return {};
}

}  // namespace gaia::test
