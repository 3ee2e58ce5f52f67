#include "gaia/decoder/sampler.h"

#include <cmath>

#include "gaia/core/error.h"
#include "gaia/decoder/tasks.h"

namespace gaia::decoder {

torch::Tensor ddim_loop(torch::Tensor z, int steps, const NoiseSchedule& sched,
                        const std::function<torch::Tensor(const torch::Tensor&, double)>& v_fn, double start) {
  if (steps < 1) fail("decoder: DDIM needs at least 1 step, got {}", steps);
  if (!(start > 0 && start <= 1)) fail("decoder.start_time must be in (0, 1], got {}", start);
  auto times = ddim_times(steps, start);
  auto opt = torch::TensorOptions().dtype(torch::kFloat64);
  for (int i = 0; i < steps; ++i) {
    const double t = times[size_t(i)], s = times[size_t(i) + 1];
    auto tt = torch::tensor({t}, opt), ss = torch::tensor({s}, opt);
    const double at = sched.alpha(tt).item<double>(), st = sched.sigma(tt).item<double>();
    const double as = sched.alpha(ss).item<double>(), sg = sched.sigma(ss).item<double>();
    auto v = v_fn(z, t);
    auto x_hat = at * z - st * v, eps_hat = st * z + at * v;
    z = as * x_hat + sg * eps_hat;
  }
  return z;
}

torch::Tensor starting_noise(at::IntArrayRef sizes, double correlation, at::Generator& gen) {
  if (!(correlation >= 0 && correlation <= 1)) fail("decoder.noise_correlation must be in [0, 1], got {}", correlation);
  if (sizes.size() < 2) fail("decoder: starting noise needs [B, T, ...], got {} dimensions", sizes.size());
  auto z = torch::randn(sizes, gen, torch::kFloat32);
  if (correlation == 0) return z;
  auto shared_sizes = sizes.vec();
  shared_sizes[1] = 1;  // [B, 1, ...]: one draw for every frame of the window, after z so r = 0 is unchanged
  auto shared = torch::randn(shared_sizes, gen, torch::kFloat32);
  return std::sqrt(correlation) * shared + std::sqrt(1 - correlation) * z;
}

SampleOptions sample_options(const DecoderConfig& cfg, int steps, uint64_t seed) {
  SampleOptions o;
  o.steps = steps > 0 ? steps : cfg.ddim_steps;
  o.mix_probability = cfg.mix_probability;
  o.mix_weight = cfg.mix_weight;
  o.noise_correlation = cfg.noise_correlation;
  o.noise_scale = cfg.noise_scale;
  o.start_time = cfg.start_time;
  o.seed = seed;
  return o;
}

torch::Tensor sample_window(VideoUNet& model, const NoiseSchedule& sched, const WindowInput& in, const SampleOptions& o) {
  torch::NoGradGuard ng;
  const int64_t B = in.frames.size(0), T = in.frames.size(1);
  const auto has_tokens = (in.tokens != model->K).flatten(2).any(2);  // [B, T]
  // Frames between known ones start from the blend of their neighbours (diffusion.h interpolation_base).
  auto cond_image = in.cond_image;
  if (cond_image.defined() && model->cfg.interp_base)
    cond_image = interpolation_base(cond_image, in.frames, in.context, has_tokens);
  // Diffusion runs on the residual over the coarse image (diffusion.h coarse_base); context frames are given as theirs.
  const auto base = coarse_base(cond_image, in.frames);
  const auto x0 = in.frames - base;
  auto ctx = in.context.to(x0.dtype()).view({B, T, 1, 1, 1});
  auto gen = at::detail::createCPUGenerator(o.seed);
  if (!(o.noise_scale >= 0 && o.noise_scale <= 1)) fail("decoder.noise_scale must be in [0, 1], got {}", o.noise_scale);
  if (o.start_time < 1 && !cond_image.defined())
    fail("decoder.start_time < 1 needs decoder.cond_image (the coarse frame the sampler starts from)");
  // z at the start time for a zero residual: sigma(start) n (sigma(1) is 1 to 1e-7; the paper's start uses n as is).
  const double sigma_start =
      o.start_time < 1 ? sched.sigma(torch::tensor({o.start_time}, torch::kFloat64)).item<double>() : 1.0;
  auto z = (sigma_start * o.noise_scale * starting_noise(x0.sizes(), o.noise_correlation, gen)).to(x0.options());
  std::mt19937_64 rng(o.seed ^ 0x9e3779b97f4a7c15ULL);
  std::bernoulli_distribution mix(o.mix_probability);
  DenoiserInput di;
  di.context = in.context;
  di.tokens = in.tokens;
  di.cond_image = cond_image;
  di.rate = torch::full({B}, in.rate, torch::TensorOptions().dtype(torch::kLong).device(x0.device()));
  // Image/video mixing applies to the frames decoded from their tokens. A frame with neither tokens nor context
  // (interpolation) is defined only by its neighbours: with the temporal layers off, the image term would pull it
  // towards an unconditional sample.
  const bool any_tokens = has_tokens.any().item<bool>();  // upsampling windows have none: skip the image pass
  const auto mix_w = o.mix_weight * has_tokens.to(x0.dtype()).view({B, T, 1, 1, 1});
  auto v_fn = [&](const torch::Tensor& zt, double t) {
    di.x = ctx * x0 + (1 - ctx) * zt;  // context frames clean, the rest at noise level t
    di.time = (1 - in.context.to(torch::kFloat32)) * float(t);
    di.temporal = in.temporal;
    Autocast autocast(o.precision, x0.device());  // the U-Net's products; the DDIM arithmetic stays float32
    auto v = model->forward(di).to(torch::kFloat);
    if (in.temporal && o.mix_probability > 0 && mix(rng) && any_tokens) {  // the draw happens either way
      di.temporal = false;  // §5.2: denoise every frame as an image, average with the video prediction
      v = mix_w * model->forward(di).to(torch::kFloat) + (1 - mix_w) * v;
    }
    return v;
  };
  z = ddim_loop(z, o.steps, sched, v_fn, o.start_time);
  return (ctx * in.frames + (1 - ctx) * (z + base)).clamp(-1, 1);
}

std::vector<Window> backward_windows(int64_t N, int T) {
  if (N < 1) fail("decoder: nothing to decode (0 frames)");
  std::vector<Window> w;
  if (N <= T) {
    w.push_back({0, std::vector<bool>(size_t(N), false)});
    return w;
  }
  int64_t first = N - T;  // first frame decoded so far
  w.push_back({first, std::vector<bool>(size_t(T), false)});
  while (first > 0) {
    const int64_t start = std::max<int64_t>(0, first - (T - kOverlapFrames));
    Window x{start, std::vector<bool>(size_t(T), false)};
    for (int64_t i = 0; i < T; ++i) x.context[size_t(i)] = start + i >= first;
    w.push_back(x);
    first = start;
  }
  return w;
}

std::vector<Window> upsample_windows(int64_t M, int T) {
  if (T % 2 == 0) fail("decoder: upsampling windows need an odd number of frames, got {}", T);
  std::vector<Window> w;
  for (int64_t s = 0; s + 1 < M; s += T - 1) {
    const int64_t len = std::min<int64_t>(T, M - s);
    Window x{s, std::vector<bool>(size_t(len), false)};
    for (int64_t i = 0; i < len; ++i) x.context[size_t(i)] = (s + i) % 2 == 0;
    w.push_back(x);
  }
  return w;
}

}  // namespace gaia::decoder
