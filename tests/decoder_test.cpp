// Video decoder (§2.4, §5.2): schedule and v identities, DDIM on an analytic denoiser, task masks, the temporal
// switch, parameter count against `gaia plan`, EMA, the backward decoding order, upsampling windows, bad inputs.
#include <torch/torch.h>

#include <map>
#include <random>
#include <set>
#include <sstream>

#include "gaia/config.h"
#include "gaia/core/error.h"
#include "gaia/decoder/diffusion.h"
#include "gaia/decoder/evaluate.h"
#include "gaia/decoder/io.h"
#include "gaia/decoder/sampler.h"
#include "gaia/decoder/tasks.h"
#include "gaia/decoder/trainer.h"
#include "gaia/decoder/unet.h"
#include "gaia/decoder/video.h"
#include "gaia/sizing/sizing.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/ema.h"
#include "test_util.h"

using namespace gaia;
using namespace gaia::decoder;

namespace {


// Random weights everywhere, including the zero-initialised output projections, so every path is exercised.
void randomize(torch::nn::Module& m, uint64_t seed, double std = 0.05) {
  torch::NoGradGuard ng;
  torch::manual_seed(seed);
  for (auto& p : m.parameters()) p.normal_(0, std);
}

DenoiserInput random_input(const VideoUNet& m, int64_t B, int64_t T, int64_t H, int64_t W, uint64_t seed) {
  torch::manual_seed(seed);
  DenoiserInput in;
  in.x = torch::randn({B, T, 3, H, W});
  in.context = torch::zeros({B, T});
  in.tokens = torch::randint(0, m->K + 1, {B, T, H / m->D, W / m->D}, torch::kLong);
  in.cond_image = torch::randn({B, T, 3, H, W});
  in.time = torch::rand({B, T});
  in.rate = torch::zeros({B}, torch::kLong);
  return in;
}

}  // namespace

TEST(DecoderDiffusion, ScheduleIsVariancePreservingAndMonotone) {
  NoiseSchedule s;
  auto t = torch::linspace(0, 1, 101, torch::kFloat64);
  auto a = s.alpha(t), g = s.sigma(t);
  EXPECT_LT((a * a + g * g - 1).abs().max().item<double>(), 1e-12);
  EXPECT_TRUE((a.slice(0, 1) <= a.slice(0, 0, -1)).all().item<bool>());  // less signal as t grows
  EXPECT_GT(a[0].item<double>(), 0.999);
  EXPECT_LT(a[100].item<double>(), 1e-3);
  // Cosine: alpha(t) = cos(pi t / 2) away from the clipped ends.
  EXPECT_NEAR(a[50].item<double>(), std::cos(M_PI / 4), 1e-9);
  // A shift below 1 adds noise at every t.
  NoiseSchedule shifted{-15, 15, 0.5};
  EXPECT_LT(shifted.alpha(t)[50].item<double>(), a[50].item<double>());
}

TEST(DecoderDiffusion, VParameterisationRecoversX0AndEps) {
  torch::manual_seed(1);
  NoiseSchedule s;
  auto x = torch::randn({2, 3, 3, 4, 4}, torch::kFloat64), eps = torch::randn_like(x);
  auto t = torch::rand({2, 3}, torch::kFloat64);
  auto a = s.alpha(t).view({2, 3, 1, 1, 1}), g = s.sigma(t).view({2, 3, 1, 1, 1});
  auto xt = add_noise(x, eps, a, g), v = v_target(x, eps, a, g);
  EXPECT_LT((x_from_v(xt, v, a, g) - x).abs().max().item<double>(), 1e-12);
  EXPECT_LT((eps_from_v(xt, v, a, g) - eps).abs().max().item<double>(), 1e-12);
  // A DDIM step to s = t with the true v returns x_t; to s = 0 it returns x.
  EXPECT_LT((ddim_step(xt, v, a, g, a, g) - xt).abs().max().item<double>(), 1e-12);
  auto one = torch::ones_like(a), zero = torch::zeros_like(a);
  EXPECT_LT((ddim_step(xt, v, a, g, one, zero) - x).abs().max().item<double>(), 1e-12);
}

TEST(DecoderDiffusion, LossIsPaperWeightedOverPredictedFramesOnly) {
  auto vp = torch::zeros({1, 2, 3, 2, 2}), vt = torch::zeros({1, 2, 3, 2, 2});
  vt[0][0].fill_(2.0);   // frame 0: |d| = 2 -> L1 2, L2 4
  vt[0][1].fill_(10.0);  // frame 1 is context: no loss
  auto w = torch::tensor({{1.0f, 0.0f}});
  EXPECT_NEAR(v_loss(vp, vt, w, 0.1, 1.0).item<double>(), 0.1 * 2 + 1.0 * 4, 1e-6);
}

// decoder.w_temporal's term: the change of the v error between consecutive predicted frames. An error that is the
// same in every frame costs nothing however large; one that alternates costs its full swing; pairs that touch a
// context frame (weight 0) do not count.
TEST(DecoderDiffusion, TemporalLossCountsOnlyErrorsThatChange) {
  auto vt = torch::randn({2, 4, 3, 4, 4});
  auto steady = vt + 0.7;  // the same error everywhere
  auto w = torch::ones({2, 4});
  EXPECT_NEAR(temporal_v_loss(steady, vt, w).item<double>(), 0.0, 1e-6);
  EXPECT_GT(v_loss(steady, vt, w, 0.1, 1.0).item<double>(), 0.5);  // v_loss does see it
  auto sign = torch::tensor({1.0f, -1.0f, 1.0f, -1.0f}).view({1, 4, 1, 1, 1});
  auto flicker = vt + 0.5 * sign;  // +0.5, -0.5, +0.5, -0.5: every step changes the error by 1
  EXPECT_NEAR(temporal_v_loss(flicker, vt, w).item<double>(), 1.0, 1e-6);
  // Frame 0 is context in every window: the pair (0, 1) drops out. Make that pair's change large; the rest 1.
  auto jump = flicker.clone();
  jump.select(1, 0).add_(100.0);
  auto w_ctx = w.clone();
  w_ctx.select(1, 0).zero_();
  EXPECT_NEAR(temporal_v_loss(jump, vt, w_ctx).item<double>(), 1.0, 1e-5);
  EXPECT_GT(temporal_v_loss(jump, vt, w).item<double>(), 30.0);
  // One predicted frame: no pair, no loss.
  auto one = torch::zeros({2, 4});
  one.select(1, 2).fill_(1.0);
  EXPECT_EQ(temporal_v_loss(flicker, vt, one).item<double>(), 0.0);
}

TEST(DecoderDiffusion, DdimWithAnalyticDenoiserMapsNoiseToTheDataDistribution) {
  // Data x ~ N(mu, s^2) per dimension. The exact denoiser is E[x | x_t] = mu + a s^2 (x_t - a mu) / (a^2 s^2 + g^2),
  // and the probability-flow ODE keeps xi = (x_t - a mu) / sqrt(a^2 s^2 + g^2) constant: DDIM with many steps must
  // map z_1 to mu + s xi(1).
  NoiseSchedule sch;
  torch::manual_seed(2);
  auto mu = torch::randn({64}, torch::kFloat64), sd = torch::rand({64}, torch::kFloat64) * 0.8 + 0.2;
  auto z1 = torch::randn({64}, torch::kFloat64);
  auto v_fn = [&](const torch::Tensor& z, double t) {
    auto tt = torch::tensor({t}, torch::kFloat64);
    auto a = sch.alpha(tt), g = sch.sigma(tt);
    auto x_hat = mu + a * sd * sd * (z - a * mu) / (a * a * sd * sd + g * g);
    auto eps_hat = (z - a * x_hat) / g;
    return a * eps_hat - g * x_hat;
  };
  auto x = ddim_loop(z1.clone(), 1000, sch, v_fn);
  auto t1 = torch::tensor({1.0}, torch::kFloat64);
  auto a1 = sch.alpha(t1), g1 = sch.sigma(t1);
  auto want = mu + sd * (z1 - a1 * mu) / (a1 * a1 * sd * sd + g1 * g1).sqrt();
  const double err = (x - want).abs().max().item<double>();
  EXPECT_LT(err, 5e-3);
  // First-order convergence: 10x fewer steps, ~10x the error (so the test can tell a wrong update from a right one).
  const double err100 = (ddim_loop(z1.clone(), 100, sch, v_fn) - want).abs().max().item<double>();
  EXPECT_GT(err100, 5 * err);
  EXPECT_LT(err100, 20 * err);
}

// decoder.start_time: DDIM from a noised datum at t0 < 1 follows the same ODE from there, so the analytic denoiser
// maps z_t0 to mu + s xi(t0) (SDEdit's start, exact for the probability-flow ODE).
TEST(DecoderDiffusion, DdimFromALaterStartTimeFollowsTheOdeFromThere) {
  const auto grid = ddim_times(4, 0.5);
  ASSERT_EQ(grid.size(), 5u);
  EXPECT_DOUBLE_EQ(grid[0], 0.5);
  EXPECT_DOUBLE_EQ(grid[1], 0.375);
  EXPECT_DOUBLE_EQ(grid[4], 0.0);
  NoiseSchedule sch;
  torch::manual_seed(3);
  auto mu = torch::randn({64}, torch::kFloat64), sd = torch::rand({64}, torch::kFloat64) * 0.8 + 0.2;
  auto v_fn = [&](const torch::Tensor& z, double t) {
    auto tt = torch::tensor({t}, torch::kFloat64);
    auto a = sch.alpha(tt), g = sch.sigma(tt);
    auto x_hat = mu + a * sd * sd * (z - a * mu) / (a * a * sd * sd + g * g);
    return a * (z - a * x_hat) / g - g * x_hat;
  };
  const double t0 = 0.4;
  auto tt0 = torch::tensor({t0}, torch::kFloat64);
  auto a0 = sch.alpha(tt0), g0 = sch.sigma(tt0);
  auto x = mu + sd * torch::randn({64}, torch::kFloat64);
  auto z0 = a0 * x + g0 * torch::randn({64}, torch::kFloat64);  // a datum noised to t0
  auto want = mu + sd * (z0 - a0 * mu) / (a0 * a0 * sd * sd + g0 * g0).sqrt();
  const double err = (ddim_loop(z0.clone(), 1000, sch, v_fn, t0) - want).abs().max().item<double>();
  EXPECT_LT(err, 5e-3);
  // Read as if it started at t = 1, the same z lands elsewhere: the start time is used.
  EXPECT_GT((ddim_loop(z0.clone(), 1000, sch, v_fn) - want).abs().max().item<double>(), 20 * err);
  EXPECT_NE(test::error_of([&] { ddim_loop(z0, 10, sch, v_fn, 0.0); }).find("decoder.start_time"), std::string::npos);
  EXPECT_NE(test::error_of([&] { ddim_loop(z0, 10, sch, v_fn, 1.5); }).find("decoder.start_time"), std::string::npos);
}

TEST(DecoderTasks, MasksForEveryTask) {
  auto img = task_masks(Task::kImage, 7);
  EXPECT_FALSE(img.temporal);
  EXPECT_EQ(std::count(img.context.begin(), img.context.end(), true), 0);
  EXPECT_EQ(std::count(img.tokens.begin(), img.tokens.end(), true), 7);
  auto vid = task_masks(Task::kVideo, 7);
  EXPECT_TRUE(vid.temporal);
  EXPECT_EQ(std::count(vid.context.begin(), vid.context.end(), true), 0);
  auto fwd = task_masks(Task::kForward, 7);
  EXPECT_EQ(fwd.context, (std::vector<bool>{true, true, false, false, false, false, false}));
  EXPECT_EQ(fwd.tokens, (std::vector<bool>{false, false, true, true, true, true, true}));
  auto bwd = task_masks(Task::kBackward, 7);
  EXPECT_EQ(bwd.context, (std::vector<bool>{false, false, false, false, false, true, true}));
  EXPECT_EQ(bwd.tokens, (std::vector<bool>{true, true, true, true, true, false, false}));
  auto itp = task_masks(Task::kInterpolate, 7);
  EXPECT_EQ(itp.context, (std::vector<bool>{true, false, true, false, true, false, true}));
  EXPECT_EQ(std::count(itp.tokens.begin(), itp.tokens.end(), true), 0);  // guided by image context alone
}

TEST(DecoderTasks, TasksAreDrawnEquallyAndInterpolationUpsamples) {
  std::mt19937_64 rng(5);
  std::map<Task, int> n;
  const int draws = 20000;
  for (int i = 0; i < draws; ++i) {
    auto d = draw_task(rng);
    ++n[d.task];
    ASSERT_GE(d.rate, d.task == Task::kInterpolate ? 1 : 0);
    ASSERT_LE(d.rate, 2);
  }
  for (auto& [task, c] : n) EXPECT_NEAR(double(c) / draws, 0.2, 0.015) << to_string(task);
  EXPECT_EQ(rate_index(12.5), 1);
  EXPECT_NE(test::error_of([] { rate_index(10); }).find("10"), std::string::npos);
}

TEST(DecoderUNet, ShapesAndParameterCountMatchThePlan) {
  for (auto c : {test::config("tiny.yaml"), Config()}) {
    VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
    EXPECT_EQ(m->parameter_count(), sizing::decoder_params(c).total) << c.name;
  }
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  auto in = random_input(m, 2, 5, 32, 64, 1);
  auto v = m->forward(in);
  EXPECT_EQ(v.sizes(), (std::vector<int64_t>{2, 5, 3, 32, 64}));
  // Output layer starts at zero (a fresh model predicts v = 0).
  EXPECT_EQ(v.abs().max().item<float>(), 0.0f);
}

// The plan's FLOPs of a U-Net pass (sizing::inference_flops) against a count read off the built model: every
// weight's multiply-adds at the pixels of its level, and the attention products where the modules sit.
TEST(DecoderUNet, PassFlopsMatchThePlan) {
  for (auto c : {test::config("tiny.yaml"), Config()}) {
    VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
    const double T = c.decoder.frames;
    auto pixels = [&](int level) { return double(c.data.height >> level) * double(c.data.width >> level); };
    auto index = [](const std::string& name, const std::string& prefix) {
      return std::stoi(name.substr(prefix.size(), name.find('.', prefix.size()) - prefix.size()));
    };
    const int L = int(c.decoder.channel_mult.size());
    double macs = 0;
    for (const auto& p : m->named_parameters()) {
      const std::string& name = p.key();
      const auto& w = p.value();
      // Matrices and kernels only: embeddings are looked up, the temporal position bias is added.
      if (w.dim() < 2 || name.rfind("token_embedding", 0) == 0 || name.rfind("rate_embedding", 0) == 0 ||
          name.find("rel_bias") != std::string::npos)
        continue;
      int level = 0;
      if (name.rfind("down.", 0) == 0) level = m->down_level.at(size_t(index(name, "down.")));
      else if (name.rfind("up.", 0) == 0) level = m->up_level.at(size_t(index(name, "up.")));
      else if (name.rfind("mid", 0) == 0) level = L - 1;
      else if (name.rfind("token_proj.", 0) == 0) level = index(name, "token_proj.");
      else if (name.rfind("downsamplers.", 0) == 0) level = index(name, "downsamplers.") + 1;
      else if (name.rfind("upsamplers.", 0) == 0) level = L - 2 - index(name, "upsamplers.");
      const bool per_frame = name.find("film") != std::string::npos || name.rfind("time_fc", 0) == 0;
      const double outputs = per_frame ? T : T * pixels(level);
      macs += double(w.numel()) * outputs;
      const double px = pixels(level), ch = double(w.size(1));  // qkv: [3c, c]
      if (name.find("spatial.qkv.weight") != std::string::npos) macs += T * 2 * px * px * ch;
      if (name.find("temporal.qkv.weight") != std::string::npos) macs += px * 2 * T * T * ch;
    }
    EXPECT_NEAR(sizing::inference_flops(c, 1).decoder_window / (2 * macs), 1.0, 1e-9) << c.name;
  }
}

// A second of video in the plan against the schedule's own windows over a long drive (backward windows, then
// two doublings): the same number of U-Net passes, up to the shorter last windows.
TEST(DecoderUNet, VideoSecondFlopsFollowTheSchedule) {
  Config c;
  const int T = c.decoder.frames;
  const int64_t N = 401;  // token frames: 64 s at 6.25 Hz
  const double tokens_windows = double(backward_windows(N, T).size());
  const double up_windows = double(upsample_windows(2 * N - 1, T).size() + upsample_windows(4 * N - 3, T).size());
  const double passes = c.decoder.ddim_steps * ((1 + c.decoder.mix_probability) * tokens_windows + up_windows);
  const double seconds = double(4 * N - 3) / (4 * c.data.world_fps);
  const auto f = sizing::inference_flops(c, 1);
  EXPECT_NEAR(f.decoder_video_second / (passes * f.decoder_window / seconds), 1.0, 0.01);
}

TEST(DecoderUNet, TemporalSwitchMakesFramesIndependent) {
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  randomize(*m, 3);
  m->eval();
  torch::NoGradGuard ng;
  auto in = random_input(m, 1, 5, 32, 64, 4);
  auto in2 = in;
  in2.x = in.x.clone();
  in2.x[0][4].normal_();  // change the last frame only
  in.temporal = in2.temporal = false;
  auto a = m->forward(in), b = m->forward(in2);
  EXPECT_LT((a.slice(1, 0, 4) - b.slice(1, 0, 4)).abs().max().item<float>(), 1e-5);  // other frames untouched
  EXPECT_GT((a[0][4] - b[0][4]).abs().max().item<float>(), 1e-3);
  // A frame alone gives the same output as in the batch (no cross-frame path at all).
  auto one = in;
  one.x = in.x.slice(1, 0, 1);
  one.context = in.context.slice(1, 0, 1);
  one.tokens = in.tokens.slice(1, 0, 1);
  one.cond_image = in.cond_image.slice(1, 0, 1);
  one.time = in.time.slice(1, 0, 1);
  EXPECT_LT((m->forward(one)[0][0] - a[0][0]).abs().max().item<float>(), 1e-4);
  in.temporal = in2.temporal = true;
  a = m->forward(in);
  b = m->forward(in2);
  EXPECT_GT((a[0][0] - b[0][0]).abs().max().item<float>(), 1e-4);  // with temporal layers, frames see each other
}

TEST(DecoderUNet, TemporalAttentionKnowsOrder) {
  // With the relative-position bias, reversing time is not a symmetry of the temporal layer.
  TemporalAttention att(8, 2, 4);
  randomize(*att, 6, 0.5);
  torch::NoGradGuard ng;
  auto x = torch::randn({5, 8, 2, 3});  // B = 1, T = 5
  auto y = att(x, 5), yr = att(x.flip(0), 5).flip(0);
  EXPECT_GT((y - yr).abs().max().item<float>(), 1e-4);
  att->rel_bias.zero_();
  y = att(x, 5);
  yr = att(x.flip(0), 5).flip(0);
  EXPECT_LT((y - yr).abs().max().item<float>(), 1e-5);  // without it, attention is permutation-equivariant
}

TEST(DecoderTrain, EmaUpdate) {
  torch::nn::Linear a(2, 2), b(2, 2);
  torch::NoGradGuard ng;
  a->weight.fill_(1.0);
  a->bias.fill_(1.0);
  b->weight.fill_(3.0);
  b->bias.fill_(3.0);
  double d = train::ema_update(*a, *b, 0.999, 1000000);
  EXPECT_DOUBLE_EQ(d, 0.999);
  EXPECT_NEAR(a->weight[0][0].item<double>(), 0.999 * 1 + 0.001 * 3, 1e-6);
  d = train::ema_update(*a, *b, 0.999, 0);  // warm-up: (1 + 0) / (10 + 0)
  EXPECT_DOUBLE_EQ(d, 0.1);
  train::ema_copy(*a, *b);
  EXPECT_EQ(a->bias[1].item<float>(), 3.0f);
}

TEST(DecoderSchedule, BackwardWindowsDecodeEveryFrameOnceFromTheEnd) {
  for (int64_t N : {1, 5, 7, 8, 12, 16, 40}) {
    const int T = 7;
    auto ws = backward_windows(N, T);
    std::vector<int> predicted(size_t(N), 0);
    std::vector<bool> known(size_t(N), false);
    int64_t prev_start = N;
    for (size_t k = 0; k < ws.size(); ++k) {
      const auto& w = ws[k];
      const int64_t len = int64_t(w.context.size());
      EXPECT_EQ(len, std::min<int64_t>(N, T));
      EXPECT_LT(w.start, prev_start);  // moves towards the start
      prev_start = w.start;
      int ctx = 0;
      for (int64_t i = 0; i < len; ++i) {
        const size_t f = size_t(w.start + i);
        if (w.context[size_t(i)]) {
          EXPECT_TRUE(known[f]) << "context frame " << f << " not decoded yet";
          ++ctx;
        } else {
          ++predicted[f];
        }
      }
      if (k == 0) {
        EXPECT_EQ(w.start + len, N);  // the last T' frames first
      } else {
        EXPECT_GE(ctx, kOverlapFrames);  // at least 2 overlapping frames
        if (w.start > 0) {
          EXPECT_EQ(ctx, kOverlapFrames);
        }
      }
      for (int64_t i = 0; i < len; ++i) known[size_t(w.start + i)] = true;
    }
    for (int p : predicted) EXPECT_EQ(p, 1) << "N = " << N;
  }
}

TEST(DecoderSchedule, UpsampleWindowsFillEveryOddFrame) {
  for (int64_t M : {3, 7, 13, 15, 31, 61}) {
    auto ws = upsample_windows(M, 7);
    std::vector<int> predicted(size_t(M), 0);
    for (const auto& w : ws) {
      EXPECT_EQ(w.start % 2, 0);
      EXPECT_TRUE(w.context.front());
      EXPECT_TRUE(w.context.back());  // starts and ends on a known frame
      for (size_t i = 0; i < w.context.size(); ++i) {
        EXPECT_EQ(w.context[i], (w.start + int64_t(i)) % 2 == 0);
        if (!w.context[i]) ++predicted[size_t(w.start) + i];
      }
    }
    for (int64_t f = 0; f < M; ++f) EXPECT_EQ(predicted[size_t(f)], f % 2) << "M = " << M << " frame " << f;
  }
  EXPECT_NE(test::error_of([] { upsample_windows(9, 6); }).find("odd"), std::string::npos);
}

TEST(DecoderVideo, DecodesToTwentyFiveHertzKeepingKnownFrames) {
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  randomize(*m, 7);
  m->eval();
  NoiseSchedule sch;
  const int64_t N = 6;  // more frames than one window of decoder.frames
  auto tokens = torch::randint(0, m->K, {1, N, 4, 8}, torch::kLong);
  auto cond = torch::rand({1, N, 3, 32, 64}) * 2 - 1;
  DecodeOptions o;
  o.sample.steps = 2;
  o.out_fps = 12.5;
  int last = 0, total = 0;
  auto v = decode_video(m, sch, tokens, cond, o, [&](int d, int t) { last = d, total = t; });
  EXPECT_EQ(v.sizes(), (std::vector<int64_t>{1, 2 * N - 1, 3, 32, 64}));
  EXPECT_GT(total, 1);
  EXPECT_EQ(last, total);
  EXPECT_EQ(total, count_windows(N, c.decoder.frames, 6.25, 12.5));
  EXPECT_LE(v.abs().max().item<float>(), 1.0f);
  // Upsampling keeps the frames it was given exactly.
  auto up = upsample_video(m, sch, v, 2, o.sample);
  EXPECT_EQ(up.size(1), 2 * v.size(1) - 1);
  EXPECT_TRUE(torch::equal(up.slice(1, 0, up.size(1), 2), v));
  // Same seed, same video.
  auto v2 = decode_video(m, sch, tokens, cond, o);
  EXPECT_TRUE(torch::equal(v, v2)) << (v - v2).abs().max().item<float>();
}

// --precision bf16: the U-Net under bf16's autocast, the norms and the DDIM arithmetic in float32. The video stays
// near the float32 one (frames in [-1, 1]), differs from it, and is float32 and repeatable.
TEST(DecoderVideo, Bf16DecodingStaysNearFloat32) {
  if (!cpu_has_bf16()) GTEST_SKIP() << "this CPU runs --precision bf16 as fp32 (no bf16 instructions)";
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  randomize(*m, 7);
  m->eval();
  NoiseSchedule sch;
  auto tokens = torch::randint(0, m->K, {1, 4, 4, 8}, torch::kLong);
  auto cond = torch::rand({1, 4, 3, 32, 64}) * 2 - 1;
  DecodeOptions o;
  o.sample.steps = 3;
  o.out_fps = 12.5;
  const auto fp32 = decode_video(m, sch, tokens, cond, o);
  o.sample.precision = Precision::kBf16;
  const auto bf16 = decode_video(m, sch, tokens, cond, o);
  ASSERT_EQ(bf16.sizes(), fp32.sizes());
  EXPECT_EQ(bf16.scalar_type(), torch::kFloat);
  const double off = (bf16 - fp32).abs().mean().item<double>();
  EXPECT_GT(off, 0);
  EXPECT_LT(off, 0.005) << "mean difference from float32 (frames span 2)";
  EXPECT_TRUE(torch::equal(decode_video(m, sch, tokens, cond, o), bf16));
}

TEST(DecoderVideo, BadInputsAreClearErrors) {
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  NoiseSchedule sch;
  DecodeOptions o;
  o.sample.steps = 1;
  auto cond = torch::zeros({1, 3, 3, 32, 64});
  EXPECT_NE(test::error_of([&] { decode_video(m, sch, torch::zeros({1, 3, 4, 8}, torch::kLong).fill_(m->K), cond, o); })
                .find("token ids"),
            std::string::npos);
  EXPECT_NE(test::error_of([&] { decode_video(m, sch, torch::zeros({1, 0, 4, 8}, torch::kLong), cond, o); })
                .find("nothing to decode"),
            std::string::npos);
  // A 5x8 grid is not the 32x64 frames the decoded images have.
  EXPECT_NE(test::error_of([&] { decode_video(m, sch, torch::zeros({1, 3, 5, 8}, torch::kLong), cond, o); }).find("decoded frames"),
            std::string::npos);
  o.out_fps = 20;
  EXPECT_NE(test::error_of([&] { decode_video(m, sch, torch::zeros({1, 3, 4, 8}, torch::kLong), cond, o); }).find("20"),
            std::string::npos);
}

TEST(DecoderVideo, ForwardAndWindowAreRepeatable) {
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  randomize(*m, 7);
  m->eval();
  torch::NoGradGuard ng;
  auto in = random_input(m, 1, 5, 32, 64, 4);
  EXPECT_TRUE(torch::equal(m->forward(in), m->forward(in)));
  WindowInput w;
  w.frames = in.x;
  w.context = in.context;
  w.tokens = in.tokens.clamp_max(m->K - 1);
  w.cond_image = in.cond_image;
  SampleOptions o;
  o.steps = 2;
  NoiseSchedule sch;
  auto a = sample_window(m, sch, w, o), b = sample_window(m, sch, w, o);
  EXPECT_TRUE(torch::equal(a, b)) << (a - b).abs().max().item<float>();
}

// Flicker (the issue's: change of the generated frames minus the truth's) against the temporal error (how far each
// generated change is from the true one): a blurred but steady decoder has negative flicker yet a temporal error
// as large as the truth's motion it misses; per-frame noise shows in both; the truth itself scores 0.
TEST(DecoderEval, FlickerAndTemporalError) {
  torch::manual_seed(11);
  auto x = (torch::rand({6, 3, 16, 32}) * 2 - 1) * 0.8;
  EXPECT_DOUBLE_EQ(temporal_error(x, x), 0.0);
  EXPECT_NEAR(temporal_change(x + 0.1), temporal_change(x), 1e-5);  // a constant offset changes nothing
  EXPECT_NEAR(temporal_error(x + 0.1, x), 0.0, 1e-5);
  auto frozen = x.select(0, 0).unsqueeze(0).expand_as(x).contiguous();  // one frame repeated
  EXPECT_DOUBLE_EQ(temporal_change(frozen), 0.0);                     // flicker = -change(x) < 0 ...
  EXPECT_NEAR(temporal_error(frozen, x), temporal_change(x), 1e-4);    // ... but every true change is missed
  auto noisy = x + 0.1 * torch::randn_like(x);                         // independent per-frame errors
  EXPECT_GT(temporal_error(noisy, x), 0.1 * 127.5 * 0.9);              // E|n1 - n2| = 0.1 * 2 / sqrt(pi) ~ 0.113
  EXPECT_LT(temporal_error(noisy, x), 0.1 * 127.5 * 1.4);
  EXPECT_THROW(temporal_error(x, x.slice(0, 1)), gaia::Error);
}

// Edge energy (the sharpness the decoder eval reports as a ratio to the truth's): a flat frame has none, a
// checkerboard of +-a has 2a between every pair of neighbours, and blurring lowers it.
TEST(DecoderEval, EdgeEnergyMeasuresFineDetail) {
  EXPECT_DOUBLE_EQ(edge_energy(torch::full({2, 3, 8, 8}, 0.4)), 0.0);
  auto idx = torch::arange(8);
  auto checker = ((idx.view({8, 1}) + idx.view({1, 8})) % 2).to(torch::kFloat32) * 0.5 - 0.25;  // +-0.25
  EXPECT_NEAR(edge_energy(checker.expand({2, 3, 8, 8})), 0.5 * 127.5, 1e-4);
  torch::manual_seed(13);
  auto x = torch::rand({2, 3, 16, 16}) * 2 - 1;
  auto blurred = torch::avg_pool2d(x.view({6, 1, 16, 16}), 3, 1, 1, false, false).view({2, 3, 16, 16});
  EXPECT_LT(edge_energy(blurred), 0.6 * edge_energy(x));
  EXPECT_DOUBLE_EQ(edge_energy(x * 3), edge_energy((x * 3).clamp(-1, 1)));  // frames are clamped first
}

// The 25 Hz baseline from 6.25 Hz tokens: key frames kept, the frames between them on the straight line, so a
// sequence that moves linearly in time is reproduced exactly.
TEST(DecoderEval, BlendToRateKeepsKeyFramesAndInterpolatesLinearly) {
  torch::manual_seed(12);
  auto a = torch::rand({3, 4, 8}), b = torch::rand({3, 4, 8});
  auto line = torch::stack({a, a + 4 * b, a + 8 * b});  // key frames of x(t) = a + t b at t = 0, 4, 8
  auto up = blend_to_rate(line, 4);
  ASSERT_EQ(up.size(0), 9);
  for (int64_t t = 0; t < 9; ++t) EXPECT_TRUE(torch::allclose(up[t], a + double(t) * b, 1e-5, 1e-5)) << t;
  EXPECT_TRUE(torch::equal(blend_to_rate(line, 1), line));
  EXPECT_EQ(blend_to_rate(line.slice(0, 0, 1), 4).size(0), 1);
  EXPECT_THROW(blend_to_rate(line, 0), gaia::Error);
}

// §5.2 mixing: with probability 1 every step averages in the image (temporal-off) prediction, but only on frames
// with tokens. With one DDIM step the output is a function of that one v, so frames without tokens (interpolation)
// must come out exactly as without mixing, and frames with tokens must not.
TEST(DecoderVideo, ImageVideoMixingOnlyTouchesFramesWithTokens) {
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  randomize(*m, 9);
  m->eval();
  auto in = random_input(m, 1, 5, 32, 64, 6);
  WindowInput w;
  w.frames = in.x.clamp(-1, 1);
  w.context = torch::tensor({1.f, 0.f, 0.f, 0.f, 1.f}).unsqueeze(0);
  w.tokens = in.tokens.clamp_max(m->K - 1);
  w.tokens.select(1, 0).fill_(m->K);  // context frames carry no tokens
  w.tokens.select(1, 4).fill_(m->K);
  w.tokens.select(1, 2).fill_(m->K);  // frame 2: interpolated (no tokens)
  w.cond_image = in.cond_image.clamp(-1, 1) * 0.1;
  w.cond_image.select(1, 2).zero_();
  SampleOptions mixed, plain;
  mixed.steps = plain.steps = 1;
  mixed.mix_probability = 1.0;
  plain.mix_probability = 0.0;
  NoiseSchedule sch;
  auto a = sample_window(m, sch, w, mixed), b = sample_window(m, sch, w, plain);
  EXPECT_TRUE(torch::equal(a.select(1, 2), b.select(1, 2))) << "interpolated frame changed by mixing";
  EXPECT_GT((a.select(1, 1) - b.select(1, 1)).abs().max().item<double>(), 1e-4) << "frame with tokens not mixed";
  EXPECT_GT((a.select(1, 3) - b.select(1, 3)).abs().max().item<double>(), 1e-4);
}

// With cond_image the diffusion runs on the residual over the coarse frame: a perfect coarse frame leaves nothing
// to diffuse on frames with tokens, while context frames (no tokens, zero coarse frame) are diffused as themselves.
// Two random clips of T frames at 16x32 with 2x4 token grids (K = 16) and a random coarse frame.
static Clips random_clips(uint64_t seed, int64_t T) {
  torch::manual_seed(seed);
  const int64_t B = 2, H = 16, W = 32, D = 8;
  Clips c;
  c.frames = torch::rand({B, T, 3, H, W}) * 2 - 1;
  c.tokens = torch::randint(0, 16, {B, T, H / D, W / D}, torch::kLong);
  c.cond = torch::rand({B, T, 3, H, W}) * 2 - 1;
  return c;
}

TEST(DecoderResidual, TrainingTargetIsTheResidualOverTheCoarseFrame) {
  const int64_t T = 5, D = 8;
  Clips c = random_clips(3, T);
  c.cond = c.frames.clone();
  NoiseSchedule sch;
  auto masks = task_masks(Task::kForward, int(T));
  auto b = make_task_batch(c, masks, 0, 0.6, 0.0, sch, 16, D);
  auto tt = torch::full({1}, 0.6);
  auto r_hat = x_from_v(b.input.x, b.v_true, sch.alpha(tt), sch.sigma(tt));
  for (int64_t f = 0; f < T; ++f) {
    auto rf = r_hat.select(1, f), xf = b.input.x.select(1, f);
    if (masks.context[size_t(f)]) {
      EXPECT_TRUE(torch::allclose(xf, c.frames.select(1, f))) << "context frame " << f << " is given clean";
    } else {
      ASSERT_TRUE(masks.tokens[size_t(f)]);
      EXPECT_LT(rf.abs().max().item<double>(), 1e-5) << "frame " << f << ": residual of a perfect coarse frame";
      EXPECT_GT(xf.std().item<double>(), 0.5) << "frame " << f << " is noised";
    }
  }
}

TEST(DecoderResidual, SamplerAddsTheCoarseFrameBack) {
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);  // fresh: zero output projection, v = 0
  torch::NoGradGuard ng;
  auto in = random_input(m, 1, 5, 32, 64, 5);
  ASSERT_EQ(m->forward(in).abs().max().item<float>(), 0.0f);
  WindowInput w;
  w.frames = in.x.clamp(-1, 1);
  w.context = torch::tensor({1.f, 0.f, 0.f, 0.f, 0.f}).unsqueeze(0);
  w.tokens = in.tokens.clamp_max(m->K - 1);
  w.cond_image = torch::rand_like(in.x) * 0.2 - 0.1;
  SampleOptions o;
  o.steps = 4;
  NoiseSchedule sch;
  auto a = sample_window(m, sch, w, o);
  WindowInput w0 = w;
  w0.cond_image = torch::zeros_like(w.cond_image);
  auto b = sample_window(m, sch, w0, o);
  EXPECT_TRUE(torch::equal(a.select(1, 0), w.frames.select(1, 0))) << "context frame kept";
  auto gen = a.slice(1, 1), gen0 = b.slice(1, 1), base = w.cond_image.slice(1, 1);
  auto inside = (gen.abs() < 0.999) & (gen0.abs() < 0.999);  // away from the final clamp
  ASSERT_GT(inside.sum().item<int64_t>(), 1000);
  EXPECT_LT(((gen - gen0 - base) * inside).abs().max().item<double>(), 1e-5);
}

// decoder.interp_base: a frame with neither tokens nor context starts from the blend of its nearest context frames
// (linear in time), or a copy of the one it has; frames with tokens, context frames and rows without any context
// are left as they were.
TEST(DecoderResidual, InterpolationBaseBlendsTheContextNeighbours) {
  const int64_t T = 6;
  auto frames = torch::arange(T, torch::kFloat32).view({1, T, 1, 1, 1}).expand({2, T, 3, 4, 8}).clone() * 0.3 - 0.7;
  auto cond = torch::full_like(frames, 0.05);
  auto ctx = torch::tensor({1.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f}).view({2, T});
  auto tok = torch::tensor({0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0}).view({2, T}).to(torch::kBool);
  auto out = interpolation_base(cond, frames, ctx, tok);
  auto f = [&](int64_t t) { return frames[0][t]; };
  EXPECT_TRUE(torch::equal(out[0][0], cond[0][0])) << "context frame";
  EXPECT_TRUE(torch::equal(out[0][1], cond[0][1])) << "frame with tokens";
  EXPECT_TRUE(torch::allclose(out[0][2], f(0) / 3 + f(3) * 2 / 3)) << "2/3 of the way from frame 0 to frame 3";
  EXPECT_TRUE(torch::equal(out[0][4], f(3))) << "after the last context frame: a copy of it";
  EXPECT_TRUE(torch::equal(out[0][5], f(3)));
  EXPECT_TRUE(torch::equal(out[1], cond[1])) << "no context at all: nothing to blend";
}

// The interpolate task trains on the same base the upsampling windows use at inference.
TEST(DecoderResidual, InterpolateTaskDiffusesTheResidualOverTheBlend) {
  const int64_t T = 7, D = 8;
  Clips c = random_clips(4, T);
  NoiseSchedule sch;
  auto masks = task_masks(Task::kInterpolate, int(T));
  auto on = make_task_batch(c, masks, 2, 0.5, 0.0, sch, 16, D, true);
  auto off = make_task_batch(c, masks, 2, 0.5, 0.0, sch, 16, D, false);
  auto tt = torch::full({1}, 0.5);
  auto r_on = x_from_v(on.input.x, on.v_true, sch.alpha(tt), sch.sigma(tt));
  for (int64_t t = 1; t < T; t += 2) {
    auto blend = (c.frames.select(1, t - 1) + c.frames.select(1, t + 1)) / 2;
    EXPECT_TRUE(torch::allclose(on.input.cond_image.select(1, t), blend, 1e-5, 1e-6)) << "frame " << t;
    EXPECT_EQ(off.input.cond_image.select(1, t).abs().max().item<float>(), 0.0f) << "off: no coarse frame";
    EXPECT_TRUE(torch::allclose(r_on.select(1, t), c.frames.select(1, t) - blend, 1e-4, 1e-4)) << "residual " << t;
  }
}

TEST(DecoderResidual, SamplerStartsInBetweenFramesFromTheBlend) {
  Config c = test::config("tiny.yaml");
  ASSERT_TRUE(c.decoder.interp_base);
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);  // fresh: v = 0
  torch::NoGradGuard ng;
  auto in = random_input(m, 1, 5, 32, 64, 6);
  WindowInput w;
  w.frames = in.x.clamp(-1, 1) * 0.5;
  w.context = torch::tensor({1.f, 0.f, 1.f, 0.f, 1.f}).unsqueeze(0);
  w.tokens = torch::full_like(in.tokens, m->K);  // upsampling: no tokens anywhere
  w.cond_image = torch::zeros_like(in.x);
  SampleOptions o;
  o.steps = 3;
  NoiseSchedule sch;
  auto a = sample_window(m, sch, w, o);
  m->cfg.interp_base = false;
  auto b = sample_window(m, sch, w, o);
  for (int64_t t : {1, 3}) {
    auto blend = (w.frames.select(1, t - 1) + w.frames.select(1, t + 1)) / 2;
    auto ga = a.select(1, t), gb = b.select(1, t);
    auto inside = (ga.abs() < 0.999) & (gb.abs() < 0.999);
    ASSERT_GT(inside.sum().item<int64_t>(), 1000);
    EXPECT_LT(((ga - gb - blend) * inside).abs().max().item<double>(), 1e-5) << "frame " << t;
  }
}

// A decoder file as saved before the config key `key` existed: its metadata's config lacks that line.
void save_without_key(VideoUNet& m, Config& c, const std::string& key, const fs::path& path) {
  std::string yaml = c.to_yaml(), old;
  std::istringstream lines(yaml);
  for (std::string l; std::getline(lines, l);)
    if (l.find(key) == std::string::npos) old += l + "\n";
  ASSERT_NE(old, yaml) << key;
  save_module(*m, path,
              {{"gaia.component", "decoder"}, {"gaia.config", old}, {"gaia.decoder.K", std::to_string(m->K)},
               {"gaia.decoder.D", std::to_string(m->D)}});
}

// Decoder files from before decoder.interp_base were trained with zero coarse frames between known ones: they load
// with it off; files saved now keep what they were trained with.
TEST(DecoderResidual, OldDecoderFilesLoadWithoutTheInterpolationBase) {
  test::TempDir dir;
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
  save_decoder(m, c, dir.path / "new.safetensors");
  Config back;
  load_decoder(dir.path / "new.safetensors", torch::kCPU, &back);
  EXPECT_TRUE(back.decoder.interp_base);
  save_without_key(m, c, "interp_base", dir.path / "old.safetensors");
  load_decoder(dir.path / "old.safetensors", torch::kCPU, &back);
  EXPECT_FALSE(back.decoder.interp_base);
}

// Decoder files from before decoder.start_time: with a coarse frame they take the default start; a decoder without
// one (the paper's setting) starts from pure noise, since nothing else is there to start from.
TEST(DecoderResidual, OldDecoderFilesTakeAStartTheyCanUse) {
  test::TempDir dir;
  Config back;
  for (bool cond : {true, false}) {
    Config c = test::config("tiny.yaml");
    c.decoder.cond_image = cond;
    c.decoder.interp_base = cond;
    c.decoder.start_time = cond ? 0.7 : 1.0;
    VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);
    save_decoder(m, c, dir.path / "new.safetensors");
    load_decoder(dir.path / "new.safetensors", torch::kCPU, &back);
    EXPECT_EQ(back.decoder.start_time, c.decoder.start_time);  // saved now: kept
    save_without_key(m, c, "start_time", dir.path / "old.safetensors");
    load_decoder(dir.path / "old.safetensors", torch::kCPU, &back);
    EXPECT_EQ(back.decoder.start_time, cond ? Config().decoder.start_time : 1.0) << "cond_image " << cond;
  }
}

// decoder.noise_correlation: each frame's starting noise stays N(0, I), any two frames of a window are correlated
// by r, windows of a batch stay independent, and r = 0 is the plain draw (so earlier samples are unchanged).
TEST(DecoderSampler, StartingNoiseCorrelatesTheFramesOfAWindow) {
  const std::vector<int64_t> sizes{2, 4, 3, 32, 32};
  auto g0 = at::detail::createCPUGenerator(5), g1 = at::detail::createCPUGenerator(5);
  EXPECT_TRUE(torch::equal(starting_noise(sizes, 0.0, g0), torch::randn(sizes, g1, torch::kFloat32)));
  auto g = at::detail::createCPUGenerator(6);
  auto z = starting_noise(sizes, 0.6, g).to(torch::kFloat64);
  auto corr = [](const torch::Tensor& a, const torch::Tensor& b) {
    auto x = a.flatten() - a.mean(), y = b.flatten() - b.mean();
    return ((x * y).sum() / (x.norm() * y.norm())).item<double>();
  };
  for (int64_t t = 0; t < 4; ++t) {
    EXPECT_NEAR(z.select(1, t).mean().item<double>(), 0.0, 0.05) << "frame " << t;
    EXPECT_NEAR(z.select(1, t).std().item<double>(), 1.0, 0.05) << "frame " << t;
  }
  EXPECT_NEAR(corr(z.select(1, 0), z.select(1, 2)), 0.6, 0.05);
  EXPECT_NEAR(corr(z.select(1, 1), z.select(1, 3)), 0.6, 0.05);
  EXPECT_NEAR(corr(z[0], z[1]), 0.0, 0.05);  // the two windows of the batch
  auto one = starting_noise(sizes, 1.0, g);
  EXPECT_TRUE(torch::equal(one.select(1, 0), one.select(1, 3)));
  EXPECT_NE(test::error_of([&] { starting_noise(sizes, 1.5, g); }).find("decoder.noise_correlation"), std::string::npos);
  Config c = test::config("tiny.yaml");
  c.decoder.noise_correlation = -0.1;
  EXPECT_NE(test::error_of([&] { c.validate(); }).find("decoder.noise_correlation"), std::string::npos);
}

// A window in which every frame of `in` is generated from its tokens (no context); the caller sets the coarse frames.
static WindowInput all_frames_generated(const VideoUNet& m, const DenoiserInput& in) {
  WindowInput w;
  w.frames = torch::zeros_like(in.x);
  w.context = torch::zeros({in.x.size(0), in.x.size(1)});
  w.tokens = in.tokens.clamp_max(m->K - 1);
  return w;
}

// The sampler draws its starting noise with the option: a fresh model (v = 0) maps each frame's noise to its output,
// so with r = 1 frames with the same coarse image come out equal, and with r = 0 they do not.
TEST(DecoderSampler, SampleWindowUsesTheNoiseCorrelation) {
  Config c = test::config("tiny.yaml");
  VideoUNet m(c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample);  // fresh: v = 0
  torch::NoGradGuard ng;
  auto in = random_input(m, 1, 5, 32, 64, 8);
  auto w = all_frames_generated(m, in);
  w.cond_image = (in.cond_image.select(1, 0).unsqueeze(1) * 0.3).expand_as(in.x).contiguous();
  NoiseSchedule sch;
  auto o = sample_options(c.decoder, 3, 11);
  EXPECT_EQ(o.steps, 3);
  EXPECT_EQ(sample_options(c.decoder, 0, 11).steps, c.decoder.ddim_steps);
  o.mix_probability = 0;
  o.noise_correlation = 1.0;
  auto a = sample_window(m, sch, w, o);
  EXPECT_LT((a.select(1, 0) - a.select(1, 4)).abs().max().item<double>(), 1e-6);
  o.noise_correlation = 0.0;
  auto b = sample_window(m, sch, w, o);
  EXPECT_GT((b.select(1, 0) - b.select(1, 4)).abs().mean().item<double>(), 0.01);
}

// A fresh model (v ~ 0: its output layer starts at zero, the rest does not) and a window of 5 frames to generate
// whose coarse frames are a random input's scaled by 0.3, for the tests of the starting noise.
struct FreshWindow {
  Config c = test::config("tiny.yaml");
  VideoUNet m{c.decoder, c.tokenizer.codebook_size, c.tokenizer.downsample};
  WindowInput w;
  NoiseSchedule sch;
  FreshWindow() {
    auto in = random_input(m, 1, 5, 32, 64, 8);
    w = all_frames_generated(m, in);
    w.cond_image = (in.cond_image * 0.3).contiguous();
  }
  torch::Tensor sample(const SampleOptions& o) { return sample_window(m, sch, w, o); }
};

// decoder.noise_scale: the temperature of the starting noise. With a fresh model (v ~ 0) DDIM is nearly linear in z_T,
// so the residual over the coarse frame scales with the option; at 0 the sampler returns the coarse frame whatever
// the seed.
TEST(DecoderSampler, NoiseScaleIsTheTemperatureOfTheStartingNoise) {
  FreshWindow f;
  auto o = sample_options(f.c.decoder, 3, 11);
  EXPECT_EQ(o.noise_scale, f.c.decoder.noise_scale);  // the config's
  o.noise_scale = 1;
  o.mix_probability = 0;
  auto full = f.sample(o);
  o.noise_scale = 0.5;
  auto half = f.sample(o);
  const auto base = f.w.cond_image.clamp(-1, 1);
  auto inside = (full.abs() < 0.999).logical_and(half.abs() < 0.999);  // away from the clamp
  ASSERT_GT(inside.sum().item<int64_t>(), 1000);
  auto r_full = (full - base).masked_select(inside), r_half = (half - base).masked_select(inside);
  EXPECT_GT(r_full.abs().mean().item<double>(), 0.05);
  // The output layer of a fresh model is zero-initialised but the rest is not, so v is only near zero: the residual
  // shrinks with the noise rather than exactly with it.
  const double ratio = r_half.abs().mean().item<double>() / r_full.abs().mean().item<double>();
  EXPECT_NEAR(ratio, 0.5, 0.05);
  EXPECT_GT(torch::cosine_similarity(r_half, r_full, 0).item<double>(), 0.95);
  o.noise_scale = 0;
  auto zero = f.sample(o);
  o.seed = 12;
  EXPECT_TRUE(torch::allclose(zero, f.sample(o)));
  EXPECT_LT((zero - base).abs().max().item<double>(), 1e-6);
  o.noise_scale = 1.5;
  EXPECT_NE(test::error_of([&] { f.sample(o); }).find("decoder.noise_scale"), std::string::npos);
  f.c.decoder.noise_scale = -0.1;
  EXPECT_NE(test::error_of([&] { f.c.validate(); }).find("decoder.noise_scale"), std::string::npos);
}

// decoder.start_time < 1 starts from the coarse frame noised to that level. With v = 0 every DDIM step multiplies z by
// alpha_s alpha_t + sigma_s sigma_t, so a fresh model (v ~ 0) leaves a residual over the coarse frame of
// sigma(t0) n times the product of those factors over the grid from t0: the residual follows the start's noise
// level. Without a coarse frame a start below 1 is an error.
TEST(DecoderSampler, StartTimeRefinesTheCoarseFrame) {
  FreshWindow f;
  auto o = sample_options(f.c.decoder, 3, 11);
  EXPECT_EQ(o.start_time, f.c.decoder.start_time);  // the config's
  EXPECT_LT(o.start_time, 1.0);                   // the CPU default refines the coarse frame ...
  EXPECT_EQ(test::config("paper.yaml").decoder.start_time, 1.0);  // ... the paper's does not
  o.mix_probability = 0;
  o.noise_scale = 0.5;  // keeps the samples inside the clamp to [-1, 1]
  const auto base = f.w.cond_image.clamp(-1, 1);
  auto sample = [&](double start) {
    o.start_time = start;
    return f.sample(o);
  };
  auto at = [&](double t) { return torch::tensor({t}, torch::kFloat64); };
  auto v0_factor = [&](double start) {  // sigma(t0) prod (alpha_s alpha_t + sigma_s sigma_t)
    const auto g = ddim_times(3, start);
    const NoiseSchedule& sch = f.sch;
    double prod = start < 1 ? sch.sigma(at(start)).item<double>() : 1.0;
    for (size_t i = 0; i + 1 < g.size(); ++i)
      prod *= (sch.alpha(at(g[i])) * sch.alpha(at(g[i + 1])) + sch.sigma(at(g[i])) * sch.sigma(at(g[i + 1]))).item<double>();
    return prod;
  };
  const auto full = sample(1.0), half = sample(0.5), low = sample(0.2);
  auto inside = (full.abs() < 0.999).logical_and(half.abs() < 0.999).logical_and(low.abs() < 0.999);
  ASSERT_GT(inside.sum().item<int64_t>(), 1000);  // away from the clamp
  auto residual = [&](const torch::Tensor& x) { return (x - base).masked_select(inside).abs().mean().item<double>(); };
  const double r1 = residual(full);
  EXPECT_GT(r1, 0.05);
  EXPECT_NEAR(residual(half) / r1, v0_factor(0.5) / v0_factor(1.0), 0.05);
  EXPECT_NEAR(residual(low) / r1, v0_factor(0.2) / v0_factor(1.0), 0.05);
  EXPECT_LT(v0_factor(0.2) / v0_factor(1.0), 0.6);  // the test tells a start of 0.2 from one of 1
  o.start_time = 0.5;
  auto no_cond = f.w;
  no_cond.cond_image = torch::Tensor();
  EXPECT_NE(test::error_of([&] { sample_window(f.m, f.sch, no_cond, o); }).find("decoder.start_time"), std::string::npos);
  f.c.decoder.start_time = 0;
  EXPECT_NE(test::error_of([&] { f.c.validate(); }).find("decoder.start_time"), std::string::npos);
  f.c.decoder.start_time = 0.5;
  f.c.decoder.cond_image = false;
  EXPECT_NE(test::error_of([&] { f.c.validate(); }).find("decoder.cond_image"), std::string::npos);
}
