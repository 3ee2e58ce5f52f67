#include "gaia/text/t5.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <optional>

#include <fmt/format.h>

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/core/safetensors.h"
#include "gaia/text/sentencepiece.h"
#include "gaia/torch/attention.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::text {

namespace nn = torch::nn;

T5Config T5Config::from_json_file(const fs::path& path) {
  const auto j = read_json(path);
  if (!j.is_object()) fail("{}: expected a JSON object (a Hugging Face T5 config)", path.string());
  auto positive = [&](const char* key, std::optional<int64_t> fallback = std::nullopt) -> int64_t {
    if (!j.contains(key)) {
      if (fallback) return *fallback;
      fail("{}: field '{}' is missing", path.string(), key);
    }
    const auto& v = j.at(key);
    if (!v.is_number_integer() || v.get<int64_t>() <= 0) fail("{}: field '{}' must be a positive integer", path.string(), key);
    return v.get<int64_t>();
  };
  T5Config c;
  c.vocab_size = positive("vocab_size");
  c.d_model = positive("d_model");
  c.d_kv = positive("d_kv");
  c.d_ff = positive("d_ff");
  c.num_layers = positive("num_layers");
  c.num_heads = positive("num_heads");
  // HF's defaults where a config leaves them out (the original T5 configs have no max_distance).
  c.num_buckets = positive("relative_attention_num_buckets", 32);
  c.max_distance = positive("relative_attention_max_distance", 128);
  if (c.num_buckets < 4) fail("{}: field 'relative_attention_num_buckets' must be at least 4", path.string());
  if (j.contains("layer_norm_epsilon")) {
    const auto& e = j.at("layer_norm_epsilon");
    if (!e.is_number() || !(e.get<double>() > 0)) fail("{}: field 'layer_norm_epsilon' must be a positive number", path.string());
    c.eps = e.get<double>();
  }
  const auto proj = j.value("feed_forward_proj", nlohmann::json("relu"));
  if (proj == "gated-gelu")
    c.gated_gelu = true;
  else if (proj != "relu")
    fail("{}: field 'feed_forward_proj' is {}; expected \"relu\" (T5) or \"gated-gelu\" (T5 v1.1)", path.string(), proj.dump());
  return c;
}

// T5's blocks, in a named namespace because T5Net (declared in t5.h) holds them.
namespace t5_blocks {

// Relative position (key - query) -> bucket, bidirectional as in T5's encoder (HF's _relative_position_bucket):
// half the buckets for keys after the query, half for the rest; within each half, distances below a quarter of the
// buckets get their own bucket and the others share log-spaced ones up to max_distance. The same float32 steps as
// HF's, so the boundaries fall where a checkpoint learnt them.
torch::Tensor relative_position_bucket(const torch::Tensor& rel, int64_t num_buckets, int64_t max_distance) {
  const int64_t half = num_buckets / 2, exact = half / 2;
  auto bucket = (rel > 0).to(torch::kLong) * half;
  const auto dist = rel.abs();
  // clamp_min: log(0) is never used (those are exact) but would turn into an undefined integer.
  auto far = exact + (torch::log(dist.clamp_min(exact).to(torch::kFloat) / exact) /
                      std::log(static_cast<double>(max_distance) / static_cast<double>(exact)) * (half - exact))
                         .to(torch::kLong);
  far = far.clamp_max(half - 1);
  return bucket + torch::where(dist < exact, dist, far);
}

// T5LayerNorm: scale by the root mean square (no mean subtraction, no bias), the variance taken in float32.
struct RmsNormImpl : nn::Module {
  torch::Tensor weight;
  double eps;
  RmsNormImpl(int64_t d, double eps) : eps(eps) { weight = register_parameter("weight", torch::ones({d})); }
  torch::Tensor forward(const torch::Tensor& x) {  // [..., d]
    const auto var = x.to(torch::kFloat).pow(2).mean(-1, /*keepdim=*/true);
    return weight * (x * torch::rsqrt(var + eps));
  }
};
TORCH_MODULE(RmsNorm);

nn::Linear linear(int64_t in, int64_t out) { return nn::Linear(nn::LinearOptions(in, out).bias(false)); }

// Multi-head self-attention without biases and without the 1/sqrt(d_kv) scaling (T5 folds it into the weights'
// initialisation). Block 0 owns the relative position bias that every block adds to its scores.
struct AttentionImpl : nn::Module {
  nn::Linear q{nullptr}, k{nullptr}, v{nullptr}, o{nullptr};
  nn::Embedding relative_attention_bias{nullptr};  // [num_buckets, heads], block 0 only
  int64_t heads, d_kv, num_buckets, max_distance;

  AttentionImpl(const T5Config& c, bool has_bias)
      : heads(c.num_heads), d_kv(c.d_kv), num_buckets(c.num_buckets), max_distance(c.max_distance) {
    const int64_t inner = c.num_heads * c.d_kv;
    q = register_module("q", linear(c.d_model, inner));
    k = register_module("k", linear(c.d_model, inner));
    v = register_module("v", linear(c.d_model, inner));
    o = register_module("o", linear(inner, c.d_model));
    if (has_bias) relative_attention_bias = register_module("relative_attention_bias", nn::Embedding(num_buckets, heads));
  }

  torch::Tensor position_bias(int64_t L, torch::Device device) {  // -> [1, H, L, L]
    const auto pos = torch::arange(L, torch::TensorOptions().dtype(torch::kLong).device(device));
    const auto buckets = relative_position_bucket(pos.unsqueeze(0) - pos.unsqueeze(1), num_buckets, max_distance);
    return relative_attention_bias(buckets).permute({2, 0, 1}).unsqueeze(0);
  }

  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& bias) {  // x [B, L, d], bias [B, H, L, L]
    const int64_t B = x.size(0), L = x.size(1);
    auto split = [&](const torch::Tensor& t) { return t.view({B, L, heads, d_kv}).transpose(1, 2); };  // [B, H, L, dk]
    // gaia::attention divides the scores by sqrt(d_kv); T5's are unscaled, so q carries the factor back.
    const auto y = attention(split(q(x)) * std::sqrt(double(d_kv)), split(k(x)), split(v(x)), bias);  // [B, H, L, dk]
    return o(y.transpose(1, 2).reshape({B, L, heads * d_kv}));
  }
};
TORCH_MODULE(Attention);

// Feed-forward: wi -> ReLU -> wo (T5), or gelu_new(wi_0) * wi_1 -> wo (T5 v1.1's gated GELU, tanh approximation).
struct DenseImpl : nn::Module {
  nn::Linear wi{nullptr}, wi_0{nullptr}, wi_1{nullptr}, wo{nullptr};
  explicit DenseImpl(const T5Config& c) {
    if (c.gated_gelu) {
      wi_0 = register_module("wi_0", linear(c.d_model, c.d_ff));
      wi_1 = register_module("wi_1", linear(c.d_model, c.d_ff));
    } else {
      wi = register_module("wi", linear(c.d_model, c.d_ff));
    }
    wo = register_module("wo", linear(c.d_ff, c.d_model));
  }
  torch::Tensor forward(const torch::Tensor& x) {  // [B, L, d] -> [B, L, d]
    if (!wi.is_empty()) return wo(torch::relu(wi(x)));
    return wo(torch::gelu(wi_0(x), "tanh") * wi_1(x));
  }
};
TORCH_MODULE(Dense);

// HF's layer.0 and layer.1 of a block: pre-norm residual sublayers.
struct SelfAttentionLayerImpl : nn::Module {
  Attention SelfAttention{nullptr};
  RmsNorm layer_norm{nullptr};
  SelfAttentionLayerImpl(const T5Config& c, bool has_bias) {
    SelfAttention = register_module("SelfAttention", Attention(c, has_bias));
    layer_norm = register_module("layer_norm", RmsNorm(c.d_model, c.eps));
  }
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& bias) { return x + SelfAttention(layer_norm(x), bias); }
};
TORCH_MODULE(SelfAttentionLayer);

struct FeedForwardLayerImpl : nn::Module {
  Dense DenseReluDense{nullptr};
  RmsNorm layer_norm{nullptr};
  explicit FeedForwardLayerImpl(const T5Config& c) {
    DenseReluDense = register_module("DenseReluDense", Dense(c));
    layer_norm = register_module("layer_norm", RmsNorm(c.d_model, c.eps));
  }
  torch::Tensor forward(const torch::Tensor& x) { return x + DenseReluDense(layer_norm(x)); }
};
TORCH_MODULE(FeedForwardLayer);

struct BlockImpl : nn::Module {
  SelfAttentionLayer attention{nullptr};
  FeedForwardLayer feed_forward{nullptr};
  BlockImpl(const T5Config& c, bool first) : attention(c, first), feed_forward(c) {
    auto layer = register_module("layer", nn::ModuleList());  // HF's names: layer.0, layer.1
    layer->push_back(attention);
    layer->push_back(feed_forward);
  }
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& bias) { return feed_forward(attention(x, bias)); }
};
TORCH_MODULE(Block);

struct StackImpl : nn::Module {
  std::vector<Block> blocks;
  RmsNorm final_layer_norm{nullptr};
  explicit StackImpl(const T5Config& c) {
    auto list = register_module("block", nn::ModuleList());
    for (int64_t i = 0; i < c.num_layers; ++i) {
      blocks.emplace_back(c, i == 0);
      list->push_back(blocks.back());
    }
    final_layer_norm = register_module("final_layer_norm", RmsNorm(c.d_model, c.eps));
  }
};
TORCH_MODULE(Stack);

// FNV-1a 64 over several byte ranges in turn.
struct Fnv {
  uint64_t h = 1469598103934665603ull;
  void add(const void* data, size_t n) {
    for (size_t i = 0; i < n; ++i) h = (h ^ static_cast<const uint8_t*>(data)[i]) * 1099511628211ull;
  }
};

}  // namespace t5_blocks

// Parameter names are HF's: shared.weight, encoder.block.{i}.layer.{0,1}...., encoder.final_layer_norm.weight.
struct T5Net : nn::Module {
  nn::Embedding shared{nullptr};
  t5_blocks::Stack encoder{nullptr};
  explicit T5Net(const T5Config& c) {
    shared = register_module("shared", nn::Embedding(c.vocab_size, c.d_model));
    encoder = register_module("encoder", t5_blocks::Stack(c));
  }
  torch::Tensor forward(const torch::Tensor& ids, const torch::Tensor& mask) {  // [B, L] long, [B, L] bool
    const int64_t L = ids.size(1);
    auto x = shared(ids);  // [B, L, d]; T5 does not scale its embeddings
    // Masked keys get the most negative float, as in HF, so a caption without tokens stays finite (all-masked rows
    // are zeroed afterwards anyway).
    const auto masked = torch::zeros(mask.sizes(), x.options())
                            .masked_fill(mask.logical_not(), std::numeric_limits<float>::lowest());
    const auto bias = encoder->blocks[0]->attention->SelfAttention->position_bias(L, x.device()) +
                      masked.view({-1, 1, 1, L});  // [B, H, L, L]
    for (auto& b : encoder->blocks) x = b(x, bias);
    return encoder->final_layer_norm(x);
  }
};

namespace {

// Copies the file's tensors into the modules by name; shapes must agree with config.json.
void load_weights(T5Net& net, const SafetensorsFile& file) {
  const fs::path& path = file.path();
  torch::NoGradGuard ng;
  for (auto& item : net.named_parameters()) {
    const std::string& name = item.key();
    torch::Tensor& param = item.value();
    std::string source = name;
    // A T5EncoderModel or a checkpoint saved with untied names keeps the embedding here only.
    if (name == "shared.weight" && !file.contains(name)) source = "encoder.embed_tokens.weight";
    if (!file.contains(source))
      fail("{}: missing tensor '{}'{}", path.string(), name, source != name ? " (or '" + source + "')" : "");
    const auto t = tensor_from_view(file.get(source));
    if (t.sizes() != param.sizes())
      fail("{}: tensor '{}' has shape {}, config.json implies {}", path.string(), source, shape_str(t.sizes().vec()),
           shape_str(param.sizes().vec()));
    if (!t.is_floating_point())
      fail("{}: tensor '{}' is {}, expected a float type", path.string(), source, c10::toString(t.scalar_type()));
    param.copy_(t.to(torch::kFloat));
  }
}

std::string checkpoint_identity(const fs::path& dir, const SafetensorsFile& file, const fs::path& spiece) {
  t5_blocks::Fnv fnv;
  // The header names every tensor with its dtype and shape; the first bytes of each tensor tell fine-tuned weights
  // of the same shapes apart without reading a whole multi-gigabyte file.
  std::ifstream in(file.path(), std::ios::binary);
  uint64_t n = 0;
  in.read(reinterpret_cast<char*>(&n), 8);
  std::string header(n, '\0');
  in.read(header.data(), static_cast<std::streamsize>(n));
  fnv.add(header.data(), header.size());
  for (const auto& name : file.names()) {
    const auto& v = file.get(name);
    fnv.add(v.data, std::min<size_t>(v.nbytes, 4096));
  }
  const std::string sp = read_file(spiece);
  fnv.add(sp.data(), sp.size());
  const auto name = dir.filename().empty() ? dir.parent_path().filename() : dir.filename();  // "dir/" too
  return fmt::format("t5:{}:{}", name.string(), fmt::format("{:016x}", fnv.h).substr(0, 12));
}

}  // namespace

T5Encoder::T5Encoder(const fs::path& dir, torch::Device device) : device_(device) {
  if (!fs::is_directory(dir)) fail("{}: not a directory (a T5 encoder's config.json, model.safetensors, spiece.model)", dir.string());
  const fs::path config = dir / "config.json", weights = dir / "model.safetensors", spiece = dir / "spiece.model";
  for (const auto& p : {config, weights, spiece})
    if (!fs::is_regular_file(p))
      fail("{}: missing (a T5 encoder directory holds config.json, model.safetensors and spiece.model)", p.string());
  config_ = T5Config::from_json_file(config);

  sp_ = std::make_unique<SentencePiece>(spiece);
  if (sp_->pad_id() != kPad || sp_->eos_id() != kEos)
    fail("{}: pad id {} and </s> id {}; T5 expects {} and {}", spiece.string(), sp_->pad_id(), sp_->eos_id(), kPad, kEos);
  if (sp_->size() > config_.vocab_size)
    fail("{}: {} pieces, more than config.json's vocab_size {}", spiece.string(), sp_->size(), config_.vocab_size);

  const SafetensorsFile file(weights);
  net_ = std::make_shared<T5Net>(config_);
  load_weights(*net_, file);
  for (auto& p : net_->parameters()) p.set_requires_grad(false);  // frozen (§2.1)
  net_->eval();
  net_->to(device_);
  identity_ = checkpoint_identity(dir, file, spiece);
}

T5Encoder::~T5Encoder() = default;
T5Encoder::T5Encoder(T5Encoder&&) noexcept = default;
T5Encoder& T5Encoder::operator=(T5Encoder&&) noexcept = default;

std::vector<int64_t> T5Encoder::tokenize(const std::string& text) const {
  std::vector<int64_t> ids = sp_->encode(text);
  ids.push_back(kEos);
  return ids;
}

torch::Tensor T5Encoder::encode(const std::vector<std::string>& captions, int64_t m) {
  if (m < 1) fail("T5 encoder: m = {} text tokens per step; need at least 1", m);
  const auto N = static_cast<int64_t>(captions.size());
  auto ids = torch::full({N, m}, kPad, torch::kLong);  // [N, m]
  auto mask = torch::zeros({N, m}, torch::kBool);      // [N, m]
  for (int64_t i = 0; i < N; ++i) {
    if (captions[i].empty()) continue;  // no text this step: all padding, all zeros out
    auto t = tokenize(captions[i]);
    if (static_cast<int64_t>(t.size()) > m) {
      t.resize(m);
      t.back() = kEos;  // HF truncates the pieces and then appends </s>
    }
    const auto n = static_cast<int64_t>(t.size());
    ids[i].slice(0, 0, n).copy_(torch::tensor(t, torch::kLong));
    mask[i].slice(0, 0, n).fill_(true);
  }
  if (N == 0) return torch::zeros({0, m, dim()});
  torch::NoGradGuard ng;
  const auto out = net_->forward(ids.to(device_), mask.to(device_));  // [N, m, d]
  return out.masked_fill(mask.to(device_).logical_not().unsqueeze(-1), 0.0).to(torch::kCPU);
}

}  // namespace gaia::text
