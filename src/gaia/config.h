#pragma once
// The one configuration of a gaia run, loaded from YAML (configs/*.yaml) plus --set key=value overrides. Each
// model's section lives beside the model (data/config.h, tokenizer/config.h, world/config.h, decoder/config.h) and
// registers its keys there; core/config_registry.h loads, overrides, checks and dumps them.
// Defaults are the CPU-sized default config; configs/paper.yaml holds the paper's values (§4).
#include <cstdint>
#include <string>
#include <vector>

#include "gaia/core/config_registry.h"
#include "gaia/core/fs.h"
#include "gaia/data/config.h"
#include "gaia/decoder/config.h"
#include "gaia/tokenizer/config.h"
#include "gaia/world/config.h"

namespace gaia {

struct RunConfig {
  std::string device = "cpu";    // cpu | cuda | cuda:N
  int threads = 0;               // 0 = all cores
  uint64_t seed = 0;
  int checkpoint_every = 200;    // steps between checkpoints (resumable training)
  std::string precision = "fp32"; // fp32 | bf16 | fp16: autocast for training and sampling (torch/precision.h)
};

struct Config {
  std::string name = "default";
  DataConfig data;
  TokenizerConfig tokenizer;
  WorldConfig world;
  DecoderConfig decoder;
  RunConfig run;

  // Derived quantities (paper §2.1, §4.2)
  int tokens_h() const { return data.height / tokenizer.downsample; }
  int tokens_w() const { return data.width / tokenizer.downsample; }
  int image_tokens() const { return tokens_h() * tokens_w(); }  // n; paper: 18 x 32 = 576
  int step_tokens() const { return world.text_tokens + image_tokens() + world.action_tokens; }  // m + n + l = 610
  int64_t sequence_length() const { return int64_t(world.context_steps) * step_tokens(); }  // paper: 15860

  // Registry: each field with its dotted key ("world.d_model"), bound to this config.
  using Field = ConfigField;
  std::vector<Field> fields();
  // The keys of one section ("world", "decoder") with one role: e.g. the sampling keys a run may override.
  static std::vector<std::string> keys(const std::string& section, ConfigRole role);

  static Config load(const fs::path& yaml);        // unknown keys -> "FILE: unknown config key 'a.b'"
  void apply_yaml(const std::string& text, const std::string& where);
  void set(const std::string& key_eq_value);        // --set world.d_model=512
  void validate() const;                            // every key's range, then cross-field checks (D divides H, W; ...)
  std::string to_yaml();
};

// A stored config's YAML `text` (e.g. a weights file's metadata) with one key set: "world.temperature=0.9", checked
// as --set checks it and the whole config validated. Only that key changes; keys the text lacks stay absent, so a
// loader still sees which keys the file was saved without (decoder/io.cpp gives those their legacy values).
std::string set_yaml_key(const std::string& text, const std::string& key_eq_value, const std::string& where);

}  // namespace gaia
