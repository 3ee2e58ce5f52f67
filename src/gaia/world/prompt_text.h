#pragma once
// Text prompts as a world model reads them (§2.1): word ids of its own vocabulary, or embeddings of the frozen
// encoder it was trained with (WorldInfo::text_encoder), for `gaia generate`, `gaia sim` and the evaluations.
#include <memory>
#include <string>

#include "gaia/text/encoder.h"
#include "gaia/world/io.h"
#include "gaia/world/rollout.h"

namespace gaia::world {

// The encoder of this model's prompts: its words; for a model trained on T5 embeddings, the T5 at `t5_dir`, which
// must be the checkpoint the model was trained with. Errors name `weights` and the flag that is missing.
std::shared_ptr<text::TextEncoder> prompt_encoder(const WorldInfo& info, const std::string& weights,
                                                  const fs::path& t5_dir, const torch::Device& device = torch::kCPU);

// Two encoder identities name the same weights (a T5's identity ends in a hash of its files; the folder's name
// before it may differ between machines).
bool same_text_encoder(const std::string& a, const std::string& b);

// `row` ([m] word ids or [m, dim] embeddings) for each of `steps` steps: [steps, m] or [steps, m, dim].
torch::Tensor repeat_rows(const torch::Tensor& row, int64_t steps);

// `row` ([m] word ids or [m, dim] embeddings) repeated for `steps`, as the text (or the negative text) of `p`.
void set_prompt_text(RolloutPrompt& p, const torch::Tensor& row, int64_t steps, bool negative = false);

// One text per future, each for all `steps` steps, through `encoder` (m tokens): the text (or negative text) of
// `p`, [futures, steps, m] ids or [futures, steps, m, dim] embeddings.
void set_future_texts(RolloutPrompt& p, text::TextEncoder& encoder, const std::vector<std::string>& texts,
                      int64_t steps, int64_t m, bool negative = false);

// A prompt given as embeddings (--text-emb FILE, .npy or .safetensors): [m, dim] for every step, or [steps, m, dim];
// m and dim must be the model's. Returns [steps, m, dim].
torch::Tensor read_prompt_embeddings(const fs::path& file, const WorldInfo& info, int64_t steps);

}  // namespace gaia::world
