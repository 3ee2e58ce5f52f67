// Image metrics against closed forms: PSNR of a constant offset, SSIM of flat images, and SSIM of a colour image as
// the mean of its channels.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "gaia/eval/metrics.h"

using namespace gaia;

TEST(Metrics, PsnrOfAConstantOffset) {
  cv::Mat a(8, 8, CV_8UC3, cv::Scalar(100, 120, 140)), b(8, 8, CV_8UC3, cv::Scalar(105, 125, 145));
  EXPECT_NEAR(eval::psnr(a, b), 10 * std::log10(255.0 * 255.0 / 25.0), 1e-9);  // MSE 25
  EXPECT_EQ(eval::psnr(a, a), 99.0);
}

TEST(Metrics, SsimOfFlatImagesInEveryChannel) {
  // Flat images have no variance, so SSIM is the luminance term (2 mx my + C1) / (mx^2 + my^2 + C1) in each channel;
  // the constants must reach every channel, not only the first.
  cv::Mat a(16, 16, CV_8UC3, cv::Scalar(100, 100, 100)), b(16, 16, CV_8UC3, cv::Scalar(110, 110, 110));
  const double C1 = 6.5025;
  EXPECT_NEAR(eval::ssim(a, b), (2 * 100.0 * 110.0 + C1) / (100.0 * 100.0 + 110.0 * 110.0 + C1), 1e-9);
  EXPECT_NEAR(eval::ssim(a, a), 1.0, 1e-12);
}

TEST(Metrics, SsimOfColourIsTheMeanOfItsChannels) {
  cv::RNG rng(7);
  cv::Mat a(24, 32, CV_8UC3), noise(24, 32, CV_8UC3);
  rng.fill(a, cv::RNG::UNIFORM, 0, 256);
  rng.fill(noise, cv::RNG::UNIFORM, 0, 40);
  cv::Mat b = a + noise;
  std::vector<cv::Mat> ca, cb;
  cv::split(a, ca);
  cv::split(b, cb);
  double mean = 0;
  for (int c = 0; c < 3; ++c) mean += eval::ssim(ca[size_t(c)], cb[size_t(c)]) / 3;
  const double s = eval::ssim(a, b);
  EXPECT_NEAR(s, mean, 1e-9);
  EXPECT_GT(s, 0.0);
  EXPECT_LT(s, 1.0);
}
