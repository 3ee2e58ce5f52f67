#include "gaia/eval/compress.h"

#include <lzma.h>
#include <zstd.h>

#include "gaia/core/error.h"

namespace gaia::eval {

namespace {

std::vector<uint8_t> le_bytes(const std::vector<int16_t>& t) {
  std::vector<uint8_t> b(t.size() * 2);
  for (size_t i = 0; i < t.size(); ++i) {
    auto u = static_cast<uint16_t>(t[i]);
    b[2 * i] = static_cast<uint8_t>(u & 0xff);
    b[2 * i + 1] = static_cast<uint8_t>(u >> 8);
  }
  return b;
}

CompressedSize make(const char* method, size_t bytes, size_t tokens) {
  return {method, bytes, tokens ? 8.0 * double(bytes) / double(tokens) : 0.0};
}

}  // namespace

CompressedSize xz_size(const std::vector<int16_t>& tokens) {
  auto in = le_bytes(tokens);
  std::vector<uint8_t> out(lzma_stream_buffer_bound(in.size()));
  size_t pos = 0;
  lzma_ret r = lzma_easy_buffer_encode(9 | LZMA_PRESET_EXTREME, LZMA_CHECK_NONE, nullptr, in.data(), in.size(),
                                       out.data(), &pos, out.size());
  if (r != LZMA_OK) fail("xz compression failed (liblzma error {})", static_cast<int>(r));
  return make("xz -9e", pos, tokens.size());
}

CompressedSize zstd_size(const std::vector<int16_t>& tokens) {
  auto in = le_bytes(tokens);
  std::vector<uint8_t> out(ZSTD_compressBound(in.size()));
  size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), 19);
  if (ZSTD_isError(n)) fail("zstd compression failed ({})", ZSTD_getErrorName(n));
  return make("zstd -19", n, tokens.size());
}

}  // namespace gaia::eval
