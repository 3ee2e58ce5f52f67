// Fuzz target: GPS tracks. The same bytes are read as an NMEA log and as a GPX file, and each track that parses is
// turned into signals. Contract: only gaia::Error may escape; a track's fixes are in strictly increasing time and
// its signals are finite or NaN, never infinite.
#include <cmath>
#include <cstdint>

#include "fuzz_util.h"
#include "gaia/core/error.h"
#include "gaia/data/gps.h"

namespace {

void check(const gaia::data::GpsTrack& t) {
  for (size_t i = 1; i < t.fixes.size(); ++i)
    if (!(t.fixes[i].t_s > t.fixes[i - 1].t_s)) gaia_fuzz::property_failed("gps fixes", "time does not increase");
  const auto s = gaia::data::track_signals(t, t.fixes.front().t_s);
  for (size_t i = 0; i < s.time_s.size(); ++i)
    if (std::isinf(s.speed[i]) || std::isinf(s.curvature[i]) || !std::isfinite(s.time_s[i]))
      gaia_fuzz::property_failed("gps signals", "an infinite value");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static gaia_fuzz::TempFile nmea("track.nmea"), gpx("track.gpx");
  try {
    check(gaia::data::read_gps_track(nmea.write(data, size)));
  } catch (const gaia::Error&) {
  }
  try {
    check(gaia::data::read_gps_track(gpx.write(data, size)));
  } catch (const gaia::Error&) {
  }
  return 0;
}
