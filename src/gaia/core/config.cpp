#include "gaia/core/config.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "gaia/core/error.h"

namespace gaia {

namespace {

template <typename T> std::string type_name();
template <> std::string type_name<int>() { return "int"; }
template <> std::string type_name<uint64_t>() { return "uint"; }
template <> std::string type_name<double>() { return "float"; }
template <> std::string type_name<bool>() { return "bool"; }
template <> std::string type_name<std::string>() { return "string"; }
template <> std::string type_name<std::vector<int>>() { return "int list"; }
template <> std::string type_name<std::vector<std::string>>() { return "string list"; }

template <typename T> std::string emit(const T& v) {
  YAML::Emitter e;
  e << YAML::Flow << v;
  return e.c_str();
}

// "[+-]digits" (a loop: std::regex recurses per character and a long scalar would overflow the stack).
bool is_decimal_integer(const std::string& s) {
  const size_t start = !s.empty() && (s[0] == '+' || s[0] == '-') ? 1 : 0;
  return s.size() > start && s.size() < 40 &&
         std::all_of(s.begin() + long(start), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// A number's check against its key's range; lists check every element.
template <typename T> void check_range(const std::string& key, const T& v, const Range& r) {
  if constexpr (std::is_same_v<T, int> || std::is_same_v<T, double> || std::is_same_v<T, uint64_t>) {
    if (!r.contains(static_cast<double>(v)))
      fail("config key '{}' = {} is out of range: allowed {}", key, emit(v), r.str());
  } else if constexpr (std::is_same_v<T, std::vector<int>>) {
    for (int x : v)
      if (!r.contains(x)) fail("config key '{}' has entry {} out of range: each entry allowed {}", key, x, r.str());
  }
}

template <typename T> Config::Field field(const std::string& key, T* p, Range r = {}) {
  Config::Field f;
  f.key = key;
  f.type = type_name<T>();
  f.range = r;
  f.get = [p] { return emit(*p); };
  f.check = [p, key, r] { check_range(key, *p, r); };
  f.set = [p, key, r](const std::string& text) {
    T v;
    try {
      YAML::Node n = YAML::Load(text);
      if (n.IsNull()) fail("config key '{}' has no value", key);
      if constexpr (std::is_same_v<T, uint64_t> || std::is_same_v<T, int>) {
        // yaml-cpp reads "0x10" as 16 and wraps "-1" into a huge unsigned; a config number is plain decimal.
        if (!n.IsScalar() || !is_decimal_integer(n.Scalar())) throw YAML::Exception(YAML::Mark(), "");
        if (std::is_same_v<T, uint64_t> && n.Scalar()[0] == '-') throw YAML::Exception(YAML::Mark(), "");
      }
      v = n.as<T>();
      if constexpr (std::is_same_v<T, std::string> || std::is_same_v<T, std::vector<std::string>>) {
        // A control character (a stray "\r") would not survive the YAML this config is saved as.
        const std::vector<std::string> items = [&] {
          if constexpr (std::is_same_v<T, std::string>) return std::vector<std::string>{v};
          else return v;
        }();
        for (auto& item : items)
          for (unsigned char ch : item)
            if (ch < 0x20 || ch == 0x7f) fail("config key '{}' has a control character in '{}'", key, item);
      }
      if constexpr (std::is_same_v<T, double>) {
        if (!(v == v)) fail("config key '{}' is NaN", key);
        if (!std::isfinite(v)) fail("config key '{}' = {} is not finite", key, text);
      }
    } catch (const YAML::Exception&) {
      fail("config key '{}' expects {} but got '{}'", key, type_name<T>(), text);
    }
    check_range(key, v, r);
    *p = v;  // only a value that parsed and is in range replaces the old one
  };
  return f;
}

// Keys are "section.key" at most, so anything deeper is an unknown key; the depth bound also ends a YAML alias that
// refers to itself (`a: &a {b: *a}`) instead of recursing forever.
void flatten(const YAML::Node& node, const std::string& prefix, std::vector<std::pair<std::string, YAML::Node>>* out,
             const std::string& where, int depth = 0) {
  if (node.IsMap() && depth < 3) {
    for (auto it = node.begin(); it != node.end(); ++it) {
      if (!it->first.IsScalar())
        fail("{}:{}: a config key must be a name, not a {}", where, it->first.Mark().line + 1,
             it->first.IsMap() ? "mapping" : "list");
      const std::string k = it->first.Scalar();
      flatten(it->second, prefix.empty() ? k : prefix + "." + k, out, where, depth + 1);
    }
  } else {
    out->emplace_back(prefix, node);
  }
}

// Range builders for the registry below.
Range closed(double lo, double hi) { return {lo, hi, false, false}; }  // [lo, hi]
Range above(double lo, double hi) { return {lo, hi, true, false}; }    // (lo, hi]
const Range kWeight = closed(0, 1e6);      // loss weights
const Range kRate = closed(0, 10);         // learning rates (0 freezes: fine-tune tests use it)
const Range kBeta = {0, 1, false, true};   // Adam betas, [0, 1)
const Range kDecay = {0, 1, false, true};  // EMA decay, dropout, [0, 1)
const Range kSteps = closed(1, 1e9);
const Range kSteps0 = closed(0, 1e9);
const Range kBatch = closed(1, 1 << 20);

}  // namespace

std::string Range::str() const {
  auto num = [](double v) {
    if (std::isinf(v)) return std::string(v < 0 ? "-inf" : "inf");
    return v == std::floor(v) && std::abs(v) < 1e15 ? fmt::format("{:.0f}", v) : fmt::format("{:g}", v);
  };
  return fmt::format("{}{}, {}{}", lo_open || std::isinf(lo) ? "(" : "[", num(lo), num(hi),
                     hi_open || std::isinf(hi) ? ")" : "]");
}

std::vector<Config::Field> Config::fields() {
  std::vector<Field> f;
  f.push_back(field("name", &name));
  auto& d = data;
  f.push_back(field("data.height", &d.height, closed(8, 8192)));
  f.push_back(field("data.width", &d.width, closed(8, 8192)));
  f.push_back(field("data.native_fps", &d.native_fps, above(0, 1000)));
  f.push_back(field("data.world_fps", &d.world_fps, above(0, 1000)));
  f.push_back(field("data.balance_tokenizer", &d.balance_tokenizer));
  f.push_back(field("data.balance_world", &d.balance_world));
  f.push_back(field("data.balance_exponent", &d.balance_exponent, closed(0, 1)));
  f.push_back(field("data.balance_bins", &d.balance_bins, closed(1, 10000)));
  auto& t = tokenizer;
  f.push_back(field("tokenizer.downsample", &t.downsample, closed(1, 256)));
  f.push_back(field("tokenizer.codebook_size", &t.codebook_size, closed(2, 32768)));
  f.push_back(field("tokenizer.code_dim", &t.code_dim, closed(1, 4096)));
  f.push_back(field("tokenizer.channels", &t.channels, closed(1, 8192)));
  f.push_back(field("tokenizer.channel_mult", &t.channel_mult, closed(1, 64)));
  f.push_back(field("tokenizer.res_blocks", &t.res_blocks, closed(1, 64)));
  f.push_back(field("tokenizer.refine_blocks", &t.refine_blocks, closed(0, 64)));
  f.push_back(field("tokenizer.token_blocks", &t.token_blocks, closed(0, 64)));
  f.push_back(field("tokenizer.z_channels", &t.z_channels, closed(1, 16384)));
  f.push_back(field("tokenizer.disc_channels", &t.disc_channels, closed(1, 8192)));
  f.push_back(field("tokenizer.disc_layers", &t.disc_layers, closed(1, 16)));
  f.push_back(field("tokenizer.w_l1", &t.w_l1, kWeight));
  f.push_back(field("tokenizer.w_l2", &t.w_l2, kWeight));
  f.push_back(field("tokenizer.w_perceptual", &t.w_perceptual, kWeight));
  f.push_back(field("tokenizer.w_gan", &t.w_gan, kWeight));
  f.push_back(field("tokenizer.w_codebook", &t.w_codebook, kWeight));
  f.push_back(field("tokenizer.w_dino", &t.w_dino, kWeight));
  f.push_back(field("tokenizer.commitment", &t.commitment, kWeight));
  f.push_back(field("tokenizer.disc_start", &t.disc_start, kSteps0));
  f.push_back(field("tokenizer.gan_adaptive", &t.gan_adaptive));
  f.push_back(field("tokenizer.lr", &t.lr, kRate));
  f.push_back(field("tokenizer.weight_decay", &t.weight_decay, closed(0, 10)));
  f.push_back(field("tokenizer.beta1", &t.beta1, kBeta));
  f.push_back(field("tokenizer.beta2", &t.beta2, kBeta));
  f.push_back(field("tokenizer.final_lr", &t.final_lr, closed(0, 10)));
  f.push_back(field("tokenizer.warmup_steps", &t.warmup_steps, kSteps0));
  f.push_back(field("tokenizer.steps", &t.steps, kSteps));
  f.push_back(field("tokenizer.batch_size", &t.batch_size, kBatch));
  f.push_back(field("tokenizer.ema_decay", &t.ema_decay, kDecay));
  auto& w = world;
  f.push_back(field("world.d_model", &w.d_model, closed(1, 65536)));
  f.push_back(field("world.n_layers", &w.n_layers, closed(1, 1024)));
  f.push_back(field("world.n_heads", &w.n_heads, closed(1, 1024)));
  f.push_back(field("world.context_steps", &w.context_steps, closed(1, 4096)));
  f.push_back(field("world.text_tokens", &w.text_tokens, closed(1, 1024)));
  f.push_back(field("world.text_dim", &w.text_dim, closed(1, 65536)));
  f.push_back(field("world.text_vocab", &w.text_vocab, closed(2, 1 << 20)));
  f.push_back(field("world.action_tokens", &w.action_tokens, closed(2, 2)));
  f.push_back(field("world.action_mlp", &w.action_mlp, closed(0, 65536)));
  f.push_back(field("world.dropout", &w.dropout, kDecay));
  f.push_back(field("world.p_uncond", &w.p_uncond, closed(0, 1)));
  f.push_back(field("world.p_action", &w.p_action, closed(0, 1)));
  f.push_back(field("world.p_text", &w.p_text, closed(0, 1)));
  f.push_back(field("world.p_action_replay", &w.p_action_replay, closed(-1, 1)));
  f.push_back(field("world.lr", &w.lr, kRate));
  f.push_back(field("world.weight_decay", &w.weight_decay, closed(0, 10)));
  f.push_back(field("world.beta1", &w.beta1, kBeta));
  f.push_back(field("world.beta2", &w.beta2, kBeta));
  f.push_back(field("world.grad_clip", &w.grad_clip, closed(0, 1e6)));
  f.push_back(field("world.final_lr_ratio", &w.final_lr_ratio, closed(0, 1)));
  f.push_back(field("world.warmup_steps", &w.warmup_steps, kSteps0));
  f.push_back(field("world.steps", &w.steps, kSteps));
  f.push_back(field("world.batch_size", &w.batch_size, kBatch));
  f.push_back(field("world.activation_checkpointing", &w.activation_checkpointing));
  f.push_back(field("world.top_k", &w.top_k, closed(1, 1 << 20)));
  f.push_back(field("world.temperature", &w.temperature, above(0, 100)));
  f.push_back(field("world.copy_bias", &w.copy_bias, closed(-100, 100)));
  f.push_back(field("world.guide_actions_within_top_k", &w.guide_actions_within_top_k));
  f.push_back(field("world.guidance_scale", &w.guidance_scale, closed(0, 100)));
  auto& v = decoder;
  f.push_back(field("decoder.channels", &v.channels, closed(1, 8192)));
  f.push_back(field("decoder.channel_mult", &v.channel_mult, closed(1, 64)));
  f.push_back(field("decoder.res_blocks", &v.res_blocks, closed(1, 64)));
  f.push_back(field("decoder.attn_levels", &v.attn_levels, closed(0, 16)));
  f.push_back(field("decoder.temporal_levels", &v.temporal_levels, closed(0, 16)));
  f.push_back(field("decoder.heads", &v.heads, closed(1, 1024)));
  f.push_back(field("decoder.token_embed_dim", &v.token_embed_dim, closed(1, 8192)));
  f.push_back(field("decoder.cond_image", &v.cond_image));
  f.push_back(field("decoder.interp_base", &v.interp_base));
  f.push_back(field("decoder.schedule_shift", &v.schedule_shift, above(0, 1000)));
  f.push_back(field("decoder.frames", &v.frames, closed(3, 1023)));
  f.push_back(field("decoder.token_dropout", &v.token_dropout, closed(0, 1)));
  f.push_back(field("decoder.ddim_steps", &v.ddim_steps, closed(1, 10000)));
  f.push_back(field("decoder.mix_probability", &v.mix_probability, closed(0, 1)));
  f.push_back(field("decoder.mix_weight", &v.mix_weight, closed(0, 1)));
  f.push_back(field("decoder.noise_correlation", &v.noise_correlation, closed(0, 1)));
  f.push_back(field("decoder.noise_scale", &v.noise_scale, closed(0, 1)));
  f.push_back(field("decoder.start_time", &v.start_time, above(0, 1)));
  f.push_back(field("decoder.train_max_time", &v.train_max_time, above(0, 1)));
  f.push_back(field("decoder.w_temporal", &v.w_temporal, kWeight));
  f.push_back(field("decoder.w_l1", &v.w_l1, kWeight));
  f.push_back(field("decoder.w_l2", &v.w_l2, kWeight));
  f.push_back(field("decoder.ema_decay", &v.ema_decay, kDecay));
  f.push_back(field("decoder.lr", &v.lr, kRate));
  f.push_back(field("decoder.weight_decay", &v.weight_decay, closed(0, 10)));
  f.push_back(field("decoder.beta1", &v.beta1, kBeta));
  f.push_back(field("decoder.beta2", &v.beta2, kBeta));
  f.push_back(field("decoder.grad_clip", &v.grad_clip, closed(0, 1e6)));
  f.push_back(field("decoder.final_lr", &v.final_lr, closed(0, 10)));
  f.push_back(field("decoder.warmup_steps", &v.warmup_steps, kSteps0));
  f.push_back(field("decoder.steps", &v.steps, kSteps));
  f.push_back(field("decoder.batch_size", &v.batch_size, kBatch));
  f.push_back(field("run.device", &run.device));
  f.push_back(field("run.threads", &run.threads, closed(0, 4096)));
  f.push_back(field("run.seed", &run.seed));
  f.push_back(field("run.checkpoint_every", &run.checkpoint_every, closed(1, 1e9)));
  return f;
}

void Config::apply_yaml(const std::string& text, const std::string& where) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    fail("{}:{}: YAML syntax error ({})", where, e.mark.line + 1, e.msg);
  }
  if (root.IsNull()) return;
  if (!root.IsMap()) fail("{}: top level must be a mapping of config keys", where);
  std::vector<std::pair<std::string, YAML::Node>> flat;
  flatten(root, "", &flat, where);
  auto fs_ = fields();
  std::map<std::string, Field*> by_key;
  for (auto& f : fs_) by_key[f.key] = &f;
  for (auto& [key, node] : flat) {
    auto it = by_key.find(key);
    int line = node.Mark().line + 1;
    if (it == by_key.end()) fail("{}:{}: unknown config key '{}'", where, line, key);
    try {
      it->second->set(YAML::Dump(node));
    } catch (const Error& e) {
      fail("{}:{}: {}", where, line, e.what());
    } catch (const YAML::Exception& e) {
      fail("{}:{}: config key '{}': {}", where, line, key, e.msg);
    }
  }
}

Config Config::load(const fs::path& yaml) {
  if (!fs::exists(yaml)) fail("{}: no such config file", yaml.string());
  Config c;
  c.apply_yaml(read_file(yaml), yaml.string());
  c.validate();
  return c;
}

void Config::set(const std::string& kv) {
  auto eq = kv.find('=');
  if (eq == std::string::npos) fail("--set '{}': expected key=value", kv);
  std::string key = kv.substr(0, eq), value = kv.substr(eq + 1);
  for (auto& f : fields())
    if (f.key == key) {
      try {
        f.set(value);
      } catch (const Error& e) {
        fail("--set {}: {}", kv, e.what());
      }
      return;
    }
  fail("--set: unknown config key '{}'", key);
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

std::string Config::to_yaml() {
  // Keys are at most two levels deep ("section.key"), so the YAML is written directly.
  std::string out, section;
  for (auto& f : fields()) {
    auto dot = f.key.find('.');
    if (dot == std::string::npos) {
      out += f.key + ": " + f.get() + "\n";
      continue;
    }
    std::string s = f.key.substr(0, dot);
    if (s != section) out += s + ":\n";
    section = s;
    out += "  " + f.key.substr(dot + 1) + ": " + f.get() + "\n";
  }
  return out;
}

std::string set_yaml_key(const std::string& text, const std::string& kv, const std::string& where) {
  Config c;
  c.apply_yaml(text, where);
  c.set(kv);
  c.validate();
  const std::string key = kv.substr(0, kv.find('='));
  std::string value;
  for (auto& f : c.fields())
    if (f.key == key) value = f.get();  // the value as the config writes it ("0.9", "[0, 1, 2]")
  YAML::Node root = YAML::Load(text);
  if (root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
  const auto dot = key.find('.');
  if (dot == std::string::npos)
    root[key] = YAML::Load(value);
  else
    root[key.substr(0, dot)][key.substr(dot + 1)] = YAML::Load(value);
  return YAML::Dump(root) + "\n";
}

}  // namespace gaia
