#pragma once
// A frozen T5 text encoder (paper §2.1: each step's text is encoded by a frozen pre-trained T5-large into m text
// tokens). It loads a Hugging Face T5 or T5 v1.1 directory and computes what transformers' T5EncoderModel computes in
// eval mode, with the tokenization of HF's T5 tokenizers (SentencePiece pieces + </s>). tools/t5_peer.py is its
// plain-PyTorch cross-check (tests/fixtures/t5/).
//
//   dir/config.json        d_model, d_kv, d_ff, num_layers, num_heads, vocab_size, feed_forward_proj ("relu" for
//                          T5, "gated-gelu" for T5 v1.1), relative_attention_{num_buckets,max_distance},
//                          layer_norm_epsilon
//   dir/model.safetensors  the encoder's tensors in HF naming (F32, F16 or BF16); decoder.* and lm_head.* ignored
//   dir/spiece.model       the SentencePiece model (pad 0, </s> 1)
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "gaia/core/fs.h"

namespace gaia::text {

struct T5Config {
  int64_t vocab_size = 0, d_model = 0, d_kv = 0, d_ff = 0, num_layers = 0, num_heads = 0;
  int64_t num_buckets = 32, max_distance = 128;  // relative_attention_num_buckets / _max_distance
  double eps = 1e-6;                             // layer_norm_epsilon
  bool gated_gelu = false;                       // feed_forward_proj "gated-gelu" (T5 v1.1); else "relu"
  // Errors name the file and the field.
  static T5Config from_json_file(const fs::path& path);
};

struct T5Net;  // the modules (t5.cpp)
class SentencePiece;  // text/sentencepiece.h

class T5Encoder {
 public:
  static constexpr int64_t kPad = 0, kEos = 1;

  // Loads dir/config.json, dir/model.safetensors and dir/spiece.model; the weights go to `device`, frozen.
  explicit T5Encoder(const fs::path& dir, torch::Device device = torch::kCPU);
  ~T5Encoder();
  T5Encoder(T5Encoder&&) noexcept;
  T5Encoder& operator=(T5Encoder&&) noexcept;

  // The SentencePiece ids of `text` followed by </s> (id 1), as HF's T5TokenizerFast / T5Tokenizer give them.
  std::vector<int64_t> tokenize(const std::string& text) const;

  // Captions -> [N, m, d_model] float32 on the CPU: each caption's ids truncated to m (</s> kept last, as HF's
  // truncation does), padded with id 0 and encoded under the attention mask; outputs at padded positions are
  // exactly 0, and an empty caption (a step without text) is all zeros.
  torch::Tensor encode(const std::vector<std::string>& captions, int64_t m);

  int64_t dim() const { return config_.d_model; }
  const T5Config& config() const { return config_; }
  // "t5:<dir name>:<12 hex>": an FNV-1a 64 hash of model.safetensors' header, the first bytes of each tensor and
  // spiece.model, so embeddings cached under one checkpoint are not taken for another's.
  std::string identity() const { return identity_; }

 private:
  T5Config config_;
  torch::Device device_;
  std::unique_ptr<SentencePiece> sp_;
  std::shared_ptr<T5Net> net_;
  std::string identity_;
};

}  // namespace gaia::text
