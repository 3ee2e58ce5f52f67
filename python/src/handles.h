#pragma once
// The loaded models the Python classes share: a Sim made from a WorldModel and a Tokenizer uses their weights,
// and keeps them alive as long as any of its sessions.
#include <memory>
#include <mutex>
#include <string>

#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/text/encoder.h"
#include "gaia/torch/precision.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/world/io.h"

namespace gaia::python {

// A `precision` argument ("fp32" | "bf16" | "fp16") on `dev`, as --precision: bf16 on a CPU without bf16
// instructions runs in fp32 with a RuntimeWarning saying so. Needs the GIL.
Precision precision_arg(const std::string& s, const torch::Device& dev);

struct TokenizerHandle {
  tokenizer::ImageTokenizer tok{nullptr};
  Config config;
  std::string path;
  torch::Device dev{torch::kCPU};
};

struct WorldHandle {
  world::WorldModel model{nullptr};
  world::WorldInfo info;
  std::string path, t5;
  torch::Device dev{torch::kCPU};
  // The prompt encoder (world::prompt_encoder), made on first use.
  std::shared_ptr<text::TextEncoder> text();

 private:
  std::mutex lock_;
  std::shared_ptr<text::TextEncoder> text_;
};

std::shared_ptr<TokenizerHandle> load_tokenizer_handle(const std::string& path, const std::string& device);
std::shared_ptr<WorldHandle> load_world_handle(const std::string& path, const std::string& device,
                                               const std::string& t5);

}  // namespace gaia::python
