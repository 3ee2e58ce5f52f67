#pragma once
// Text control (§5.1, the paper's Fig. 8 in pictures): scenes generated from a text prompt alone, for prompts
// that name a weather, a time of day or a traffic-light state; the scene probe reads the attribute back from the
// decoded frames. Measured as the probe's accuracy on the prompted attribute against the classifier-free guidance
// scale (eq. 2), with a negative prompt, and with the token / frame guidance schedules (Fig. 6).
#include "gaia/control/common.h"
#include "gaia/world/sampling.h"

namespace gaia::control {

struct TextTarget {
  int attribute;          // 0 weather, 1 time of day, 2 traffic light (probe heads)
  std::string value;      // the class the probe should read
  std::string prompt;     // words of the synth captions' vocabulary
  std::string negative;   // the opposite, for the negative-prompt run
};
std::vector<TextTarget> text_targets();

struct TextEvalOptions {
  int futures = 4;                                   // rollouts per target and setting
  int frames = 4;                                    // generated from scratch
  std::vector<double> scales{0.0, 1.0, 2.0, 4.0};    // guidance scales s
  world::SamplingOptions sampling;
  uint64_t seed = 0;
};

nlohmann::json text_control(Models& m, const TextEvalOptions& o, Output& out);

}  // namespace gaia::control
