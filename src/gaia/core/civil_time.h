#pragma once
// Calendar dates as day counts, for the timestamps of GPS tracks and KITTI drives (UTC, no leap seconds).
#include <cstdint>

namespace gaia {

// Days from 1970-01-01 to year-month-day in the proleptic Gregorian calendar (era-based: 400-year cycles).
constexpr int64_t days_from_civil(int64_t y, int64_t m, int64_t d) {
  y -= m <= 2;
  const int64_t era = (y >= 0 ? y : y - 399) / 400;
  const int64_t yoe = y - era * 400;
  const int64_t doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const int64_t doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + doe - 719468;
}
static_assert(days_from_civil(1970, 1, 1) == 0 && days_from_civil(2000, 3, 1) == 11017);

// Seconds since 1970-01-01 00:00 UTC.
constexpr double utc_seconds(int64_t y, int64_t mo, int64_t d, int64_t h, int64_t mi, double s) {
  return double(days_from_civil(y, mo, d)) * 86400 + double(h * 3600 + mi * 60) + s;
}

}  // namespace gaia
