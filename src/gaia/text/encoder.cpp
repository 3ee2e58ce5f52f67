#include "gaia/text/encoder.h"

#include <algorithm>
#include <mutex>

#include "gaia/text/t5.h"

namespace gaia::text {

torch::Tensor TextEncoder::encode_all(const std::vector<std::string>& captions, int64_t m) {
  std::vector<torch::Tensor> rows;
  for (auto& c : captions) rows.push_back(encode(c, m));
  return torch::stack(rows);
}

torch::Tensor WordEncoder::encode(const std::string& caption, int64_t m) {
  return torch::tensor(vocab_.encode(caption, m), torch::kLong);
}

struct T5TextEncoder::Impl {
  T5Encoder t5;
  std::map<std::pair<std::string, int64_t>, torch::Tensor> cache;  // (caption, m) -> [m, dim]
  std::mutex mu;  // sessions of gaia sim share one encoder
};

T5TextEncoder::T5TextEncoder(const fs::path& dir, const torch::Device& device)
    : impl_(new Impl{T5Encoder(dir, device), {}, {}}) {}
T5TextEncoder::~T5TextEncoder() = default;

torch::Tensor T5TextEncoder::encode_all(const std::vector<std::string>& captions, int64_t m) {
  std::lock_guard<std::mutex> lock(impl_->mu);
  std::vector<std::string> todo;
  for (auto& c : captions)
    if (!impl_->cache.count({c, m}) && std::find(todo.begin(), todo.end(), c) == todo.end()) todo.push_back(c);
  constexpr size_t kBatch = 64;  // bounds the encoder's activations for a dataset's many distinct captions
  for (size_t i = 0; i < todo.size(); i += kBatch) {
    std::vector<std::string> part(todo.begin() + long(i), todo.begin() + long(std::min(todo.size(), i + kBatch)));
    auto e = impl_->t5.encode(part, m);  // [k, m, dim]
    for (size_t j = 0; j < part.size(); ++j) impl_->cache[{part[j], m}] = e[long(j)].clone();
  }
  std::vector<torch::Tensor> rows;
  for (auto& c : captions) rows.push_back(impl_->cache.at({c, m}));
  return rows.empty() ? torch::empty({0, m, dim()}) : torch::stack(rows);
}

torch::Tensor T5TextEncoder::encode(const std::string& caption, int64_t m) { return encode_all({caption}, m)[0]; }
std::string T5TextEncoder::identity() const { return impl_->t5.identity(); }
int64_t T5TextEncoder::dim() const { return impl_->t5.dim(); }

}  // namespace gaia::text
