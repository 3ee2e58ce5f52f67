#include "gaia/world/config.h"

namespace gaia {

void add_config_fields(WorldConfig& w, std::vector<ConfigField>& f) {
  const auto A = ConfigRole::Architecture, T = ConfigRole::Training, S = ConfigRole::Sampling;
  f.push_back(config_field("world.d_model", &w.d_model, A, closed(1, 65536)));
  f.push_back(config_field("world.n_layers", &w.n_layers, A, closed(1, 1024)));
  f.push_back(config_field("world.n_heads", &w.n_heads, A, closed(1, 1024)));
  f.push_back(config_field("world.context_steps", &w.context_steps, A, closed(1, 4096)));
  f.push_back(config_field("world.text_tokens", &w.text_tokens, A, closed(1, 1024)));
  f.push_back(config_field("world.text_dim", &w.text_dim, A, closed(1, 65536)));
  f.push_back(config_field("world.text_vocab", &w.text_vocab, A, closed(2, 1 << 20)));
  f.push_back(config_field("world.action_tokens", &w.action_tokens, A, closed(2, 2)));
  f.push_back(config_field("world.action_mlp", &w.action_mlp, A, closed(0, 65536)));
  f.push_back(config_field("world.dropout", &w.dropout, T, kDecayRange));
  f.push_back(config_field("world.p_uncond", &w.p_uncond, T, closed(0, 1)));
  f.push_back(config_field("world.p_action", &w.p_action, T, closed(0, 1)));
  f.push_back(config_field("world.p_text", &w.p_text, T, closed(0, 1)));
  f.push_back(config_field("world.p_action_replay", &w.p_action_replay, T, closed(-1, 1)));
  f.push_back(config_field("world.lr", &w.lr, T, kRateRange));
  f.push_back(config_field("world.weight_decay", &w.weight_decay, T, closed(0, 10)));
  f.push_back(config_field("world.beta1", &w.beta1, T, kBetaRange));
  f.push_back(config_field("world.beta2", &w.beta2, T, kBetaRange));
  f.push_back(config_field("world.grad_clip", &w.grad_clip, T, closed(0, 1e6)));
  f.push_back(config_field("world.final_lr_ratio", &w.final_lr_ratio, T, closed(0, 1)));
  f.push_back(config_field("world.warmup_steps", &w.warmup_steps, T, kStepsOrZeroRange));
  f.push_back(config_field("world.steps", &w.steps, T, kStepsRange));
  f.push_back(config_field("world.batch_size", &w.batch_size, T, kBatchRange));
  f.push_back(config_field("world.activation_checkpointing", &w.activation_checkpointing, T));
  f.push_back(config_field("world.scaling_width", &w.scaling_width, T, closed(1, 65536)));
  f.push_back(config_field("world.scaling_head_dim", &w.scaling_head_dim, T, closed(1, 65536)));
  f.push_back(config_field("world.scaling_width_per_layer", &w.scaling_width_per_layer, T, closed(1, 65536)));
  f.push_back(config_field("world.scaling_growth", &w.scaling_growth, T, closed(1.01, 16)));
  f.push_back(config_field("world.scaling_tokens_per_param", &w.scaling_tokens_per_param, T, above(0, 1e6)));
  f.push_back(config_field("world.top_k", &w.top_k, S, closed(1, 1 << 20)));
  f.push_back(config_field("world.temperature", &w.temperature, S, above(0, 100)));
  f.push_back(config_field("world.copy_bias", &w.copy_bias, A, closed(-100, 100)));
  f.push_back(config_field("world.copy_bias_run", &w.copy_bias_run, A, closed(-100, 100)));
  f.push_back(config_field("world.guide_actions_within_top_k", &w.guide_actions_within_top_k, S));
  f.push_back(config_field("world.guidance_scale", &w.guidance_scale, S, closed(0, 100)));
}

}  // namespace gaia
