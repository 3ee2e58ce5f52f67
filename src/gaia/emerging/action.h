#pragma once
// Action control (§5, Fig. 9 of the paper shows it in pictures): from held-out video prompts, roll out under
// commanded speed / curvature sequences, in and out of the training distribution, and read back what the ego did
// with the dynamics probe. Measured three ways:
//   - agreement of commanded and read-back curvature and speed (Spearman over rollouts, steering sign accuracy);
//   - the same rollouts without action conditioning (null actions), the baseline the conditioning must beat;
//   - against the counterfactual replay of the procedural world under the same commands (per-frame PSNR of the
//     decoded frames and FD-probe), when the raw dataset the tokens came from is given.
#include "gaia/emerging/common.h"
#include "gaia/data/episode.h"
#include "gaia/world/sampling.h"

namespace gaia::emerging {

struct Command {
  std::string name;
  double speed = -1;      // m/s; < 0: hold the prompt's last speed
  double curvature = 0;   // 1/m, + = left; held for every generated frame
  double drift = 0;       // 1/m per generated frame added on top (a slow drift off the lane)
  bool out_of_distribution = false;
};
// straight, left, right (gentle curves, within what the recorded drivers do), strong-left, strong-right (a 30 m
// radius, beyond the lane keeper's driving; only swerving drives turn this hard), drift-right (a
// growing pull off the lane, which the recorded driver never does), slow and fast (speed commands, straight).
// "sweep": the steering response curve instead, turns of 8 to 40 1/km right and 8 to 30 1/km left at the kept speed,
// to see where the model's read-back stops growing with the command.
inline const std::vector<std::string> kCommandSets{"default", "sweep"};  // the sets action_commands() knows
std::vector<Command> action_commands(const std::string& set = "default");

struct ActionEvalOptions {
  int prompts = 8;            // held-out video prompts
  int prompt_frames = 3;      // P
  int frames = 5;             // F generated frames per rollout
  world::SamplingOptions sampling;
  // Classifier-free guidance on the actions (eq. 2 with null action tokens as the unconditional branch): the
  // paper guides text; the same mechanism amplifies whatever the model has learned about the commands.
  double guidance_scale = 0;
  // The unconditional branch's actions: null (eq. 2 as in the paper) or, with `mirror_negative`, the
  // counter-command: the curvature mirrored, the speed the steering commands keep (the prompt's, at least 3 m/s).
  // Guidance then contrasts turning right with turning left, and slow or fast with keeping the speed, instead of
  // either with no command; a straight command at the kept speed is not guided at all.
  bool mirror_negative = true;
  std::string commands = "default";  // action_commands(): "default" or "sweep"
  Footage footage = Footage::kAny;   // which held-out episodes give the prompts
  uint64_t seed = 0;
};

// raw: the procedural dataset the tokens were made from (counterfactual replay); nullptr skips that part.
nlohmann::json action_control(Models& m, const world::TokenDataset& tokens, const data::Dataset* raw,
                              const ActionEvalOptions& o, Output& out);

}  // namespace gaia::emerging
