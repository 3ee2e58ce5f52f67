// Fuzz target: read_signals_csv on arbitrary bytes, then interpolation and captions at and between the rows.
// Contract: only gaia::Error may escape the parser; a crash, sanitizer report or other exception is a bug.
#include <cmath>
#include <cstdint>

#include "fuzz_util.h"
#include "gaia/core/error.h"
#include "gaia/data/signals.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static gaia_fuzz::TempFile in("signals.csv");
  try {
    const gaia::data::Signals s = gaia::data::read_signals_csv(in.write(data, size));
    const size_t n = s.time_s.size();
    if (s.speed.size() != n || s.curvature.size() != n || (s.has_caption && s.caption.size() != n))
      gaia_fuzz::property_failed("signals columns", "lengths differ");
    volatile double sink = 0;
    // Bounded: a long file is checked at its first rows, their midpoints and just outside the span.
    for (size_t i = 0; i < n && i < 64; ++i) {
      const double t = s.time_s[i], next = i + 1 < n ? s.time_s[i + 1] : t + 1;
      for (double x : {t, 0.5 * (t + next), t - 1, next}) {
        sink = sink + s.speed_at(x) + s.curvature_at(x) + static_cast<double>(s.caption_at(x).size());
      }
    }
    sink = sink + s.speed_at(NAN) + s.curvature_at(INFINITY) + static_cast<double>(s.caption_at(-INFINITY).size());
  } catch (const gaia::Error&) {
  }
  return 0;
}
