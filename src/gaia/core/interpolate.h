#pragma once
// Weight-space interpolation between two trainings of one model (WiSE-FT, Wortsman et al. 2022: "Robust
// fine-tuning of zero-shot models"). A fine-tune that teaches one skill can cost another; the straight line between
// the weights before and after often keeps most of both, because both ends share one initialisation.
#include "gaia/core/fs.h"

namespace gaia {

// Writes base + alpha * (tuned - base) for every float tensor (computed in float32, stored as F32), `tuned`'s other
// tensors unchanged and its metadata. alpha = 0 gives base's values, 1 tuned's. Both files must hold the same tensor
// names and shapes; errors name the file and the tensor. Written atomically; `out` may be either input.
void interpolate_weights(const fs::path& base, const fs::path& tuned, double alpha, const fs::path& out);

}  // namespace gaia
