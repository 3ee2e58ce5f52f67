#include "gaia/decoder/pipeline.h"

#include <opencv2/core.hpp>

#include "gaia/core/error.h"
#include "gaia/decoder/io.h"
#include "gaia/tokenizer/io.h"

namespace gaia::decoder {

torch::Tensor coarse_frames(tokenizer::ImageTokenizer& tok, const torch::Tensor& ids, const torch::Device& dev) {
  torch::NoGradGuard ng;
  const int64_t F = ids.size(0), N = ids.size(1);
  std::vector<torch::Tensor> per_future;
  for (int64_t f = 0; f < F; ++f) {
    std::vector<torch::Tensor> parts;
    for (int64_t s = 0; s < N; s += 16)
      parts.push_back(tok->decode_tokens(ids[f].slice(0, s, std::min(N, s + 16)).to(dev).to(torch::kLong)).clamp(-1, 1));
    per_future.push_back(torch::cat(parts));
  }
  return torch::stack(per_future);
}

torch::Tensor diffusion_decode(tokenizer::ImageTokenizer& tok, const fs::path& weights, const torch::Tensor& ids,
                               const torch::Tensor& coarse, int steps, double token_fps, double out_fps, uint64_t seed,
                               const torch::Device& dev, const std::function<void(int, int)>& progress,
                               const std::function<void(Config&)>& configure, Precision precision) {
  Config dc;
  auto model = load_decoder(weights, dev, &dc);
  if (configure) configure(dc);
  if (model->K != tok->cfg.codebook_size || model->D != tok->cfg.downsample)
    fail("{}: the decoder was trained with K = {}, D = {}; the tokenizer has K = {}, D = {}", weights.string(),
         model->K, model->D, tok->cfg.codebook_size, tok->cfg.downsample);
  DecodeOptions o;
  o.sample = sample_options(dc.decoder, steps, seed);
  o.sample.precision = precision;
  o.token_fps = token_fps;
  o.out_fps = out_fps;
  NoiseSchedule sched{-15.0, 15.0, dc.decoder.schedule_shift};
  return decode_video(model, sched, ids.to(dev).to(torch::kLong), model->cfg.cond_image ? coarse : torch::Tensor(), o,
                      progress);
}

std::vector<cv::Mat> side_by_side(const torch::Tensor& v) {
  std::vector<cv::Mat> out;
  const int64_t F = v.size(0), M = v.size(1), H = v.size(3), W = v.size(4);
  auto cpu = v.to(torch::kCPU).contiguous();
  for (int64_t k = 0; k < M; ++k) {
    std::vector<cv::Mat> cols;
    for (int64_t f = 0; f < F; ++f) {
      cv::Mat m(int(H), int(W), CV_8UC3);
      tokenizer::tensor_to_image(cpu[f][k], m.data);
      cols.push_back(m);
    }
    cv::Mat frame;
    cv::hconcat(cols, frame);
    out.push_back(frame);
  }
  return out;
}

}  // namespace gaia::decoder
