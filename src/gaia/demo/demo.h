#pragma once
// `gaia demo`, the README's first command, as one library call: with the shipped models, a video prompt and three
// sampled futures, steering left / right against the counterfactual replay of the same procedural world, scenes
// generated from a text prompt alone (§5), an unconditional scene, the video decoder (§2.4) beside the tokenizer's
// decoder, and the probes' read-back of what was asked for, gathered into one HTML report (report/report.h).
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gaia/core/fs.h"
#include "gaia/torch/precision.h"

namespace gaia::demo {

struct DemoOptions {
  fs::path models = "models";    // world, tokenizer, decoder and probe weights, by their shipped file names
  std::string video;             // a driving video as the prompt instead of a procedural drive (e.g. a real clip)
  int prompt_frames = 3;         // video prompt frames (6.25 Hz)
  int frames = 10;               // frames generated per rollout (6.25 Hz)
  int ddim_steps = 10;           // video decoder; §5.2 uses 50, fewer keep the demo short
  double fps = 12.5;             // the video decoder's output rate: 6.25, 12.5 or 25 Hz
  double text_guidance = 8.0;    // §5.1 guidance scale on the text prompts, constant over the frames
  double action_guidance = 16.0; // guidance on the steering commands, against the mirrored command (0 = off)
  uint64_t seed = 0;
  std::string device = "cpu";
  Precision precision = Precision::kFp32;  // --precision: the rollouts' and the video decoder's products
  std::string command_line;      // recorded in the report, so that the page can be remade
};

// What the demo asked for and what the probes read back from the decoded frames (one rollout each: an
// illustration; `gaia eval` measures).
struct DemoResult {
  fs::path report;               // OUT/report.html
  nlohmann::json readback;
  double seconds = 0;
};

// Runs the demo into `out` (report.html, report.json, videos/). `say` gets the lines worth showing a user (the
// models, the prompt, notes); progress bars go to stderr. Fails with one line naming a missing weights file.
DemoResult run_demo(const DemoOptions& o, const fs::path& out, const std::function<void(const std::string&)>& say);

// The prompts of the text section and the scene-probe class each should be read back as.
struct TextPrompt {
  std::string prompt;
  int attribute;                 // 0 weather, 1 time of day (probe::read_scene's columns)
  std::string read_as;           // the class name (probe::weather_classes / time_classes)
};
const std::vector<TextPrompt>& demo_text_prompts();

}  // namespace gaia::demo
