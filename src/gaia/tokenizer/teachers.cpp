#include "gaia/tokenizer/teachers.h"

#include <cmath>
#include <map>
#include <regex>

#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"
#include "gaia/torch/attention.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::tokenizer {

namespace F = torch::nn::functional;

torch::Tensor imagenet_normalize(const torch::Tensor& x) {
  auto mean = torch::tensor({0.485, 0.456, 0.406}, x.options()).view({1, 3, 1, 1});
  auto std = torch::tensor({0.229, 0.224, 0.225}, x.options()).view({1, 3, 1, 1});
  return ((x + 1) * 0.5 - mean) / std;
}

namespace {
// torchvision's VGG16 `features`: conv indices; max-pools follow 3, 8, 15, 22, 29 (the relus we tap).
const int kConv[] = {0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26, 28};
const int kTap[] = {3, 8, 15, 22, 29};

std::map<std::string, torch::Tensor> read_all(const fs::path& p) {
  SafetensorsFile f(p);
  std::map<std::string, torch::Tensor> out;
  for (auto& n : f.names()) out[n] = tensor_from_view(f.get(n)).to(torch::kFloat32);
  return out;
}

torch::Tensor need(const std::map<std::string, torch::Tensor>& sd, const fs::path& p, const std::string& name) {
  auto it = sd.find(name);
  if (it == sd.end()) fail("{}: missing tensor '{}' (not a VGG16/ViT teacher in the expected layout?)", p.string(), name);
  return it->second;
}

void copy_into(torch::Tensor dst, const torch::Tensor& src, const fs::path& p, const std::string& name) {
  if (dst.sizes() != src.sizes())
    fail("{}: tensor '{}' has shape {}, expected {}", p.string(), name, c10::str(src.sizes()), c10::str(dst.sizes()));
  dst.copy_(src);
}
}  // namespace

Vgg16Impl::Vgg16Impl(const fs::path& weights) {
  if (!fs::exists(weights)) fail("{}: no such VGG16 weights file", weights.string());
  auto sd = read_all(weights);
  int64_t cin = 3;
  size_t ci = 0;
  for (int i = 0; i <= 30; ++i) {
    if (ci < 13 && kConv[ci] == i) {
      auto w = need(sd, weights, fmt::format("features.{}.weight", i));
      if (w.dim() != 4 || w.size(1) != cin || w.size(2) != 3)
        fail("{}: features.{}.weight has shape {}, expected [*, {}, 3, 3]", weights.string(), i, c10::str(w.sizes()), cin);
      int64_t cout = w.size(0);
      features->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(cin, cout, 3).padding(1)));
      cin = cout;
      ++ci;
    } else if (i == 4 || i == 9 || i == 16 || i == 23 || i == 30) {
      features->push_back(torch::nn::MaxPool2d(torch::nn::MaxPool2dOptions(2).stride(2)));
    } else {
      features->push_back(torch::nn::ReLU());
    }
  }
  register_module("features", features);
  torch::NoGradGuard ng;
  for (auto& p : named_parameters(true)) copy_into(p.value(), need(sd, weights, p.key()), weights, p.key());
  for (auto& p : parameters()) p.set_requires_grad(false);
  eval();
}

std::vector<torch::Tensor> Vgg16Impl::forward(const torch::Tensor& x) {
  std::vector<torch::Tensor> taps;
  auto h = imagenet_normalize(x);
  size_t t = 0;
  for (size_t i = 0; i < features->size() && t < 5; ++i) {
    h = features[i]->as<torch::nn::Conv2d>() ? features[i]->as<torch::nn::Conv2d>()->forward(h)
        : features[i]->as<torch::nn::ReLU>() ? features[i]->as<torch::nn::ReLU>()->forward(h)
                                             : features[i]->as<torch::nn::MaxPool2d>()->forward(h);
    if (static_cast<int>(i) == kTap[t]) { taps.push_back(h); ++t; }
  }
  return taps;
}

torch::Tensor perceptual_loss(Vgg16& vgg, const torch::Tensor& x, const torch::Tensor& y) {
  auto fx = vgg->forward(x), fy = vgg->forward(y);
  torch::Tensor loss = torch::zeros({}, x.options());
  for (size_t i = 0; i < fx.size(); ++i) {
    auto a = fx[i] / (fx[i].pow(2).sum(1, true).sqrt() + 1e-10);
    auto b = fy[i] / (fy[i].pow(2).sum(1, true).sqrt() + 1e-10);
    loss = loss + (a - b).pow(2).sum(1).mean();
  }
  return loss / static_cast<double>(fx.size());
}

ViTBlockImpl::ViTBlockImpl(int64_t d, int64_t h, int64_t mlp) : heads(h) {
  norm1 = register_module("norm1", torch::nn::LayerNorm(torch::nn::LayerNormOptions({d}).eps(1e-6)));
  qkv = register_module("qkv", torch::nn::Linear(d, 3 * d));
  proj = register_module("proj", torch::nn::Linear(d, d));
  norm2 = register_module("norm2", torch::nn::LayerNorm(torch::nn::LayerNormOptions({d}).eps(1e-6)));
  fc1 = register_module("fc1", torch::nn::Linear(d, mlp));
  fc2 = register_module("fc2", torch::nn::Linear(mlp, d));
}

torch::Tensor ViTBlockImpl::forward(const torch::Tensor& x) {
  const auto B = x.size(0), N = x.size(1), D = x.size(2), hd = D / heads;
  auto q_k_v = qkv(norm1(x)).reshape({B, N, 3, heads, hd}).permute({2, 0, 3, 1, 4});  // [3, B, heads, N, hd]
  auto y = attention(q_k_v[0], q_k_v[1], q_k_v[2]).transpose(1, 2).reshape({B, N, D});
  auto h = x + proj(y);
  return h + fc2(F::gelu(fc1(norm2(h))));
}

DinoViTImpl::DinoViTImpl(const fs::path& weights) {
  if (!fs::exists(weights)) fail("{}: no such DINO ViT weights file", weights.string());
  SafetensorsFile file(weights);
  auto sd = read_all(weights);
  // torchvision layout -> timm layout
  if (sd.count("conv_proj.weight")) {
    std::map<std::string, torch::Tensor> m;
    static const std::regex layer_re("encoder\\.layers\\.encoder_layer_(\\d+)\\.(.*)");
    for (auto& [k, v] : sd) {
      std::smatch mm;
      if (k == "conv_proj.weight") m["patch_embed.proj.weight"] = v;
      else if (k == "conv_proj.bias") m["patch_embed.proj.bias"] = v;
      else if (k == "class_token") m["cls_token"] = v;
      else if (k == "encoder.pos_embedding") m["pos_embed"] = v;
      else if (k == "encoder.ln.weight") m["norm.weight"] = v;
      else if (k == "encoder.ln.bias") m["norm.bias"] = v;
      else if (std::regex_match(k, mm, layer_re)) {
        static const std::map<std::string, std::string> sub = {
            {"ln_1.weight", "norm1.weight"}, {"ln_1.bias", "norm1.bias"},
            {"self_attention.in_proj_weight", "attn.qkv.weight"}, {"self_attention.in_proj_bias", "attn.qkv.bias"},
            {"self_attention.out_proj.weight", "attn.proj.weight"}, {"self_attention.out_proj.bias", "attn.proj.bias"},
            {"ln_2.weight", "norm2.weight"}, {"ln_2.bias", "norm2.bias"},
            {"mlp.0.weight", "mlp.fc1.weight"}, {"mlp.0.bias", "mlp.fc1.bias"},
            {"mlp.3.weight", "mlp.fc2.weight"}, {"mlp.3.bias", "mlp.fc2.bias"},
            {"mlp.linear_1.weight", "mlp.fc1.weight"}, {"mlp.linear_1.bias", "mlp.fc1.bias"},
            {"mlp.linear_2.weight", "mlp.fc2.weight"}, {"mlp.linear_2.bias", "mlp.fc2.bias"}};
        auto it = sub.find(mm[2].str());
        if (it != sub.end()) m["blocks." + mm[1].str() + "." + it->second] = v;
      }
    }
    sd = std::move(m);
  }
  auto pw = need(sd, weights, "patch_embed.proj.weight");
  dim = pw.size(0);
  patch = pw.size(2);
  pos_embed = register_parameter("pos_embed", need(sd, weights, "pos_embed").clone(), false);
  cls_token = register_parameter("cls_token", need(sd, weights, "cls_token").clone(), false);
  grid = static_cast<int64_t>(std::lround(std::sqrt(double(pos_embed.size(1) - 1))));
  if (grid * grid != pos_embed.size(1) - 1) fail("{}: pos_embed has {} entries, not 1 + a square grid", weights.string(), pos_embed.size(1));
  auto md = file.metadata();
  heads = md.count("num_heads") ? std::stoll(md.at("num_heads")) : std::max<int64_t>(1, dim / 64);
  int64_t depth = 0;
  while (sd.count(fmt::format("blocks.{}.attn.qkv.weight", depth))) ++depth;
  if (depth == 0) fail("{}: no transformer blocks found", weights.string());
  int64_t mlp = need(sd, weights, "blocks.0.mlp.fc1.weight").size(0);
  patch_embed = register_module("patch_embed", torch::nn::Conv2d(torch::nn::Conv2dOptions(3, dim, patch).stride(patch)));
  for (int64_t i = 0; i < depth; ++i) blocks->push_back(ViTBlock(dim, heads, mlp));
  register_module("blocks", blocks);
  norm = register_module("norm", torch::nn::LayerNorm(torch::nn::LayerNormOptions({dim}).eps(1e-6)));
  torch::NoGradGuard ng;
  auto rename = [](const std::string& k) {  // our module names -> timm names
    std::string s = std::regex_replace(k, std::regex("^patch_embed\\."), "patch_embed.proj.");
    s = std::regex_replace(s, std::regex("^(blocks\\.\\d+)\\.(qkv|proj)\\."), "$1.attn.$2.");
    s = std::regex_replace(s, std::regex("^(blocks\\.\\d+)\\.(fc1|fc2)\\."), "$1.mlp.$2.");
    return s;
  };
  for (auto& p : named_parameters(true)) {
    if (p.key() == "pos_embed" || p.key() == "cls_token") continue;
    std::string name = rename(p.key());
    copy_into(p.value(), need(sd, weights, name), weights, name);
  }
  for (auto& p : parameters()) p.set_requires_grad(false);
  eval();
}

torch::Tensor DinoViTImpl::forward(const torch::Tensor& x) {
  auto p = patch_embed(imagenet_normalize(x));  // [B, D, h, w]
  const auto B = p.size(0), h = p.size(2), w = p.size(3);
  auto tokens = p.flatten(2).transpose(1, 2);    // [B, h w, D]
  // Interpolate the position grid to this image's patch grid (as DINO does for other resolutions).
  auto pe_cls = pos_embed.slice(1, 0, 1), pe = pos_embed.slice(1, 1);
  if (h != grid || w != grid) {
    pe = pe.reshape({1, grid, grid, dim}).permute({0, 3, 1, 2});
    pe = F::interpolate(pe, F::InterpolateFuncOptions().size(std::vector<int64_t>{h, w}).mode(torch::kBicubic).align_corners(false));
    pe = pe.permute({0, 2, 3, 1}).reshape({1, h * w, dim});
  }
  auto seq = torch::cat({cls_token.expand({B, 1, dim}) + pe_cls, tokens + pe}, 1);
  for (auto& b : *blocks) seq = b->as<ViTBlock>()->forward(seq);
  seq = norm(seq);
  return seq.slice(1, 1).transpose(1, 2).reshape({B, dim, h, w});
}

}  // namespace gaia::tokenizer
