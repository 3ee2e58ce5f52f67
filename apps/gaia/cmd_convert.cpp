// gaia convert: re-store a weights file (tokenizer, world model, decoder, probe) with F32 tensors as F16, and/or with
// a sampling setting of its stored config changed (e.g. the temperature the world model is shipped to sample at).
#include <algorithm>
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"

namespace gaia::app {

void register_convert(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "convert", "store a safetensors weights file in fp16 (half the size; loaders convert back) and/or change the "
                 "sampling settings stored with it");
  auto in = std::make_shared<std::string>(), out = std::make_shared<std::string>();
  auto half = std::make_shared<bool>(false);
  auto sets = std::make_shared<std::vector<std::string>>();
  cmd->add_option("WEIGHTS", *in, "safetensors file")->required();
  cmd->add_flag("--half", *half, "store F32 tensors as F16");
  cmd->add_option("--set", *sets,
                  "KEY=VALUE: change a sampling setting in the file's stored config (the default of every command "
                  "that loads it), e.g. world.temperature=0.9; repeatable")
      ->take_all();
  cmd->add_option("--out", *out, "output file (may be WEIGHTS itself)")->required();
  cmd->callback([=] {
    if (!*half && sets->empty()) fail("gaia convert: say --half, --set KEY=VALUE or both");
    std::map<std::string, std::string> metadata;
    if (!sets->empty()) {
      std::string yaml;
      {
        SafetensorsFile f(*in);
        auto it = f.metadata().find("gaia.config");
        if (it == f.metadata().end()) fail("{}: no gaia.config metadata (not a gaia weights file)", *in);
        yaml = it->second;
      }
      // Only how the model is sampled: any other key is fixed by the weights themselves (their shapes, their
      // training), and a changed copy would describe another model than the one stored.
      for (const auto& kv : *sets) {
        const std::string key = kv.substr(0, kv.find('='));
        const bool sampling = std::count(kWorldSamplingKeys.begin(), kWorldSamplingKeys.end(), key) ||
                              std::count(kDecoderSamplingKeys.begin(), kDecoderSamplingKeys.end(), key);
        if (!sampling)
          fail("--set {}: only sampling settings can be changed in a weights file ({}, {})", kv,
               fmt::join(kWorldSamplingKeys, ", "), fmt::join(kDecoderSamplingKeys, ", "));
        yaml = set_yaml_key(yaml, kv, *in + " [metadata]");
      }
      metadata["gaia.config"] = yaml;
    }
    const double err = rewrite_weights(*in, *out, *half, metadata);
    if (*half) std::printf("%s -> %s (F16; largest rounding error %.3g)\n", in->c_str(), out->c_str(), err);
    for (const auto& kv : *sets) std::printf("%s: %s\n", out->c_str(), kv.c_str());
  });
}

}  // namespace gaia::app
