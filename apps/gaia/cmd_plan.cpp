// gaia plan CONFIG: parameter counts, FLOPs per token, memory and sequence length of a configuration.
#include <cstdio>

#include <nlohmann/json.hpp>
#include <torch/version.h>

#include "common.h"
#include "gaia/sizing/sizing.h"

namespace gaia::app {

void register_plan(CLI::App& app) {
  auto* cmd = app.add_subcommand("plan", "parameters, FLOPs per token (6N), memory and sequence length of a config");
  auto flags = std::make_shared<SharedFlags>();
  auto positional = std::make_shared<std::string>();
  cmd->add_option("CONFIG", *positional, "config YAML (same as --config)");
  add_shared_flags(cmd, flags.get(), "unused");
  auto json = std::make_shared<bool>(false), keys = std::make_shared<bool>(false);
  auto ranks = std::make_shared<int>(1), accumulate = std::make_shared<int>(1);
  auto shard = std::make_shared<bool>(false);
  cmd->add_option("--nproc", *ranks, "training memory: ranks the world model trains on (data-parallel)")
      ->check(number_in({1, 1 << 20}));
  cmd->add_option("--accumulate", *accumulate, "training memory: micro-batches per rank and step")
      ->check(number_in({1, 1 << 16}));
  cmd->add_flag("--shard-optimizer", *shard, "training memory: AdamW's state sharded over the ranks (ZeRO-1)");
  auto shard_grads = std::make_shared<bool>(false);
  cmd->add_flag("--shard-gradients", *shard_grads,
                "training memory: the kept gradients sharded too (ZeRO-2; implies --shard-optimizer)");
  cmd->add_flag("--json", *json, "print the plan as JSON");
  cmd->add_flag("--keys", *keys, "list every config key with its type, role (architecture, training, sampling, ...), value in this config and allowed range");
  cmd->callback([=] {
    SharedFlags f = *flags;
    if (!positional->empty()) f.config = *positional;
    Config c = resolve_config(f);
    if (*keys) {
      std::printf("%-34s %-12s %-12s %-24s %s\n", "key", "type", "role", "value", "allowed");
      for (auto& k : c.fields())
        std::printf("%-34s %-12s %-12s %-24s %s\n", k.key.c_str(), k.type.c_str(), role_name(k.role), k.get().c_str(),
                    k.range.bounded() ? k.range.str().c_str() : "");
      return;
    }
    sizing::Plan p = sizing::make_plan(c);
    // This build's attention: fused where LibTorch has scaled_dot_product_attention (torch/attention.cpp).
    const auto ms = sizing::train_memory_settings(c, *ranks, *accumulate, *shard, TORCH_VERSION_MAJOR >= 2, *shard_grads);
    const auto mem = sizing::world_train_memory(c, ms);
    const auto flops = sizing::inference_flops(c, 2);
    if (*json) {
      nlohmann::json j = {{"config", c.name},
                          {"tokenizer_params", p.tokenizer.total},
                          {"discriminator_params", p.discriminator},
                          {"world_params", p.world.total},
                          {"world_non_embedding_params", p.world.non_embedding},
                          {"decoder_params", p.decoder.total},
                          {"image_tokens", p.image_tokens},
                          {"sequence_length", p.sequence_length},
                          {"bit_compression", p.bit_compression},
                          {"world_flops_per_token", p.world_flops_per_token},
                          {"world_flops_per_token_with_attn", p.world_flops_per_token_with_attn},
                          {"inference_flops",
                           {{"world_token", flops.world_token},
                            {"world_frame_sampling_guided", flops.world_frame_sampling},
                            {"world_frame_reencode_guided", flops.world_frame_reencode},
                            {"decoder_window", flops.decoder_window},
                            {"decoder_video_second", flops.decoder_video_second}}},
                          {"world_train_memory",
                           {{"micro_batch", ms.micro_batch},
                            {"ranks", ms.ranks},
                            {"precision", c.run.precision},
                            {"fused_attention", ms.fused_attention},
                            {"weights", mem.weights},
                            {"gradients", mem.grads},
                            {"optimizer", mem.optimizer},
                            {"allreduce_buffers", mem.buckets},
                            {"activations", mem.activations},
                            {"output_distribution", mem.logits},
                            {"beyond_weights", mem.beyond_weights()},
                            {"total", mem.total()}}}};
      std::printf("%s\n", j.dump(2).c_str());
    } else {
      std::fputs(sizing::format_plan(p, c).c_str(), stdout);
      std::fputs(sizing::format_train_memory(mem, ms).c_str(), stdout);
    }
  });
}

}  // namespace gaia::app
