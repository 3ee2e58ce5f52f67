// GIF writer: the file decodes in FFmpeg (a peer implementation) to exactly the palette colours we chose.
#include <opencv2/core.hpp>

#include <cstdio>
#include <random>

#include "gaia/data/gif.h"
#include "test_util.h"

using namespace gaia;

TEST(Gif, FfmpegDecodesTheFramesWeWrote) {
  if (std::system("ffmpeg -version > /dev/null 2>&1") != 0) GTEST_SKIP() << "ffmpeg not installed (scripts/setup.sh installs it)";
  test::TempDir d;
  // Noisy frames (worst case for LZW: the code table fills and is cleared many times) and smooth gradients.
  std::mt19937 rng(1);
  std::vector<cv::Mat> frames;
  for (int k = 0; k < 4; ++k) {
    cv::Mat f(37, 53, CV_8UC3);
    for (int y = 0; y < f.rows; ++y)
      for (int x = 0; x < f.cols; ++x)
        f.at<cv::Vec3b>(y, x) = k % 2 ? cv::Vec3b(uint8_t(rng()), uint8_t(rng()), uint8_t(rng()))
                                      : cv::Vec3b(uint8_t(x * 4), uint8_t(y * 6), uint8_t(k * 60));
    frames.push_back(f);
  }
  data::write_gif(d / "a.gif", frames, 12.5);
  const std::string raw = (d / "a.raw").string();
  const std::string cmd = "ffmpeg -v error -y -i '" + (d / "a.gif").string() + "' -f rawvideo -pix_fmt bgr24 '" + raw + "'";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  auto bytes = read_file(raw);
  ASSERT_EQ(bytes.size(), size_t(4 * 37 * 53 * 3));
  size_t i = 0, bad = 0;
  for (const auto& f : frames)
    for (int y = 0; y < f.rows; ++y)
      for (int x = 0; x < f.cols; ++x) {
        cv::Vec3b want = data::gif_palette_color(data::gif_palette_index(f.at<cv::Vec3b>(y, x), x, y));
        for (int c = 0; c < 3; ++c) bad += uint8_t(bytes[i++]) != want[c];
      }
  EXPECT_EQ(bad, 0u);
}

TEST(Gif, PaletteIsCloseAndBadInputsFail) {
  // Dithered palette colours average back to the input colour over a 4x4 tile.
  cv::Vec3b c(200, 90, 33);
  double sum[3] = {0, 0, 0};
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) {
      auto p = data::gif_palette_color(data::gif_palette_index(c, x, y));
      for (int k = 0; k < 3; ++k) sum[k] += p[k] / 16.0;
    }
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(sum[k], c[k], 9.0);
  test::TempDir d;
  EXPECT_NE(test::error_of([&] { data::write_gif(d / "x.gif", {}, 10); }).find("no frames"), std::string::npos);
  EXPECT_FALSE(fs::exists(d / "x.gif"));
}
