#include "gaia/decoder/config.h"

namespace gaia {

void add_config_fields(DecoderConfig& v, std::vector<ConfigField>& f) {
  const auto A = ConfigRole::Architecture, T = ConfigRole::Training, S = ConfigRole::Sampling;
  f.push_back(config_field("decoder.channels", &v.channels, A, closed(1, 8192)));
  f.push_back(config_field("decoder.channel_mult", &v.channel_mult, A, closed(1, 64)));
  f.push_back(config_field("decoder.res_blocks", &v.res_blocks, A, closed(1, 64)));
  f.push_back(config_field("decoder.attn_levels", &v.attn_levels, A, closed(0, 16)));
  f.push_back(config_field("decoder.temporal_levels", &v.temporal_levels, A, closed(0, 16)));
  f.push_back(config_field("decoder.heads", &v.heads, A, closed(1, 1024)));
  f.push_back(config_field("decoder.token_embed_dim", &v.token_embed_dim, A, closed(1, 8192)));
  f.push_back(config_field("decoder.cond_image", &v.cond_image, A));
  f.push_back(config_field("decoder.interp_base", &v.interp_base, A));
  f.push_back(config_field("decoder.schedule_shift", &v.schedule_shift, A, above(0, 1000)));
  f.push_back(config_field("decoder.frames", &v.frames, A, closed(3, 1023)));
  f.push_back(config_field("decoder.token_dropout", &v.token_dropout, T, closed(0, 1)));
  f.push_back(config_field("decoder.ddim_steps", &v.ddim_steps, S, closed(1, 10000)));
  f.push_back(config_field("decoder.mix_probability", &v.mix_probability, S, closed(0, 1)));
  f.push_back(config_field("decoder.mix_weight", &v.mix_weight, S, closed(0, 1)));
  f.push_back(config_field("decoder.noise_correlation", &v.noise_correlation, S, closed(0, 1)));
  f.push_back(config_field("decoder.noise_scale", &v.noise_scale, S, closed(0, 1)));
  f.push_back(config_field("decoder.start_time", &v.start_time, S, above(0, 1)));
  f.push_back(config_field("decoder.train_max_time", &v.train_max_time, T, above(0, 1)));
  f.push_back(config_field("decoder.w_temporal", &v.w_temporal, T, kWeightRange));
  f.push_back(config_field("decoder.w_l1", &v.w_l1, T, kWeightRange));
  f.push_back(config_field("decoder.w_l2", &v.w_l2, T, kWeightRange));
  f.push_back(config_field("decoder.ema_decay", &v.ema_decay, T, kDecayRange));
  f.push_back(config_field("decoder.lr", &v.lr, T, kRateRange));
  f.push_back(config_field("decoder.weight_decay", &v.weight_decay, T, closed(0, 10)));
  f.push_back(config_field("decoder.beta1", &v.beta1, T, kBetaRange));
  f.push_back(config_field("decoder.beta2", &v.beta2, T, kBetaRange));
  f.push_back(config_field("decoder.grad_clip", &v.grad_clip, T, closed(0, 1e6)));
  f.push_back(config_field("decoder.final_lr", &v.final_lr, T, closed(0, 10)));
  f.push_back(config_field("decoder.warmup_steps", &v.warmup_steps, T, kStepsOrZeroRange));
  f.push_back(config_field("decoder.steps", &v.steps, T, kStepsRange));
  f.push_back(config_field("decoder.batch_size", &v.batch_size, T, kBatchRange));
}

}  // namespace gaia
