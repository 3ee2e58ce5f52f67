#pragma once
// GPS tracks as driving signals (docs/formats.md, "GPS tracks"): NMEA 0183 logs (RMC and GGA sentences, as most
// dashcams write them) and GPX files. Speed and curvature come from successive fixes: positions on a local plane,
// heading change per metre of path.
//   read_gps_track   .nmea/.txt/.log (NMEA) or .gpx; fixes in time order, UTC seconds
//   track_signals    speed (m/s) and curvature (1/m, + = left) at each fix, on the video's clock
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "gaia/core/fs.h"
#include "gaia/data/signals.h"

namespace gaia::data {

struct GpsFix {
  double t_s = 0;  // seconds since 1970-01-01 UTC (NMEA GGA alone, without a date: since midnight)
  double lat = 0, lon = 0;  // degrees
  double speed = std::numeric_limits<double>::quiet_NaN();  // m/s as the receiver reported it; NaN = none
};

struct GpsTrack {
  std::vector<GpsFix> fixes;   // strictly increasing t_s
  int64_t skipped_lines = 0;   // NMEA sentences with a bad checksum, no fix or unreadable fields
};

// By extension: .gpx is GPX, anything else NMEA. Fails naming the file when it holds fewer than two fixes.
GpsTrack read_gps_track(const fs::path& file);
GpsTrack read_nmea(const fs::path& file);
GpsTrack read_gpx(const fs::path& file);

// Heading changes are taken over chords of at least this much path on each side of a fix, so receiver noise of a
// metre or two does not read as steering.
inline constexpr double kGpsChordMetres = 5.0;

// Signals at the fixes' times minus `t0` (the track time of video time 0). Speed: the receiver's, else path length
// over time; curvature: NaN where the car moved less than a chord within kGpsMaxChordSeconds on either side.
inline constexpr double kGpsMaxChordSeconds = 5.0;
Signals track_signals(const GpsTrack& track, double t0);

// Metres between two fixes (haversine).
double gps_distance(double lat1, double lon1, double lat2, double lon2);

}  // namespace gaia::data
