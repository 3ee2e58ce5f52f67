// gaia convert: re-store a weights file (tokenizer, world model, decoder, probe) with F32 tensors as F16, and/or with
// a sampling setting of its stored config changed (e.g. the temperature a world model samples at by default),
// and/or interpolated towards the weights it was fine-tuned from (core/interpolate.h).
#include <algorithm>
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/interpolate.h"
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
  auto from = std::make_shared<std::string>();
  auto alpha = std::make_shared<double>(0.5);
  cmd->add_option("--interpolate-from", *from,
                  "weights WEIGHTS was fine-tuned from: write FROM + alpha (WEIGHTS - FROM) instead (WiSE-FT; keeps "
                  "more of what the fine-tune would cost)");
  auto* alpha_opt = cmd->add_option("--alpha", *alpha, "with --interpolate-from: 0 = FROM, 1 = WEIGHTS (beyond: extrapolates)")
                        ->check(kSignedNumber);
  auto terms = std::make_shared<std::string>();
  cmd->add_option("--terms", *terms,
                  "the terms of use the weights carry from their training data (stored as gaia.terms metadata), e.g. "
                  "\"research use only\"");
  cmd->add_option("--out", *out, "output file (may be WEIGHTS itself)")->required();
  cmd->callback([=] {
    if (!*half && sets->empty() && from->empty() && terms->empty())
      fail("gaia convert: say --half, --set KEY=VALUE, --interpolate-from FROM, --terms TEXT or a combination");
    if (from->empty() && alpha_opt->count()) fail("gaia convert: --alpha needs --interpolate-from FROM");
    if (!from->empty() && !(*alpha >= 0 && *alpha <= 1)) fail("--alpha must be in [0, 1], got {}", *alpha);
    // Every check before anything is written. The interpolated weights carry WEIGHTS' metadata, so its config is
    // the one --set changes.
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
    if (!terms->empty()) metadata["gaia.terms"] = *terms;
    std::string src = *in;
    if (!from->empty()) {
      interpolate_weights(*from, *in, *alpha, *out);
      std::printf("%s: %s + %.3g (%s - %s)\n", out->c_str(), from->c_str(), *alpha, in->c_str(), from->c_str());
      if (!*half && sets->empty() && terms->empty()) return;
      src = *out;  // the rest rewrites the interpolated weights in place
    }
    const double err = rewrite_weights(src, *out, *half, metadata);
    if (*half) std::printf("%s -> %s (F16; largest rounding error %.3g)\n", src.c_str(), out->c_str(), err);
    for (const auto& kv : *sets) std::printf("%s: %s\n", out->c_str(), kv.c_str());
    if (!terms->empty()) std::printf("%s: terms: %s\n", out->c_str(), terms->c_str());
  });
}

}  // namespace gaia::app
