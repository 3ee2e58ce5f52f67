#include "gaia/decoder/video.h"

#include "gaia/core/error.h"
#include "gaia/decoder/tasks.h"

namespace gaia::decoder {

namespace {

int doublings(double token_fps, double out_fps) {
  for (int d = 0; d <= 2; ++d)
    if (std::abs(token_fps * (1 << d) - out_fps) < 1e-6) return d;
  fail("decoder: output rate {} Hz is not the token rate {} Hz times 1, 2 or 4", out_fps, token_fps);
}

// Window tensors of a sequence [B, M, ...] at the window's frames.
torch::Tensor slice(const torch::Tensor& x, int64_t start, int64_t len) { return x.slice(1, start, start + len); }

}  // namespace

int count_windows(int64_t N, int frames, double token_fps, double out_fps) {
  int n = int(backward_windows(N, frames).size());
  int64_t M = N;
  for (int d = 0; d < doublings(token_fps, out_fps); ++d) {
    M = 2 * M - 1;
    n += int(upsample_windows(M, frames).size());
  }
  return n;
}

torch::Tensor upsample_video(VideoUNet& model, const NoiseSchedule& sched, const torch::Tensor& frames, int out_rate,
                             const SampleOptions& o, const std::function<void()>& on_window) {
  // frames [B, M, 3, H, W] -> [B, 2M - 1, 3, H, W]
  const int64_t B = frames.size(0), M = frames.size(1), H = frames.size(3), W = frames.size(4);
  const int64_t M2 = 2 * M - 1, h = H / model->D, w = W / model->D;
  auto out = torch::zeros({B, M2, 3, H, W}, frames.options());
  out.index_put_({torch::indexing::Slice(), torch::indexing::Slice(0, M2, 2)}, frames);
  auto no_tokens = torch::full({B, M2, h, w}, model->K, frames.options().dtype(torch::kLong));
  auto no_image = model->cfg.cond_image ? torch::zeros_like(out) : torch::Tensor();
  int k = 0;
  for (const auto& win : upsample_windows(M2, model->cfg.frames)) {
    const int64_t len = int64_t(win.context.size());
    WindowInput in;
    in.frames = slice(out, win.start, len);
    std::vector<float> c(win.context.begin(), win.context.end());
    in.context = torch::tensor(c).to(frames.device()).unsqueeze(0).expand({B, len}).contiguous();
    in.tokens = slice(no_tokens, win.start, len);
    if (no_image.defined()) in.cond_image = slice(no_image, win.start, len);
    in.rate = out_rate;
    SampleOptions so = o;
    so.seed = o.seed + 7919 * uint64_t(++k) + 104729 * uint64_t(out_rate);
    out.slice(1, win.start, win.start + len).copy_(sample_window(model, sched, in, so));
    if (on_window) on_window();
  }
  return out;
}

torch::Tensor decode_video(VideoUNet& model, const NoiseSchedule& sched, const torch::Tensor& tokens,
                           const torch::Tensor& cond, const DecodeOptions& o,
                           const std::function<void(int, int)>& progress) {
  torch::NoGradGuard ng;
  if (tokens.dim() != 4) fail("decoder: tokens must be [B, N, h, w], got {} dimensions", tokens.dim());
  const int64_t B = tokens.size(0), N = tokens.size(1), h = tokens.size(2), w = tokens.size(3);
  const int64_t H = h * model->D, W = w * model->D;
  if (N < 1) fail("decoder: nothing to decode (0 token frames)");
  if (tokens.min().item<int64_t>() < 0 || tokens.max().item<int64_t>() >= model->K)
    fail("decoder: token ids must be in [0, {}) (the tokenizer's codebook)", model->K);
  if (model->cfg.cond_image && (!cond.defined() || cond.sizes() != torch::IntArrayRef{B, N, 3, H, W}))
    fail("decoder: this decoder is conditioned on the tokenizer's decoded frames; they are missing or mis-shaped");
  const int T = model->cfg.frames;
  const int rate0 = rate_index(o.token_fps);
  const int total = count_windows(N, T, o.token_fps, o.out_fps);
  const int d = doublings(o.token_fps, o.out_fps);
  if (rate0 + d > 2) fail("decoder: {} Hz is above the highest rate the decoder is trained on (25 Hz)", o.out_fps);
  int done = 0;
  auto opts = torch::TensorOptions().device(tokens.device());
  auto frames = torch::zeros({B, N, 3, H, W}, opts);
  auto tok = tokens.to(torch::kLong);
  for (const auto& win : backward_windows(N, T)) {
    const int64_t len = int64_t(win.context.size());
    WindowInput in;
    in.frames = slice(frames, win.start, len);
    std::vector<float> c(win.context.begin(), win.context.end());
    auto ctx = torch::tensor(c).to(tokens.device());
    in.context = ctx.unsqueeze(0).expand({B, len}).contiguous();
    // Context frames carry no tokens (as in the training tasks); the others are decoded from theirs.
    auto has = (1 - ctx).to(torch::kLong).view({1, len, 1, 1});
    in.tokens = slice(tok, win.start, len) * has + model->K * (1 - has);
    if (model->cfg.cond_image) in.cond_image = slice(cond, win.start, len) * has.view({1, len, 1, 1, 1}).to(cond.dtype());
    in.rate = rate0;
    SampleOptions so = o.sample;
    so.seed = o.sample.seed + 7919 * uint64_t(done + 1);
    frames.slice(1, win.start, win.start + len).copy_(sample_window(model, sched, in, so));
    ++done;  // also seeds the next window: count whether or not anyone watches
    if (progress) progress(done, total);
  }
  for (int k = 1; k <= d; ++k)
    frames = upsample_video(model, sched, frames, rate0 + k, o.sample, [&] {
      ++done;
      if (progress) progress(done, total);
    });
  return frames;
}

}  // namespace gaia::decoder
