#include "gaia/config.h"

#include "gaia/core/error.h"

namespace gaia {

std::vector<Config::Field> Config::fields() {
  std::vector<Field> f;
  f.push_back(config_field("name", &name, ConfigRole::Run));
  add_config_fields(data, f);
  add_config_fields(tokenizer, f);
  add_config_fields(world, f);
  add_config_fields(decoder, f);
  const auto R = ConfigRole::Run;
  f.push_back(config_field("run.device", &run.device, R));
  f.push_back(config_field("run.threads", &run.threads, R, closed(0, 4096)));
  f.push_back(config_field("run.seed", &run.seed, R));
  f.push_back(config_field("run.checkpoint_every", &run.checkpoint_every, R, closed(1, 1e9)));
  f.push_back(config_field("run.precision", &run.precision, R));
  return f;
}

std::vector<std::string> Config::keys(const std::string& section, ConfigRole role) {
  Config c;
  std::vector<std::string> out;
  for (const auto& f : c.fields())
    if (f.role == role && f.key.rfind(section + ".", 0) == 0) out.push_back(f.key);
  return out;
}

void Config::apply_yaml(const std::string& text, const std::string& where) {
  auto f = fields();
  apply_config_yaml(f, text, where);
}

Config Config::load(const fs::path& yaml) {
  if (!fs::exists(yaml)) fail("{}: no such config file", yaml.string());
  Config c;
  c.apply_yaml(read_file(yaml), yaml.string());
  c.validate();
  return c;
}

void Config::set(const std::string& kv) {
  auto f = fields();
  set_config_key(f, kv);
}

void Config::validate() const {
  auto need = [&](bool ok, const std::string& msg) {
    if (!ok) fail("config '{}': {}", name, msg);
  };
  Config copy = *this;  // fields() hands out setters, so it is not const
  for (auto& f : copy.fields()) {
    try {
      f.check();
    } catch (const Error& e) {
      fail("config '{}': {}", name, e.what());
    }
  }
  need(data.height > 0 && data.width > 0, "data.height and data.width must be positive");
  need(run.precision == "fp32" || run.precision == "bf16" || run.precision == "fp16",
       fmt::format("run.precision '{}': expected fp32, bf16 or fp16", run.precision));
  need(tokenizer.downsample > 0 && (tokenizer.downsample & (tokenizer.downsample - 1)) == 0,
       "tokenizer.downsample must be a power of two");
  need(data.height % tokenizer.downsample == 0 && data.width % tokenizer.downsample == 0,
       "tokenizer.downsample must divide data.height and data.width");
  int levels = 0;
  for (int d = tokenizer.downsample; d > 1; d /= 2) ++levels;
  need(static_cast<int>(tokenizer.channel_mult.size()) == levels + 1,
       fmt::format("tokenizer.channel_mult needs log2(downsample) + 1 = {} entries", levels + 1));
  need(tokenizer.codebook_size >= 2, "tokenizer.codebook_size must be >= 2");
  need(tokenizer.ema_decay >= 0 && tokenizer.ema_decay < 1, "tokenizer.ema_decay must be in [0, 1)");
  need(tokenizer.res_blocks >= 1 && tokenizer.refine_blocks >= 0 && tokenizer.token_blocks >= 0,
       "tokenizer.res_blocks must be >= 1 and tokenizer.refine_blocks, tokenizer.token_blocks >= 0");
  need(world.d_model % world.n_heads == 0, "world.d_model must be divisible by world.n_heads");
  need(world.action_tokens == 2, "world.action_tokens must be 2 (speed, curvature; paper §2.1)");
  need(world.action_mlp >= 0, "world.action_mlp must be >= 0 (hidden units; 0 = one linear layer per action)");
  // m >= 1: the first image token of a step is predicted from the last text token before it.
  need(world.context_steps >= 1 && world.text_tokens >= 1, "world.context_steps >= 1 and world.text_tokens >= 1");
  double p = world.p_uncond + world.p_action + world.p_text;
  need(p > 0.999 && p < 1.001, "world.p_uncond + p_action + p_text must be 1");
  need(world.p_action_replay == -1 || (world.p_action_replay >= 0 && world.p_action_replay <= 1),
       "world.p_action_replay must be in [0, 1], or -1 for the same mix as every other window");
  need(world.top_k >= 1, "world.top_k must be >= 1");
  need(world.temperature > 0, "world.temperature must be > 0");
  need(data.balance_exponent >= 0 && data.balance_exponent <= 1, "data.balance_exponent must be in [0, 1]");
  need(data.native_fps > 0 && data.world_fps > 0 && data.world_fps <= data.native_fps,
       "data.world_fps must be in (0, data.native_fps]");
  need(decoder.frames >= 3, "decoder.frames must be >= 3");
  need(decoder.channel_mult.size() >= 1, "decoder.channel_mult must not be empty");
  need(decoder.channels % decoder.heads == 0, "decoder.channels must be divisible by decoder.heads");
  need(decoder.frames % 2 == 1, "decoder.frames must be odd (interpolation windows start and end on a context frame)");
  need(data.height % (1 << (decoder.channel_mult.size() - 1)) == 0 &&
           data.width % (1 << (decoder.channel_mult.size() - 1)) == 0,
       "data.height and data.width must be divisible by 2^(len(decoder.channel_mult) - 1)");
  need(decoder.schedule_shift > 0, "decoder.schedule_shift must be positive");
  need(decoder.noise_correlation >= 0 && decoder.noise_correlation <= 1, "decoder.noise_correlation must be in [0, 1]");
  need(decoder.noise_scale >= 0 && decoder.noise_scale <= 1, "decoder.noise_scale must be in [0, 1]");
  need(decoder.start_time > 0 && decoder.start_time <= 1, "decoder.start_time must be in (0, 1]");
  need(decoder.train_max_time > 0 && decoder.train_max_time <= 1, "decoder.train_max_time must be in (0, 1]");
  need(decoder.w_temporal >= 0, "decoder.w_temporal must be >= 0");
  need(decoder.start_time == 1 || decoder.cond_image,
       "decoder.start_time < 1 needs decoder.cond_image (the coarse frame the sampler starts from)");
}

std::string Config::to_yaml() { return config_yaml(fields()); }

std::string set_yaml_key(const std::string& text, const std::string& kv, const std::string& where) {
  Config c;
  c.apply_yaml(text, where);
  c.set(kv);
  c.validate();
  const std::string key = kv.substr(0, kv.find('='));
  std::string value;
  for (auto& f : c.fields())
    if (f.key == key) value = f.get();  // the value as the config writes it ("0.9", "[0, 1, 2]")
  return replace_yaml_key(text, key, value);
}

}  // namespace gaia
