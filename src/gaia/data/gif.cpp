#include "gaia/data/gif.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "gaia/core/error.h"

namespace gaia::data {

namespace {

constexpr int kLevels[3] = {6, 7, 6};  // R, G, B
// 4x4 Bayer matrix, thresholds in (0, 1).
constexpr int kBayer[4][4] = {{0, 8, 2, 10}, {12, 4, 14, 6}, {3, 11, 1, 9}, {15, 7, 13, 5}};

// LZW codes packed least-significant bit first, emitted in sub-blocks of at most 255 bytes.
class BitWriter {
 public:
  explicit BitWriter(std::string* out) : out_(out) {}
  void put(int code, int bits) {
    acc_ |= uint32_t(code) << nbits_;
    nbits_ += bits;
    while (nbits_ >= 8) {
      byte(uint8_t(acc_ & 0xff));
      acc_ >>= 8;
      nbits_ -= 8;
    }
  }
  void finish() {
    if (nbits_ > 0) byte(uint8_t(acc_ & 0xff));
    acc_ = 0;
    nbits_ = 0;
    flush_block();
    out_->push_back('\0');  // block terminator
  }

 private:
  void byte(uint8_t b) {
    block_.push_back(char(b));
    if (block_.size() == 255) flush_block();
  }
  void flush_block() {
    if (block_.empty()) return;
    out_->push_back(char(block_.size()));
    out_->append(block_);
    block_.clear();
  }
  std::string* out_;
  std::string block_;
  uint32_t acc_ = 0;
  int nbits_ = 0;
};

// LZW as giflib does it: the code width grows after a code is written once the next free code reaches 2^width,
// and the table is cleared when it would pass 4095.
void lzw(const std::vector<uint8_t>& px, std::string* out) {
  const int min_size = 8, clear = 1 << min_size, eoi = clear + 1;
  out->push_back(char(min_size));
  BitWriter w(out);
  std::unordered_map<uint32_t, int> dict;
  int bits = min_size + 1, next = eoi + 1;
  w.put(clear, bits);
  int prefix = px.empty() ? -1 : px[0];
  for (size_t i = 1; i < px.size(); ++i) {
    const uint32_t key = (uint32_t(prefix) << 8) | px[i];
    auto it = dict.find(key);
    if (it != dict.end()) {
      prefix = it->second;
      continue;
    }
    w.put(prefix, bits);
    if (next >= (1 << bits) && bits < 12) ++bits;
    if (next >= 4095) {
      w.put(clear, bits);
      dict.clear();
      bits = min_size + 1;
      next = eoi + 1;
    } else {
      dict[key] = next++;
    }
    prefix = px[i];
  }
  if (prefix >= 0) {
    w.put(prefix, bits);
    if (next >= (1 << bits) && bits < 12) ++bits;
  }
  w.put(eoi, bits);
  w.finish();
}

void u16(std::string* s, int v) {
  s->push_back(char(v & 0xff));
  s->push_back(char((v >> 8) & 0xff));
}

}  // namespace

uint8_t gif_palette_index(const cv::Vec3b& bgr, int x, int y) {
  const double th = (kBayer[y & 3][x & 3] + 0.5) / 16.0;
  int q[3];
  const uint8_t rgb[3] = {bgr[2], bgr[1], bgr[0]};
  for (int c = 0; c < 3; ++c) {
    const double v = rgb[c] / 255.0 * (kLevels[c] - 1);  // position between palette levels
    q[c] = std::min(kLevels[c] - 1, int(std::floor(v)) + ((v - std::floor(v)) > th ? 1 : 0));
  }
  return uint8_t((q[0] * kLevels[1] + q[1]) * kLevels[2] + q[2]);
}

cv::Vec3b gif_palette_color(uint8_t index) {
  const int b = index % kLevels[2], g = (index / kLevels[2]) % kLevels[1], r = index / (kLevels[1] * kLevels[2]);
  auto lv = [](int q, int n) { return uint8_t(std::lround(255.0 * q / (n - 1))); };
  return {lv(b, kLevels[2]), lv(g, kLevels[1]), lv(r, kLevels[0])};
}

void write_gif(const fs::path& path, const std::vector<cv::Mat>& frames, double fps) {
  if (frames.empty()) fail("{}: no frames to write", path.string());
  if (!(fps > 0)) fail("{}: frame rate must be positive", path.string());
  const int W = frames[0].cols, H = frames[0].rows;
  if (W > 65535 || H > 65535) fail("{}: {}x{} is too large for GIF", path.string(), W, H);
  std::string s = "GIF89a";
  u16(&s, W);
  u16(&s, H);
  s.push_back(char(0xF7));  // global colour table, 8 bits colour resolution, 256 entries
  s.push_back('\0');        // background colour index
  s.push_back('\0');        // pixel aspect ratio
  for (int i = 0; i < 256; ++i) {
    cv::Vec3b c = i < kLevels[0] * kLevels[1] * kLevels[2] ? gif_palette_color(uint8_t(i)) : cv::Vec3b(0, 0, 0);
    s.push_back(char(c[2]));
    s.push_back(char(c[1]));
    s.push_back(char(c[0]));
  }
  // NETSCAPE2.0 application extension: loop forever.
  s += std::string("\x21\xFF\x0BNETSCAPE2.0\x03\x01\x00\x00\x00", 19);
  const int delay = std::max(2, int(std::lround(100.0 / fps)));  // centiseconds; many players clamp < 2
  std::vector<uint8_t> px(size_t(W) * H);
  for (const auto& f : frames) {
    if (f.cols != W || f.rows != H || f.type() != CV_8UC3)
      fail("{}: every frame must be {}x{} BGR (got {}x{})", path.string(), W, H, f.cols, f.rows);
    s += std::string("\x21\xF9\x04\x04", 4);  // graphic control extension, disposal: do not dispose
    u16(&s, delay);
    s += std::string("\x00\x00", 2);
    s.push_back(',');  // image descriptor
    u16(&s, 0);
    u16(&s, 0);
    u16(&s, W);
    u16(&s, H);
    s.push_back('\0');
    for (int y = 0; y < H; ++y) {
      const auto* row = f.ptr<cv::Vec3b>(y);
      for (int x = 0; x < W; ++x) px[size_t(y) * W + x] = gif_palette_index(row[x], x, y);
    }
    lzw(px, &s);
  }
  s.push_back(';');
  write_file_atomic(path, s);
}

}  // namespace gaia::data
