#include "gaia/tokenizer/config.h"

namespace gaia {

void add_config_fields(TokenizerConfig& t, std::vector<ConfigField>& f) {
  const auto A = ConfigRole::Architecture, T = ConfigRole::Training;
  f.push_back(config_field("tokenizer.downsample", &t.downsample, A, closed(1, 256)));
  f.push_back(config_field("tokenizer.codebook_size", &t.codebook_size, A, closed(2, 32768)));
  f.push_back(config_field("tokenizer.code_dim", &t.code_dim, A, closed(1, 4096)));
  f.push_back(config_field("tokenizer.channels", &t.channels, A, closed(1, 8192)));
  f.push_back(config_field("tokenizer.channel_mult", &t.channel_mult, A, closed(1, 64)));
  f.push_back(config_field("tokenizer.res_blocks", &t.res_blocks, A, closed(1, 64)));
  f.push_back(config_field("tokenizer.refine_blocks", &t.refine_blocks, A, closed(0, 64)));
  f.push_back(config_field("tokenizer.token_blocks", &t.token_blocks, A, closed(0, 64)));
  f.push_back(config_field("tokenizer.z_channels", &t.z_channels, A, closed(1, 16384)));
  f.push_back(config_field("tokenizer.disc_channels", &t.disc_channels, A, closed(1, 8192)));
  f.push_back(config_field("tokenizer.disc_layers", &t.disc_layers, A, closed(1, 16)));
  f.push_back(config_field("tokenizer.w_l1", &t.w_l1, T, kWeightRange));
  f.push_back(config_field("tokenizer.w_l2", &t.w_l2, T, kWeightRange));
  f.push_back(config_field("tokenizer.w_perceptual", &t.w_perceptual, T, kWeightRange));
  f.push_back(config_field("tokenizer.w_gan", &t.w_gan, T, kWeightRange));
  f.push_back(config_field("tokenizer.w_codebook", &t.w_codebook, T, kWeightRange));
  f.push_back(config_field("tokenizer.w_dino", &t.w_dino, T, kWeightRange));
  f.push_back(config_field("tokenizer.commitment", &t.commitment, T, kWeightRange));
  f.push_back(config_field("tokenizer.disc_start", &t.disc_start, T, kStepsOrZeroRange));
  f.push_back(config_field("tokenizer.gan_adaptive", &t.gan_adaptive, T));
  f.push_back(config_field("tokenizer.lr", &t.lr, T, kRateRange));
  f.push_back(config_field("tokenizer.weight_decay", &t.weight_decay, T, closed(0, 10)));
  f.push_back(config_field("tokenizer.beta1", &t.beta1, T, kBetaRange));
  f.push_back(config_field("tokenizer.beta2", &t.beta2, T, kBetaRange));
  f.push_back(config_field("tokenizer.final_lr", &t.final_lr, T, closed(0, 10)));
  f.push_back(config_field("tokenizer.warmup_steps", &t.warmup_steps, T, kStepsOrZeroRange));
  f.push_back(config_field("tokenizer.steps", &t.steps, T, kStepsRange));
  f.push_back(config_field("tokenizer.batch_size", &t.batch_size, T, kBatchRange));
  f.push_back(config_field("tokenizer.ema_decay", &t.ema_decay, T, kDecayRange));
  f.push_back(config_field("tokenizer.augment_dark", &t.augment_dark, T, closed(0, 1)));
}

}  // namespace gaia
