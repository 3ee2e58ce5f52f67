#include "gaia/tokenizer/io.h"

#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"
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

torch::Tensor encode_frames(ImageTokenizer& t, const std::vector<cv::Mat>& frames, const torch::Device& device) {
  if (frames.empty()) fail("tokenizer: no frames to encode");
  torch::NoGradGuard ng;
  std::vector<torch::Tensor> out;
  const size_t B = 16;
  for (size_t s = 0; s < frames.size(); s += B) {
    std::vector<torch::Tensor> xs;
    for (size_t i = s; i < std::min(frames.size(), s + B); ++i) {
      const cv::Mat& f = frames[i];
      if (f.rows != t->height || f.cols != t->width || f.type() != CV_8UC3)
        fail("tokenizer: frame {} is {}x{}, the tokenizer was trained at {}x{}", i, f.rows, f.cols, t->height, t->width);
      cv::Mat c = f.isContinuous() ? f : f.clone();
      xs.push_back(image_to_tensor(c.data, c.rows, c.cols));
    }
    out.push_back(t->tokenize(torch::stack(xs).to(device)).to(torch::kCPU));
  }
  return torch::cat(out);
}

std::vector<cv::Mat> decode_tokens(ImageTokenizer& t, const torch::Tensor& tokens, const torch::Device& device) {
  torch::NoGradGuard ng;
  std::vector<cv::Mat> out;
  const int64_t B = 16;
  for (int64_t s = 0; s < tokens.size(0); s += B) {
    auto x = t->decode_tokens(tokens.slice(0, s, std::min(tokens.size(0), s + B)).to(device).to(torch::kLong));
    for (int64_t i = 0; i < x.size(0); ++i) {
      cv::Mat m(t->height, t->width, CV_8UC3);
      tensor_to_image(x[i], m.data);
      out.push_back(m);
    }
  }
  return out;
}

}  // namespace gaia::tokenizer
