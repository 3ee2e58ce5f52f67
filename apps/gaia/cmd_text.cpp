// gaia text embed: a token dataset's captions through a frozen T5 (§2.1), stored with the dataset as its text
// embeddings (docs/formats.md), which gaia world train then reads instead of the built-in words.
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/embed_captions.h"

namespace gaia::app {

// The dataset's captions through the T5 at `t5` (m tokens a step), with a progress bar; says what it did.
void embed_dataset_captions(const std::string& tokens, const std::string& t5, int64_t m, const torch::Device& dev) {
  text::T5TextEncoder encoder(t5, dev);
  std::unique_ptr<ProgressBar> bar;
  auto r = world::embed_captions(tokens, encoder, m, [&](int64_t done, int64_t total) {
    if (!bar) bar = std::make_unique<ProgressBar>(total, "text embed");
    bar->update(done);
  });
  if (bar) bar->finish();
  if (r.embedded == 0)
    std::fprintf(stderr, "text: %s already has embeddings of %s (m = %lld)\n", tokens.c_str(),
                 encoder.identity().c_str(), (long long)m);
  else
    std::fprintf(stderr, "text: %lld of %lld episodes embedded with %s (%lld distinct captions, m = %lld, dim = %lld)\n",
                 (long long)r.embedded, (long long)r.episodes, encoder.identity().c_str(), (long long)r.captions,
                 (long long)m, (long long)encoder.dim());
}

void register_text(CLI::App& app) {
  auto* text = app.add_subcommand("text", "text encoders (§2.1): embed a token dataset's captions with T5");
  text->require_subcommand(1);
  auto* cmd = text->add_subcommand(
      "embed", "every step's caption through a frozen T5, stored with the dataset (TOKENS/episodes/*/text_emb.npy); "
               "resumable, and a no-op when already there");
  auto flags = std::make_shared<SharedFlags>();
  auto tokens = std::make_shared<std::string>(), t5 = std::make_shared<std::string>();
  auto m = std::make_shared<int64_t>(0);
  cmd->add_option("TOKENS", *tokens, "token dataset (gaia tokenize) with captions")->required();
  add_weights_flag(cmd, Weights::T5, t5.get())->required();
  cmd->add_option("--m", *m, "text tokens per step (default: config world.text_tokens; the paper: 32)")
      ->check(number_in({1, 4096}));
  add_shared_flags(cmd, flags.get(), "unused", WithPrecision::kNo);
  cmd->callback([=] {
    Config c = resolve_config(*flags);
    apply_threads(c);
    embed_dataset_captions(*tokens, *t5, *m > 0 ? *m : c.world.text_tokens, parse_device(c.run.device));
  });
}

}  // namespace gaia::app
