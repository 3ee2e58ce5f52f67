#pragma once
// Classifier-free guidance (§5.1, paper eq. 2): l = (1 + s) l_cond - s l_uncond, where l_uncond comes from the
// same network with the conditioning replaced by null tokens, or by a negative prompt. The scale s is scheduled
// over the tokens of a frame and over the frames of a rollout (Fig. 6: it helps to guide the first tokens of a
// frame, which fix its layout, more than the last ones, and the first frames more than later ones).
#include <string>

#include <torch/torch.h>

namespace gaia::world {

struct GuidanceSchedule {
  enum class Tokens { Constant, Linear };   // Linear: s at the first token of a frame, decreasing to 0 at the last
  enum class Frames { Constant, Cosine };   // Cosine: s for `plateau` frames, then half a cosine down to 0
  double scale = 0;                         // s; 0 = no guidance (one forward pass)
  Tokens tokens = Tokens::Constant;
  Frames frames = Frames::Constant;
  int plateau = 0;                          // frames at full scale before the cosine decay
  int total_frames = 1;                     // frames the cosine decays over (the rollout length)

  double at(int frame, int token, int tokens_per_frame) const;  // s for this token of this generated frame
  bool active() const { return scale != 0; }
};

GuidanceSchedule::Tokens parse_token_schedule(const std::string& s);  // "constant" | "linear"
GuidanceSchedule::Frames parse_frame_schedule(const std::string& s);  // "constant" | "cosine"

// Paper eq. 2 on logits of any shape.
inline torch::Tensor guide(const torch::Tensor& cond, const torch::Tensor& uncond, double s) {
  return (1.0 + s) * cond - s * uncond;
}

}  // namespace gaia::world
