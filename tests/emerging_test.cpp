// Token statistics of the long-rollout evaluation (emerging/rollouts.h) on frames with known answers.
#include <cmath>

#include <torch/torch.h>

#include <array>
#include <cstdio>

#include "gaia/emerging/common.h"
#include "gaia/emerging/rollouts.h"
#include "gaia/probe/trainer.h"
#include "gaia/eval/svg_plot.h"
#include "test_util.h"

using namespace gaia;

TEST(EmergingStats, CopyRateAndEntropyOfKnownFrames) {
  // Three frames of 4 tokens; frame 1 repeats frame 0 in 3 of 4 positions, frame 2 repeats frame 1 in 1 of 4.
  auto f = torch::tensor({0, 1, 2, 3, 0, 1, 2, 0, 5, 5, 5, 0}, torch::kLong).view({3, 4});
  EXPECT_DOUBLE_EQ(emerging::copy_rate(f), (3.0 + 1.0) / 8.0);
  EXPECT_TRUE(std::isnan(emerging::copy_rate(f.slice(0, 0, 1))));  // one frame: no pairs
  // A frozen video copies everything; four equally frequent tokens have 2 bits of entropy, one token 0 bits.
  EXPECT_DOUBLE_EQ(emerging::copy_rate(f[0].unsqueeze(0).repeat({5, 1})), 1.0);
  EXPECT_NEAR(emerging::unigram_entropy_bits(f[0].unsqueeze(0), 16), 2.0, 1e-12);
  EXPECT_NEAR(emerging::unigram_entropy_bits(torch::full({2, 4}, 7, torch::kLong), 16), 0.0, 1e-12);
}

// Bar charts with negative values (a right turn's curvature): bars of +v and -v have the same height and meet at
// the zero line, one above it and one below.
TEST(SvgPlot, BarsHangBelowZeroForNegativeValues) {
  auto svg = eval::svg_bars("t", {"left", "right"}, {{"s", {2.0, -2.0}, "#123456"}}, 400, 200);
  std::vector<std::array<double, 2>> rects;  // (y, height)
  for (size_t at = svg.find("<rect x="); at != std::string::npos; at = svg.find("<rect x=", at + 1)) {
    double x, y, wd, ht;
    if (std::sscanf(svg.c_str() + at, "<rect x=\"%lf\" y=\"%lf\" width=\"%lf\" height=\"%lf\" fill=\"#123456\"", &x,
                    &y, &wd, &ht) == 4)
      rects.push_back({y, ht});
  }
  ASSERT_EQ(rects.size(), 3u);  // two bars and the legend swatch
  EXPECT_NEAR(rects[0][1], rects[1][1], 1e-6);
  EXPECT_GT(rects[0][1], 10.0);
  EXPECT_NEAR(rects[0][0] + rects[0][1], rects[1][0], 0.11);  // the positive bar ends where the negative one starts
}

// The dynamics read-back slides the probe's K-frame window over a sequence one step at a time: S frames give
// S - K + 1 readings, each the probe on exactly its window (speed and curvature in m/s and 1/m); too short a
// sequence is one clear error that names the probe's window.
TEST(EmergingReadback, DynamicsWindowsSlideOverTheSequence) {
  torch::manual_seed(3);
  emerging::Models m;
  m.dynamics = probe::ProbeNet(probe::ProbeKind::kDynamics, 3);
  m.dynamics->eval();
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 5; ++i) {
    cv::Mat f(16, 32, CV_8UC3);
    cv::randu(f, cv::Scalar::all(0), cv::Scalar::all(255));
    frames.push_back(f);
  }
  auto y = emerging::read_dynamics(m, frames);
  ASSERT_EQ(y.sizes(), (std::vector<int64_t>{3, 2}));
  torch::NoGradGuard ng;
  for (int64_t k = 0; k < 3; ++k) {
    auto want = m.dynamics->forward(probe::probe_input({frames[size_t(k)], frames[size_t(k) + 1], frames[size_t(k) + 2]}).unsqueeze(0))[0];
    EXPECT_NEAR(y[k][0].item<double>(), want[0].item<double>() * world::kSpeedScale, 1e-4);
    EXPECT_NEAR(y[k][1].item<double>(), want[1].item<double>() * world::kCurvatureScale, 1e-7);
  }
  auto err = test::error_of([&] { emerging::read_dynamics(m, {frames[0], frames[1]}); });
  EXPECT_NE(err.find("reads 3 consecutive frames"), std::string::npos) << err;
}
