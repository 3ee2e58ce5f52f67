#pragma once
// Driving signals from a CSV with header `time_s,speed,curvature[,caption]` (speed m/s, curvature 1/m,
// positive = turning left). Values are linearly interpolated to frame times; outside the recorded span they are
// missing (NaN), never extrapolated and never zero-filled. Empty cells are missing too.
#include <string>
#include <vector>

#include "gaia/core/fs.h"

namespace gaia::data {

struct Signals {
  std::vector<double> time_s, speed, curvature;  // NaN where a cell was empty
  std::vector<std::string> caption;              // empty when the CSV has no caption column
  bool has_caption = false;

  // Interpolated values at time t. Caption: the latest caption at or before t.
  double speed_at(double t) const;
  double curvature_at(double t) const;
  std::string caption_at(double t) const;
};

Signals read_signals_csv(const fs::path& csv);  // errors name file:line and the column

// Splits one CSV line (RFC 4180 quoting: "a, b" and "" escapes).
std::vector<std::string> split_csv_line(const std::string& line);

}  // namespace gaia::data
