#pragma once
// What turns a caption into the inputs of the world model's m text tokens c_t (§2.1): word ids of the built-in
// vocabulary, or the output tokens of a frozen encoder (T5, text/t5.h), which the world model projects to d.
#include <map>
#include <memory>
#include <string>

#include <torch/torch.h>

#include "gaia/core/fs.h"
#include "gaia/text/vocab.h"

namespace gaia::text {

class TextEncoder {
 public:
  virtual ~TextEncoder() = default;
  // One caption -> [m] int64 word ids (embeds() false), or [m, dim] float32 embeddings (embeds() true), on the CPU.
  virtual torch::Tensor encode(const std::string& caption, int64_t m) = 0;
  // Many captions: [N, m] or [N, m, dim] (encode() of each, unless an encoder batches them).
  virtual torch::Tensor encode_all(const std::vector<std::string>& captions, int64_t m);
  virtual bool embeds() const = 0;
  // "words", or the encoder's identity (T5Encoder::identity), which a model trained on its embeddings records.
  virtual std::string identity() const = 0;
};

// The built-in encoder: the world model's own vocabulary (its word embedding is trained with it).
class WordEncoder final : public TextEncoder {
 public:
  explicit WordEncoder(Vocab vocab) : vocab_(std::move(vocab)) {}
  torch::Tensor encode(const std::string& caption, int64_t m) override;
  bool embeds() const override { return false; }
  std::string identity() const override { return "words"; }

 private:
  Vocab vocab_;
};

// A frozen T5 encoder from a Hugging Face directory (text/t5.h), each caption encoded once (captions repeat).
// Thread-safe.
class T5TextEncoder final : public TextEncoder {
 public:
  explicit T5TextEncoder(const fs::path& dir, const torch::Device& device = torch::kCPU);
  ~T5TextEncoder() override;
  torch::Tensor encode(const std::string& caption, int64_t m) override;
  // Those not cached go through the encoder in batches: [N, m, dim].
  torch::Tensor encode_all(const std::vector<std::string>& captions, int64_t m) override;
  bool embeds() const override { return true; }
  std::string identity() const override;
  int64_t dim() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gaia::text
