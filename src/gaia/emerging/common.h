#pragma once
// What the paper shows in pictures (§5), measured: the world model is asked for something (a steering command, a
// text prompt, several futures, a minute of driving), its tokens are decoded with the tokenizer's decoder, and
// the evaluation probes read back what happened. This file holds what every measurement shares.
//
//   Models         the world model, the tokenizer that made its tokens, and the two probes
//   Prompts        held-out video prompts (token episodes never trained on) with their recorded actions
//   read_*         probe read-back of decoded frames: ego speed / curvature between frames, scene attributes
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <torch/torch.h>

#include "gaia/probe/probe.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/text/encoder.h"
#include "gaia/torch/precision.h"
#include "gaia/world/footage.h"
#include "gaia/world/io.h"
#include "gaia/world/token_dataset.h"

namespace gaia::emerging {

struct Models {
  world::WorldModel world{nullptr};
  world::WorldInfo info;
  tokenizer::ImageTokenizer tok{nullptr};
  probe::ProbeNet dynamics{nullptr}, scene{nullptr};
  probe::ProbeNet realism{nullptr};  // optional (load_realism_probe): whether futures of real prompts stay real
  torch::Device dev{torch::kCPU};
  // Every rollout's products (--precision, world::RolloutOptions::precision); the tokenizer and the probes that
  // read the frames back stay float32, so a measure reads bf16 rollouts with the same instrument.
  Precision precision = Precision::kFp32;
  // Text prompts as the world model reads them (world/prompt_text.h); null for a model that reads T5 embeddings
  // when no T5 was given (text prompts then fail naming --t5).
  std::shared_ptr<text::TextEncoder> text;
  fs::path world_path;
  text::TextEncoder& text_encoder() const;  // fails as said above
};

// Loads the four weight files (and `t5`, the text encoder of a world model trained on T5 embeddings); errors name
// the file (and say when the tokenizer's grid is not the world model's).
Models load_models(const fs::path& world, const fs::path& tokenizer, const fs::path& dynamics_probe,
                   const fs::path& scene_probe, const torch::Device& dev, const fs::path& t5 = {});
// The realism probe (probe-realism.safetensors) into `m`; fails naming the file unless it is one.
void load_realism_probe(Models& m, const fs::path& path);
// Fails, naming both files, unless the tokenizer makes the token grid and codebook the world model was trained on.
void check_tokenizer_fits(const world::WorldInfo& info, const fs::path& world, const tokenizer::ImageTokenizer& tok,
                          const fs::path& tokenizer);

// Which held-out episodes give prompts (world/footage.h): a dataset of real and procedural drives measures each apart.
using world::Footage;

// `count` held-out prompts (split seed = the world model's training seed) of `frames` steps (at least `need` steps left in the episode from the start), spread over
// the token dataset's validation episodes; the start skips the first second of an episode.
struct Prompts {
  std::vector<size_t> episodes;  // token-dataset episode indices
  std::vector<int64_t> starts;   // first prompt step in each
  torch::Tensor tokens;          // [count, frames, n] int64
  torch::Tensor actions;         // [count, frames, 2] normalised (world/batch.h), NaN where unknown
};
// `keep` (optional) narrows the episodes further, e.g. to daytime drives.
Prompts held_out_prompts(const world::TokenDataset& ds, int count, int64_t frames, int64_t need, uint64_t seed,
                         Footage footage = Footage::kAny, const std::function<bool(size_t)>& keep = {});

// One token episode's image tokens -> [steps, n] int64 (a copy: it outlives the dataset's episode cache).
torch::Tensor episode_tokens(const world::TokenDataset& ds, size_t e);

// Token rollouts [N, S, n] -> N sequences of S BGR frames through the tokenizer's decoder.
std::vector<std::vector<cv::Mat>> decode(Models& m, const torch::Tensor& tokens);

// Dynamics probe on each window of K consecutive frames (one world step apart; K = the probe's frames, 2 for the
// pair probe) -> [S - K + 1, 2]: speed (m/s), curvature (1/m), each the mean over its window's steps.
torch::Tensor read_dynamics(Models& m, const std::vector<cv::Mat>& frames);
// Scene probe -> class ids [S, 4] (weather, time of day, light, lead close) and optionally features [S, F].
torch::Tensor read_scene(Models& m, const std::vector<cv::Mat>& frames, torch::Tensor* features = nullptr);
// Realism probe on each frame -> [N] probability that it is camera footage (needs m.realism).
torch::Tensor read_realism(Models& m, const std::vector<cv::Mat>& frames);

// Frames side by side (each row one sequence, each column one step) for the report's videos: -> S frames.
std::vector<cv::Mat> tile(const std::vector<std::vector<cv::Mat>>& rows, const std::vector<std::string>& labels);

// Where a measurement writes its videos and plots, and what it adds to the report (report/report.h manifest).
struct Output {
  fs::path dir;                   // run directory
  nlohmann::json sections = nlohmann::json::array();
  std::string command;            // the command line that produced it
  void gif(const std::string& rel, const std::vector<cv::Mat>& frames, double fps) const;  // dir / rel
  void text(const std::string& rel, const std::string& content) const;
};

}  // namespace gaia::emerging
