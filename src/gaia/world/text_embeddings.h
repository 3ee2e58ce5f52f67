#pragma once
// Precomputed text embeddings of a token dataset (§2.1: each step's text as the m output tokens of a frozen
// encoder such as T5-large, which the world model's linear layer projects to d). docs/formats.md, "Text
// embeddings":
//
//   TOKENS/text_emb.json               {"encoder": "t5:...", "m": 32, "dim": 1024}; optional for files made
//                                      elsewhere (the encoder is then "precomputed", m and dim from the files)
//   TOKENS/episodes/<id>/text_emb.npy  [steps, m, dim], float16/32/64; or text_emb.safetensors (its one tensor,
//                                      or the one named "text_emb")
//
// Captions repeat over many steps, so an episode's embeddings are held once per distinct row.
#include <cstdint>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "gaia/core/fs.h"

namespace gaia::world {

struct TextEmbInfo {
  std::string encoder;  // who made them: a text encoder's identity (text/t5.h), or "precomputed"
  int64_t m = 0, dim = 0;
  bool defined() const { return m > 0; }
};

// One episode's embeddings, deduplicated.
struct TextEmbeddings {
  int64_t m = 0, dim = 0;
  std::vector<float> rows;     // [distinct, m, dim]
  std::vector<int32_t> index;  // [steps]: the row of each step
  const float* step(int64_t t) const { return rows.data() + static_cast<size_t>(index.at(size_t(t))) * size_t(m * dim); }
};

inline constexpr const char* kTextEmbInfoFile = "text_emb.json";
// Present while `gaia text embed` writes (embed_captions.h): the dataset then reads as having no embeddings.
inline constexpr const char* kTextEmbPartialFile = ".text_emb.partial.json";

fs::path text_emb_file(const fs::path& episode_dir);  // its text_emb.npy or text_emb.safetensors; empty if none
TextEmbInfo read_text_emb_info(const fs::path& dataset_dir);  // TOKENS/text_emb.json; undefined when absent
void write_text_emb_info(const fs::path& dataset_dir, const TextEmbInfo& info);  // atomic

// One episode's file, checked: [steps, m, dim] with m and dim as `info` says (when defined), finite values.
TextEmbeddings read_text_embeddings(const fs::path& file, int64_t steps, const TextEmbInfo& info);
// The dataset-level record a set of files implies: text_emb.json when present, else m and dim of `first_file`.
TextEmbInfo probe_text_emb_info(const fs::path& dataset_dir, const fs::path& first_file);
// Writes one episode's [steps, m, dim] float32 embeddings as EPISODE_DIR/text_emb.npy (atomic).
void write_text_embeddings(const fs::path& episode_dir, const torch::Tensor& emb);

}  // namespace gaia::world
