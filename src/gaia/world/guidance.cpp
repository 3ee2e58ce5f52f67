#include "gaia/world/guidance.h"

#include <cmath>

#include "gaia/core/error.h"

namespace gaia::world {

double GuidanceSchedule::at(int frame, int token, int n) const {
  double s = scale;
  if (tokens == Tokens::Linear && n > 1) s *= 1.0 - double(token) / double(n - 1);
  if (frames == Frames::Cosine && frame >= plateau) {
    const int span = std::max(1, total_frames - plateau - 1);
    const double u = std::min(1.0, double(frame - plateau) / span);
    s *= 0.5 * (1.0 + std::cos(M_PI * u));
  }
  return s;
}

GuidanceSchedule::Tokens parse_token_schedule(const std::string& s) {
  if (s == "constant") return GuidanceSchedule::Tokens::Constant;
  if (s == "linear") return GuidanceSchedule::Tokens::Linear;
  fail("unknown token guidance schedule '{}' (choose constant or linear)", s);
}

GuidanceSchedule::Frames parse_frame_schedule(const std::string& s) {
  if (s == "constant") return GuidanceSchedule::Frames::Constant;
  if (s == "cosine") return GuidanceSchedule::Frames::Cosine;
  fail("unknown frame guidance schedule '{}' (choose constant or cosine)", s);
}

}  // namespace gaia::world
