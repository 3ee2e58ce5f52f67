#pragma once
// Helpers shared by the fuzz targets. Most gaia parsers take a path, so each input is written to one
// per-process temp file, reused for every input so a long run does not litter /tmp.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

namespace gaia_fuzz {

class TempFile {
 public:
  explicit TempFile(const std::string& name)
      : path_(std::filesystem::temp_directory_path() / ("gaia-fuzz-" + std::to_string(::getpid()) + "-" + name)) {}
  ~TempFile() { std::error_code ec; std::filesystem::remove(path_, ec); }
  const std::filesystem::path& path() const { return path_; }
  const std::filesystem::path& write(const void* data, size_t size) {
    FILE* f = std::fopen(path_.c_str(), "wb");
    // A failing write is the harness's problem, not the parser's: stop loudly rather than fuzz nothing.
    if (!f || (size && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) std::abort();
    return path_;
  }

 private:
  std::filesystem::path path_;
};

// A property the harness checks beyond "no crash" (e.g. a round trip) failed: report and abort so it counts.
[[noreturn]] inline void property_failed(const char* what, const char* detail) {
  std::fprintf(stderr, "gaia fuzz: property failed: %s (%s)\n", what, detail);
  std::abort();
}

}  // namespace gaia_fuzz
