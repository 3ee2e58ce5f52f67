#include "gaia/synth/caption.h"

#include <cmath>
#include <map>

#include "gaia/synth/rng.h"

namespace gaia::synth {

namespace {

using nlohmann::json;

template <typename T>
const T& pick(Rng& r, const std::vector<T>& v) {
  return v[static_cast<size_t>(r.integer(0, static_cast<int>(v.size()) - 1))];
}

std::string str(const json& j, const char* key, const std::string& def = "") {
  auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : def;
}
double num(const json& j, const char* key, double def = 0) {
  auto it = j.find(key);
  return it != j.end() && it->is_number() ? it->get<double>() : def;
}

std::string article(const std::string& noun) {
  return (!noun.empty() && std::string("aeiou").find(noun[0]) != std::string::npos ? "an " : "a ") + noun;
}

std::string conditions(Rng& r, const std::string& w, const std::string& t) {
  static const std::map<std::string, std::vector<std::string>> w_noun = {
      {"clear", {"clear weather", "clear skies"}},   {"overcast", {"overcast skies", "cloudy weather", "grey, overcast weather"}},
      {"rain", {"heavy rain", "the rain", "light rain", "pouring rain"}}, {"fog", {"thick fog", "fog", "dense fog"}},
      {"snow", {"falling snow", "snow", "light snow"}}};
  static const std::map<std::string, std::vector<std::string>> w_adj = {
      {"clear", {"clear"}}, {"overcast", {"overcast", "cloudy"}}, {"rain", {"rainy", "wet and rainy"}},
      {"fog", {"foggy"}},   {"snow", {"snowy"}}};
  static const std::map<std::string, std::vector<std::string>> t_noun = {
      {"day", {"day", "daytime"}}, {"dusk", {"dusk", "evening at dusk"}}, {"night", {"night", "night-time"}}};
  static const std::map<std::string, std::vector<std::string>> t_when = {
      {"day", {"during the day", "in daylight"}}, {"dusk", {"at dusk"}}, {"night", {"at night", "late at night"}}};
  const std::string wn = w_noun.count(w) ? pick(r, w_noun.at(w)) : w;
  const std::string wa = w_adj.count(w) ? pick(r, w_adj.at(w)) : w;
  const std::string tn = t_noun.count(t) ? pick(r, t_noun.at(t)) : t;
  const std::string tw = t_when.count(t) ? pick(r, t_when.at(t)) : t;
  if (w == "clear" && t == "day" && r.chance(0.4)) return pick(r, std::vector<std::string>{"sunny day", "bright sunny daytime"});
  switch (r.integer(0, 3)) {
    case 0: return tn + ", " + wn;
    case 1: return wa + " " + tn;
    case 2: return "driving " + tw + " in " + wn;
    default: return wn + " " + tw;
  }
}

}  // namespace

std::string conditions_caption(const std::string& weather, const std::string& time_of_day, uint64_t key) {
  Rng r(key);
  return conditions(r, weather, time_of_day);
}

const std::vector<std::string>& weather_words(const std::string& weather) {
  static const std::map<std::string, std::vector<std::string>> m = {{"clear", {"clear", "sunny"}},
                                                                     {"overcast", {"overcast", "cloudy"}},
                                                                     {"rain", {"rain"}},
                                                                     {"fog", {"fog"}},
                                                                     {"snow", {"snow"}}};
  static const std::vector<std::string> none;
  auto it = m.find(weather);
  return it == m.end() ? none : it->second;
}

const std::vector<std::string>& time_words(const std::string& time_of_day) {
  static const std::map<std::string, std::vector<std::string>> m = {
      {"day", {"day"}}, {"dusk", {"dusk"}}, {"night", {"night"}}};
  static const std::vector<std::string> none;
  auto it = m.find(time_of_day);
  return it == m.end() ? none : it->second;
}

std::string make_caption(const json& j, uint64_t key) {
  Rng r(key);
  std::vector<std::string> clauses;
  const double speed = num(j, "speed"), accel = num(j, "accel");
  const std::string light = str(j, "light_state", "none");
  // Traffic light.
  if (light == "red")
    clauses.push_back(speed < 0.3 ? pick(r, std::vector<std::string>{"waiting at a red light", "stopped at a red light"})
                                  : pick(r, std::vector<std::string>{"red light ahead", "approaching a red light", "red traffic light ahead"}));
  else if (light == "amber")
    clauses.push_back(pick(r, std::vector<std::string>{"amber light ahead", "lights turning amber"}));
  else if (light == "green" && r.chance(0.7))
    clauses.push_back(pick(r, std::vector<std::string>{"green light ahead", "lights on green"}));
  // Lead vehicle.
  const auto lead = j.find("lead_distance_m");
  if (lead != j.end() && lead->is_number() && lead->get<double>() < 45) {
    const std::string type = str(j, "lead_type", "car");
    const bool close = j.value("lead_close", false);
    if (accel < -1.0 && speed > 0.3)
      clauses.push_back(pick(r, std::vector<std::string>{"slowing behind ", "braking behind "}) + article(type));
    else if (close)
      clauses.push_back(pick(r, std::vector<std::string>{"close behind ", "right behind "}) + article(type));
    else
      clauses.push_back(pick(r, std::vector<std::string>{"following ", "behind "}) + article(type));
  }
  if (num(j, "pedestrians_crossing") > 0)
    clauses.push_back(pick(r, std::vector<std::string>{"pedestrians crossing ahead", "people on the crossing"}));
  // Ego motion.
  const int lane = static_cast<int>(num(j, "ego_lane")), target = static_cast<int>(num(j, "target_lane", lane));
  if (target != lane && lane >= 0)
    clauses.push_back(std::string("changing lanes to the ") + (target < lane ? "left" : "right"));
  if (!(light == "red" && speed < 0.3)) {
    if (speed < 0.3)
      clauses.push_back(pick(r, std::vector<std::string>{"stopped", "stationary", "standing still"}));
    else if (accel < -1.0 && clauses.size() < 2)
      clauses.push_back(pick(r, std::vector<std::string>{"braking", "slowing down"}));
    else if (accel > 0.6)
      clauses.push_back(pick(r, std::vector<std::string>{"accelerating", "speeding up"}));
    else if (r.chance(0.6)) {
      const int kmh = static_cast<int>(std::lround(speed * 3.6 / 5) * 5);
      const int mph = static_cast<int>(std::lround(speed * 2.237 / 5) * 5);
      clauses.push_back(r.chance(0.5) ? "cruising at about " + std::to_string(kmh) + " km/h"
                                      : "driving at around " + std::to_string(mph) + " mph");
    }
  }
  const std::string road = str(j, "road_ahead", "straight");
  if (road != "straight" && clauses.size() < 4)
    clauses.push_back(road == "left_bend" ? pick(r, std::vector<std::string>{"approaching a left bend", "road curving to the left"})
                                          : pick(r, std::vector<std::string>{"approaching a right bend", "road curving to the right"}));
  else if (clauses.size() < 2 && r.chance(0.5))
    clauses.push_back(pick(r, std::vector<std::string>{"on a straight road", "straight road ahead"}));
  if (j.value("oncoming_close", false) && clauses.size() < 4 && r.chance(0.5))
    clauses.push_back("oncoming " + str(j, "oncoming_type", "car"));
  if (j.value("speed_bump_ahead", false) && clauses.size() < 4) clauses.push_back("speed bump ahead");
  // The conditions phrase (weather and time of day) always comes first.
  std::string out = conditions(r, str(j, "weather"), str(j, "time_of_day"));
  for (size_t i = 0; i < clauses.size(); ++i)
    out += (i + 1 == clauses.size() && clauses.size() > 1 && r.chance(0.3) ? " and " : ", ") + clauses[i];
  return out;
}

}  // namespace gaia::synth
