#pragma once
// Driving signals from a CSV with header `time_s,speed,curvature[,caption]` (docs/formats.md, "Signals CSV").
//   time_s     seconds, finite, strictly increasing row to row
//   speed      m/s in [0, 100] (reversing is not modelled)
//   curvature  1/m in [-1, 1], positive = turning left (|1/m| above 1 would be a turn radius under a metre)
// Numbers are plain decimal with an optional exponent (`12`, `-0.5`, `3e-2`); hex, inf and nan are errors, as is
// any value outside its range. An empty speed or curvature cell is missing.
// Values are linearly interpolated to frame times between two neighbouring rows. Missing stays missing: where
// either neighbour is missing, and outside the recorded span, the value is NaN; it is never bridged across a gap,
// extrapolated or zero-filled.
#include <string>
#include <vector>

#include "gaia/core/fs.h"

namespace gaia::data {

inline constexpr double kMaxSpeed = 100.0;     // m/s
inline constexpr double kMaxCurvature = 1.0;   // 1/m, either sign

struct Signals {
  std::vector<double> time_s, speed, curvature;  // NaN where a cell was empty
  std::vector<std::string> caption;              // empty when the CSV has no caption column
  bool has_caption = false;

  // Interpolated values at time t (NaN in a gap or outside the span). Caption: the latest caption at or before t.
  double speed_at(double t) const;
  double curvature_at(double t) const;
  std::string caption_at(double t) const;
};

Signals read_signals_csv(const fs::path& csv);  // errors name file:line and the column

// Splits one CSV line (RFC 4180 quoting: "a, b" and "" escapes). A quoted cell must close on the same line;
// otherwise this fails naming `where` (e.g. "file.csv:7").
std::vector<std::string> split_csv_line(const std::string& line, const std::string& where = "CSV line");

}  // namespace gaia::data
