#include "gaia/world/prompt_text.h"

#include "gaia/core/error.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::world {

namespace {
torch::Tensor& text_field(RolloutPrompt& p, bool embeddings, bool negative) {
  if (embeddings) return negative ? p.negative_text_emb : p.text_emb;
  return negative ? p.negative_text_ids : p.text_ids;
}
}  // namespace

bool same_text_encoder(const std::string& a, const std::string& b) {
  if (a == b) return true;
  auto hash = [](const std::string& s) { return s.rfind("t5:", 0) == 0 ? s.substr(s.rfind(':')) : s; };
  return a.rfind("t5:", 0) == 0 && b.rfind("t5:", 0) == 0 && hash(a) == hash(b);
}

std::shared_ptr<text::TextEncoder> prompt_encoder(const WorldInfo& info, const std::string& weights,
                                                  const fs::path& t5_dir, const torch::Device& device) {
  if (!info.embeds_text()) {
    if (!t5_dir.empty())
      fail("{}: reads text with its own words, not T5 embeddings; leave out --t5", weights);
    return std::make_shared<text::WordEncoder>(info.vocab);
  }
  if (info.text_encoder.rfind("t5:", 0) != 0)
    fail("{}: was trained on text embeddings made elsewhere ({}); give a text prompt as --text-emb FILE "
         "(docs/formats.md)", weights, info.text_encoder);
  if (t5_dir.empty())
    fail("{}: reads text as embeddings of {}; give that encoder with --t5 DIR (or a prompt as --text-emb FILE)",
         weights, info.text_encoder);
  auto t5 = std::make_shared<text::T5TextEncoder>(t5_dir, device);
  if (!same_text_encoder(t5->identity(), info.text_encoder))
    fail("{}: is {}, but {} was trained on embeddings of {}", t5_dir.string(), t5->identity(), weights,
         info.text_encoder);
  if (t5->dim() != info.config.world.text_dim)
    fail("{}: embeddings of width {}, but {} takes world.text_dim = {}", t5_dir.string(), t5->dim(), weights,
         info.config.world.text_dim);
  return t5;
}

torch::Tensor repeat_rows(const torch::Tensor& row, int64_t steps) {
  std::vector<int64_t> reps(size_t(row.dim()) + 1, 1);
  reps[0] = steps;
  return row.unsqueeze(0).repeat(reps);
}

void set_prompt_text(RolloutPrompt& p, const torch::Tensor& row, int64_t steps, bool negative) {
  text_field(p, row.is_floating_point(), negative) = repeat_rows(row, steps);
}

void set_future_texts(RolloutPrompt& p, text::TextEncoder& encoder, const std::vector<std::string>& texts,
                      int64_t steps, int64_t m, bool negative) {
  std::vector<torch::Tensor> rows;
  for (auto& t : texts) rows.push_back(repeat_rows(encoder.encode(t, m), steps));
  text_field(p, encoder.embeds(), negative) = torch::stack(rows);
}

torch::Tensor read_prompt_embeddings(const fs::path& file, const WorldInfo& info, int64_t steps) {
  torch::Tensor t = read_float_array(file, "text_emb");
  const int64_t m = info.config.world.text_tokens, dim = info.config.world.text_dim;
  if (t.dim() == 2) t = t.unsqueeze(0).expand({steps, t.size(0), t.size(1)}).contiguous();
  if (t.dim() != 3 || t.size(0) != steps || t.size(1) != m || t.size(2) != dim)
    fail("{}: shape {}, want [m = {}, dim = {}] or [steps = {}, m, dim]", file.string(), c10::str(t.sizes()), m, dim,
         steps);
  return t;
}

}  // namespace gaia::world
