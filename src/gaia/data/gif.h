#pragma once
// Animated GIF writer (GIF89a, LZW), for previews that play anywhere, including inline in the HTML report.
// Colours are mapped to a fixed 6 x 7 x 6 RGB palette (252 entries; 7 levels of green, to which the eye is most
// sensitive) with 4x4 ordered dithering, which keeps frames independent (no per-frame palette flicker).
#include <vector>

#include <opencv2/core.hpp>

#include "gaia/core/fs.h"

namespace gaia::data {

// frames: CV_8UC3 BGR, all the same size; fps > 0; loops forever. Written atomically.
void write_gif(const fs::path& path, const std::vector<cv::Mat>& frames, double fps);

// The palette index of a BGR pixel at (x, y) (exposed for tests), and the palette colour of an index.
uint8_t gif_palette_index(const cv::Vec3b& bgr, int x, int y);
cv::Vec3b gif_palette_color(uint8_t index);

}  // namespace gaia::data
