#pragma once
// Text control (§5.1, the paper's Fig. 8 in pictures): scenes generated from a text prompt alone, for prompts
// that name a weather, a time of day or a traffic-light state; the scene probe reads the attribute back from the
// decoded frames. Measured as the probe's accuracy on the prompted attribute against the classifier-free guidance
// scale (eq. 2), with a negative prompt, and with the token / frame guidance schedules (Fig. 6).
#include "gaia/emerging/common.h"
#include "gaia/world/sampling.h"

namespace gaia::emerging {

struct TextTarget {
  int attribute;          // 0 weather, 1 time of day, 2 traffic light (probe heads)
  std::string value;      // the class the probe should read
  std::string prompt;     // words of the synth captions' vocabulary
  std::string negative;   // the opposite, for the negative-prompt run
};
std::vector<TextTarget> text_targets();

struct TextEvalOptions {
  int futures = 4;                                   // rollouts per target and setting
  int frames = 4;                                    // generated (from scratch, or after a real prompt)
  // > 0: each rollout starts from this many steps of a held-out daytime drive of the token dataset, of
  // prompt_footage, and only weather and time of day are prompted: text steering a scene in view. 0: from scratch
  // (the paper's Fig. 8).
  int prompt_frames = 0;
  Footage prompt_footage = Footage::kReal;
  // Guidance scales s; the last one also runs with the negative prompt and with the schedules. The range reaches
  // past the scales where text control usually saturates, so the curve shows where it stops rising.
  std::vector<double> scales{0.0, 1.0, 2.0, 4.0, 8.0};
  world::SamplingOptions sampling;
  uint64_t seed = 0;
};

// The ceiling of those accuracies: the scene probe on decoded real frames (`frames_per_episode` evenly spaced steps
// of each of these token episodes, through the same tokenizer decoder) whose episode's weather / time of day is a
// prompted value -> {"per_target": {value: accuracy}, "weather", "time_of_day" (means over the values present),
// "frames", "episodes"}. Light states are per frame and not in token episodes' metadata: not measured.
nlohmann::json real_decoded_accuracy(Models& m, const world::TokenDataset& ds, const std::vector<size_t>& episodes,
                                     int frames_per_episode);

// real: the token dataset whose held-out episodes give the ceiling above (and the real prompts); nullptr skips it.
nlohmann::json text_control(Models& m, const TextEvalOptions& o, Output& out, const world::TokenDataset* real = nullptr);

}  // namespace gaia::emerging
