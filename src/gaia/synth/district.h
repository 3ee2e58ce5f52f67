#pragma once
// A virtual map of districts around London (lat 51.5, lon -0.1). Each district has its own weather climate
// and road mix, so episode metadata (lat/lon, weather) is meaningful for balancing and geofenced splits.
#include <array>
#include <string>
#include <vector>

namespace gaia::synth {

struct District {
  std::string name;
  double lat, lon, radius_deg;          // episodes are placed uniformly in a disc around the centre
  std::array<double, 5> weather_p;      // clear, overcast, rain, fog, snow
  std::array<double, 3> time_p;         // day, dusk, night
  int min_lanes, max_lanes;             // lanes in the ego's direction
  double bendiness;                     // 0 = straight grid, 1 = winding country road
  double building_density, tree_density, hedge_p;
  double lamp_p;                        // probability that a block has street lamps
  double parking_p;                     // probability of a parking strip with parked cars
  double traffic;                       // vehicles per 100 m (each direction)
  double light_spacing;                 // mean metres between traffic lights (0 = none)
  double bump_p;                        // speed bumps per 100 m
  double speed_min, speed_max;          // cruise speed range, m/s
  double building_h_min, building_h_max;
};

const std::vector<District>& districts();
const District& district_by_name(const std::string& name);  // throws gaia::Error for an unknown name

extern const std::array<const char*, 5> kWeathers;     // clear, overcast, rain, fog, snow
extern const std::array<const char*, 3> kTimesOfDay;   // day, dusk, night
int weather_index(const std::string& w);                // -1 if unknown
int time_index(const std::string& t);                   // -1 if unknown

}  // namespace gaia::synth
