#pragma once
// Shipping a world model: weights in safetensors with everything needed to use them in the metadata: the config
// (YAML), the token grid (h, w), the codebook size K and how it reads text (the built-in words, or embeddings).
#include "gaia/text/vocab.h"
#include "gaia/world/model.h"

namespace gaia::world {

struct WorldInfo {
  Config config;
  int64_t grid_h = 0, grid_w = 0, K = 0;
  text::Vocab vocab;
  // Who made the text embeddings the model was trained on (a text encoder's identity, text/t5.h, or
  // "precomputed"); empty = the built-in words of `vocab`. A prompt's text must come from the same encoder.
  std::string text_encoder;
  // Share of the training steps that had an action (speed or curvature); -1 = not recorded (older weights).
  // 0 means the model never saw one: action conditioning (--steer, --speed, --actions) would do nothing.
  double action_share = -1;
  int64_t n() const { return grid_h * grid_w; }
  bool embeds_text() const { return !text_encoder.empty(); }
};

void save_world(WorldModel& m, const WorldInfo& info, const fs::path& path);
// The metadata alone (no weights read). Errors name the file.
WorldInfo read_world_info(const fs::path& path);
// Builds the model from the file's metadata and loads the weights (on `device`, eval mode). Errors name the file.
WorldModel load_world(const fs::path& path, const torch::Device& device, WorldInfo* info_out = nullptr);

}  // namespace gaia::world
