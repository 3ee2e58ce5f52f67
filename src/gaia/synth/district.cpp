#include "gaia/synth/district.h"

#include "gaia/core/error.h"

namespace gaia::synth {

const std::array<const char*, 5> kWeathers = {"clear", "overcast", "rain", "fog", "snow"};
const std::array<const char*, 3> kTimesOfDay = {"day", "dusk", "night"};

int weather_index(const std::string& w) {
  for (size_t i = 0; i < kWeathers.size(); ++i)
    if (w == kWeathers[i]) return static_cast<int>(i);
  return -1;
}

int time_index(const std::string& t) {
  for (size_t i = 0; i < kTimesOfDay.size(); ++i)
    if (t == kTimesOfDay[i]) return static_cast<int>(i);
  return -1;
}

const std::vector<District>& districts() {
  // name, lat, lon, radius, weather(clear, overcast, rain, fog, snow), time(day, dusk, night), lanes,
  // bendiness, buildings, trees, hedges, lamps, parking, traffic, light spacing, bumps, speed, building height
  static const std::vector<District> d = {
      {"city", 51.515, -0.092, 0.012, {0.30, 0.35, 0.30, 0.03, 0.02}, {0.55, 0.2, 0.25}, 1, 2, 0.05, 1.0, 0.1, 0.0,
       1.0, 0.5, 2.0, 160, 0.00, 8, 12, 12, 30},
      {"camden", 51.541, -0.143, 0.015, {0.30, 0.30, 0.32, 0.05, 0.03}, {0.5, 0.25, 0.25}, 1, 1, 0.15, 0.8, 0.4, 0.0,
       1.0, 0.8, 1.4, 260, 0.35, 7, 11, 7, 14},
      {"canary_wharf", 51.505, -0.020, 0.010, {0.40, 0.30, 0.22, 0.06, 0.02}, {0.5, 0.25, 0.25}, 2, 3, 0.10, 0.9, 0.3,
       0.0, 1.0, 0.0, 2.2, 300, 0.00, 10, 15, 25, 60},
      {"richmond", 51.461, -0.303, 0.020, {0.45, 0.25, 0.20, 0.07, 0.03}, {0.6, 0.25, 0.15}, 1, 1, 0.30, 0.35, 1.0,
       0.3, 0.9, 0.6, 0.9, 450, 0.25, 8, 12, 6, 11},
      {"greenwich", 51.482, 0.000, 0.015, {0.38, 0.30, 0.24, 0.05, 0.03}, {0.55, 0.25, 0.2}, 1, 2, 0.25, 0.5, 0.6,
       0.2, 0.9, 0.4, 1.2, 350, 0.15, 9, 13, 7, 16},
      {"epping", 51.660, 0.100, 0.040, {0.30, 0.30, 0.15, 0.18, 0.07}, {0.5, 0.25, 0.25}, 1, 1, 0.75, 0.0, 1.0, 0.8,
       0.0, 0.0, 0.6, 0, 0.00, 13, 19, 5, 8},
  };
  return d;
}

const District& district_by_name(const std::string& name) {
  for (auto& d : districts())
    if (d.name == name) return d;
  std::string known;
  for (auto& d : districts()) known += (known.empty() ? "" : ", ") + d.name;
  fail("unknown synth district '{}' (known: {})", name, known);
}

}  // namespace gaia::synth
