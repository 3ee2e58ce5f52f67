#pragma once
// General-purpose compressors as a floor for the world model (issue: "bits per token against xz and zstd"):
// a model that cannot beat xz -9 / zstd -19 on the same token stream has learned less than a dictionary coder.
#include <cstdint>
#include <string>
#include <vector>

namespace gaia::eval {

struct CompressedSize {
  std::string method;     // "xz -9e" or "zstd -19"
  size_t bytes = 0;
  double bits_per_token = 0;
};

// Compresses the tokens as little-endian int16 (the token dataset's own storage) with liblzma preset 9 |
// extreme and libzstd level 19, in memory.
CompressedSize xz_size(const std::vector<int16_t>& tokens);
CompressedSize zstd_size(const std::vector<int16_t>& tokens);

}  // namespace gaia::eval
