#include "gaia/tokenizer/io.h"

#include <cstring>

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"
#include "gaia/data/video_io.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::tokenizer {

void save_tokenizer(ImageTokenizer& t, const Config& c, const fs::path& path, bool half) {
  Config copy = c;
  save_module(*t, path, {{"gaia.component", "tokenizer"}, {"gaia.config", copy.to_yaml()}}, half);
}

ImageTokenizer load_tokenizer(const fs::path& path, const torch::Device& device, Config* config_out,
                              const Config* fallback) {
  Config c;
  int64_t dino_dim = 0;
  {
    SafetensorsFile f(path);
    auto md = f.metadata();
    if (md.count("gaia.config") && md["gaia.component"] == "tokenizer") {
      c.apply_yaml(md["gaia.config"], path.string() + " [metadata]");
    } else if (fallback && f.contains("quantizer.codebook.weight")) {
      c = *fallback;  // a checkpoint's weights: the caller's --config describes the architecture
    } else {
      fail("{}: not a gaia tokenizer weights file (no gaia.config metadata; for checkpoint weights pass --config)", path.string());
    }
    c.validate();
    if (f.contains("dino_head.weight")) dino_dim = f.get("dino_head.weight").shape[0];
  }
  ImageTokenizer t(c, dino_dim);
  load_module(*t, path);
  t->to(device);
  t->eval();
  if (config_out) *config_out = c;
  return t;
}

torch::Tensor encode_rgb(ImageTokenizer& t, const torch::Tensor& rgb, const torch::Device& device) {
  if (rgb.dim() != 4 || rgb.size(1) != t->height || rgb.size(2) != t->width || rgb.size(3) != 3 ||
      rgb.scalar_type() != torch::kUInt8)
    fail("tokenizer: frames must be uint8 [N, {}, {}, 3] (the tokenizer's size), got {} {}", t->height, t->width,
         c10::toString(rgb.scalar_type()), shape_str(rgb.sizes().vec()));
  if (rgb.size(0) == 0) fail("tokenizer: no frames to encode");
  torch::NoGradGuard ng;
  std::vector<torch::Tensor> out;
  const int64_t B = 16;
  for (int64_t s = 0; s < rgb.size(0); s += B) {
    auto x = rgb.slice(0, s, std::min(rgb.size(0), s + B)).permute({0, 3, 1, 2}).to(torch::kFloat32);
    out.push_back(t->tokenize(x.div(127.5).sub(1.0).contiguous().to(device)).to(torch::kCPU));
  }
  return torch::cat(out);
}

torch::Tensor decode_rgb(ImageTokenizer& t, const torch::Tensor& tokens, const torch::Device& device) {
  torch::NoGradGuard ng;
  std::vector<torch::Tensor> out;
  const int64_t B = 16;
  for (int64_t s = 0; s < tokens.size(0); s += B) {
    auto x = t->decode_tokens(tokens.slice(0, s, std::min(tokens.size(0), s + B)).to(device).to(torch::kLong));
    out.push_back(x.detach().to(torch::kCPU).clamp(-1, 1).add(1).mul(127.5).round().to(torch::kUInt8).permute({0, 2, 3, 1}));
  }
  return torch::cat(out).contiguous();
}

torch::Tensor encode_frames(ImageTokenizer& t, const std::vector<cv::Mat>& frames, const torch::Device& device) {
  if (frames.empty()) fail("tokenizer: no frames to encode");
  std::vector<torch::Tensor> bgr;
  for (size_t i = 0; i < frames.size(); ++i) {
    const cv::Mat& f = frames[i];
    if (f.rows != t->height || f.cols != t->width || f.type() != CV_8UC3)
      fail("tokenizer: frame {} is {}x{}, the tokenizer was trained at {}x{}", i, f.rows, f.cols, t->height, t->width);
    cv::Mat c = f.isContinuous() ? f : f.clone();
    bgr.push_back(torch::from_blob(c.data, {c.rows, c.cols, 3}, torch::kUInt8).clone());
  }
  return encode_rgb(t, torch::stack(bgr).flip({3}), device);
}

std::vector<cv::Mat> decode_tokens(ImageTokenizer& t, const torch::Tensor& tokens, const torch::Device& device) {
  auto bgr = decode_rgb(t, tokens, device).flip({3}).contiguous();
  std::vector<cv::Mat> out;
  for (int64_t i = 0; i < bgr.size(0); ++i) {
    cv::Mat m(t->height, t->width, CV_8UC3);
    std::memcpy(m.data, bgr[i].data_ptr(), size_t(bgr[i].numel()));
    out.push_back(m);
  }
  return out;
}

torch::Tensor video_prompt_tokens(ImageTokenizer& t, const Config& tok_cfg, const fs::path& video, int64_t frames,
                                  int64_t n, const torch::Device& device) {
  auto f = data::read_frames_at_rate(video, tok_cfg.data.world_fps, frames, tok_cfg.data.height, tok_cfg.data.width);
  auto tokens = encode_frames(t, f, device).reshape({int64_t(f.size()), -1}).to(torch::kCPU);
  if (tokens.size(1) != n)
    fail("{}: the tokenizer gives {} tokens per frame, the world model takes {}", video.string(), tokens.size(1), n);
  return tokens;
}

}  // namespace gaia::tokenizer
