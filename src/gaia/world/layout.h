#pragma once
// The world model's sequence (§2.1, §2.3): per time step t, m text tokens c_t, n image tokens z_t and l action
// tokens a_t, in that order; T steps per context. Positions are factorised: a temporal index t (shared by all
// tokens of a step) and a spatial slot s in [0, m + n + l).
//
//   step t:  [ c_t,1 .. c_t,m | z_t,1 .. z_t,n | a_t,1 .. a_t,l ]      flat index = t * S + slot,  S = m + n + l
//
// The output at flat position p predicts the token at p + 1, so image token z_t,i is predicted by the output at
// t * S + m + i - 1 (for i = 0 that is the last text token: the text of a step is seen before its image).
#include <cstdint>

namespace gaia::world {

struct SequenceLayout {
  int64_t m = 0, n = 0, l = 2, T = 1;  // text, image, action tokens per step; steps per context

  int64_t per_step() const { return m + n + l; }                                 // S
  int64_t length() const { return T * per_step(); }                              // paper: 26 x (32+576+2) = 15860
  int64_t image_slot(int64_t i) const { return m + i; }                          // spatial slot of z_i
  int64_t action_slot(int64_t j) const { return m + n + j; }
  int64_t flat(int64_t t, int64_t slot) const { return t * per_step() + slot; }
  int64_t predictor(int64_t t, int64_t i) const { return flat(t, image_slot(i)) - 1; }  // output that predicts z_t,i
};

}  // namespace gaia::world
