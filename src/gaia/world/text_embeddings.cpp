#include "gaia/world/text_embeddings.h"

#include <cstring>
#include <map>

#include <nlohmann/json.hpp>

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/core/npy.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::world {

fs::path text_emb_file(const fs::path& episode_dir) {
  for (const char* name : {"text_emb.npy", "text_emb.safetensors"})
    if (fs::exists(episode_dir / name)) return episode_dir / name;
  return {};
}

TextEmbInfo read_text_emb_info(const fs::path& dataset_dir) {
  const fs::path f = dataset_dir / kTextEmbInfoFile;
  TextEmbInfo info;
  if (!fs::exists(f)) return info;
  const auto j = read_json(f);
  try {
    for (auto& [k, v] : j.items())
      if (k != "encoder" && k != "m" && k != "dim") fail("{}: unknown key '{}' (want encoder, m, dim)", f.string(), k);
    info.encoder = j.at("encoder").get<std::string>();
    info.m = j.at("m").get<int64_t>();
    info.dim = j.at("dim").get<int64_t>();
  } catch (const nlohmann::json::exception& e) {
    fail("{}: bad text embedding record ({})", f.string(), e.what());
  }
  if (info.encoder.empty() || info.m < 1 || info.dim < 1)
    fail("{}: encoder must be named and m, dim >= 1 (got '{}', {}, {})", f.string(), info.encoder, info.m, info.dim);
  return info;
}

void write_text_emb_info(const fs::path& dataset_dir, const TextEmbInfo& info) {
  const nlohmann::json j = {{"encoder", info.encoder}, {"m", info.m}, {"dim", info.dim}};
  write_file_atomic(dataset_dir / kTextEmbInfoFile, j.dump(2) + "\n");
}

TextEmbeddings read_text_embeddings(const fs::path& file, int64_t steps, const TextEmbInfo& info) {
  torch::Tensor t = read_float_array(file, "text_emb").contiguous();
  if (t.dim() != 3 || t.size(0) != steps || (info.defined() && (t.size(1) != info.m || t.size(2) != info.dim)))
    fail("{}: shape {}, want [steps = {}, m = {}, dim = {}]", file.string(), c10::str(t.sizes()), steps,
         info.defined() ? std::to_string(info.m) : "m", info.defined() ? std::to_string(info.dim) : "dim");
  TextEmbeddings e;
  e.m = t.size(1);
  e.dim = t.size(2);
  const size_t row = static_cast<size_t>(e.m * e.dim);
  const float* p = t.data_ptr<float>();
  std::map<std::string, int32_t> seen;  // a row's bytes -> its index in e.rows
  for (int64_t s = 0; s < steps; ++s) {
    std::string key(reinterpret_cast<const char*>(p + size_t(s) * row), row * sizeof(float));
    auto [it, added] = seen.emplace(std::move(key), static_cast<int32_t>(seen.size()));
    if (added) e.rows.insert(e.rows.end(), p + size_t(s) * row, p + size_t(s + 1) * row);
    e.index.push_back(it->second);
  }
  return e;
}

TextEmbInfo probe_text_emb_info(const fs::path& dataset_dir, const fs::path& first_file) {
  TextEmbInfo info = read_text_emb_info(dataset_dir);
  if (info.defined()) return info;
  torch::Tensor t = read_float_array(first_file, "text_emb");
  if (t.dim() != 3) fail("{}: shape {}, want [steps, m, dim]", first_file.string(), c10::str(t.sizes()));
  return TextEmbInfo{"precomputed", t.size(1), t.size(2)};
}

void write_text_embeddings(const fs::path& episode_dir, const torch::Tensor& emb) {
  if (emb.dim() != 3) fail("text embeddings must be [steps, m, dim], got {}", c10::str(emb.sizes()));
  auto t = emb.detach().to(torch::kCPU, torch::kFloat32).contiguous();
  NpyArray a;
  a.dtype = DType::F32;
  a.shape = t.sizes().vec();
  a.bytes.resize(static_cast<size_t>(t.numel()) * sizeof(float));
  std::memcpy(a.bytes.data(), t.data_ptr<float>(), a.bytes.size());
  npy_write(episode_dir / "text_emb.npy", a);
}

}  // namespace gaia::world
