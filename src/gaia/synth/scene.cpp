#include "gaia/synth/scene.h"

#include <algorithm>
#include <cmath>

#include "gaia/core/error.h"
#include "gaia/synth/rng.h"

namespace gaia::synth {

namespace {

constexpr double kEgoStart = 60.0;   // ego's initial arc length (road behind it is drawn too)
constexpr double kEgoFront = 2.0;    // camera to front bumper
constexpr double kEgoHalfLen = 2.3;

const std::vector<std::string> kScenes = {"random", "bend", "red_light", "lead_vehicle", "straight"};

cv::Vec3b bgr(int r, int g, int b) { return cv::Vec3b(uchar(b), uchar(g), uchar(r)); }

cv::Vec3b car_colour(Rng& r) {
  static const std::vector<cv::Vec3b> pal = {bgr(200, 200, 205), bgr(235, 235, 235), bgr(25, 25, 30),
                                             bgr(40, 55, 110),   bgr(150, 25, 25),   bgr(90, 92, 98),
                                             bgr(60, 100, 170),  bgr(50, 80, 60),    bgr(170, 150, 110),
                                             bgr(120, 20, 40)};
  static const std::vector<double> w = {3, 3, 3, 1.5, 1.2, 3, 1, 0.6, 0.6, 0.6};
  return pal[static_cast<size_t>(r.weighted(w))];
}

}  // namespace

const char* vehicle_name(VehicleKind k) {
  switch (k) {
    case VehicleKind::Car: return "car";
    case VehicleKind::Van: return "van";
    case VehicleKind::Bus: return "bus";
    case VehicleKind::Truck: return "truck";
  }
  return "car";
}

const char* light_state_name(int state) { return state == 0 ? "green" : state == 1 ? "amber" : "red"; }

int TrafficLight::state(double t) const {
  double c = std::fmod(t + offset, cycle());
  if (c < 0) c += cycle();
  return c < green ? 0 : c < green + amber ? 1 : 2;
}

namespace {

// The change part of resolve_spec: checks change_at and change_lead, draws "random" targets (the rest resolved).
SceneSpec resolve_change(SceneSpec spec) {
  const bool asked = !spec.change_weather.empty() || !spec.change_time_of_day.empty();
  if (spec.change_at == 0) {
    if (asked) fail("synth: a change of weather or time of day needs its time (--change-at)");
    return spec;
  }
  if (!(spec.change_at > 0 && spec.change_at < spec.seconds))
    fail("synth: --change-at must be within the drive's (0, {}) s, got {}", spec.seconds, spec.change_at);
  if (!(spec.change_lead >= 0 && spec.change_lead <= spec.change_at))
    fail("synth: --change-lead must be in [0, --change-at = {}] s, got {}", spec.change_at, spec.change_lead);
  if (!asked) fail("synth: --change-at {} s changes nothing: give --change-weather or --change-time", spec.change_at);
  Rng r(stream_key(spec.seed, static_cast<uint64_t>(spec.index), "change"));
  auto other = [&](const auto& values, const std::string& own) {  // uniform over the values other than `own`
    std::vector<std::string> rest;
    for (const char* v : values)
      if (own != v) rest.push_back(v);
    return rest[static_cast<size_t>(r.integer(0, static_cast<int>(rest.size()) - 1))];
  };
  if (spec.change_weather == "random") spec.change_weather = other(kWeathers, spec.weather);
  if (spec.change_time_of_day == "random") spec.change_time_of_day = other(kTimesOfDay, spec.time_of_day);
  if (!spec.change_weather.empty() && weather_index(spec.change_weather) < 0)
    fail("synth: unknown --change-weather '{}' (clear, overcast, rain, fog, snow, random)", spec.change_weather);
  if (!spec.change_time_of_day.empty() && time_index(spec.change_time_of_day) < 0)
    fail("synth: unknown --change-time '{}' (day, dusk, night, random)", spec.change_time_of_day);
  return spec;
}

}  // namespace

SceneSpec resolve_spec(SceneSpec spec) {
  if (!(spec.fps > 0 && spec.fps <= 1000)) fail("synth: fps must be in (0, 1000], got {}", spec.fps);
  if (!(spec.seconds > 0 && spec.seconds <= 3600)) fail("synth: seconds must be in (0, 3600], got {}", spec.seconds);
  if (spec.index < 0) fail("synth: episode index must be >= 0, got {}", spec.index);
  if (!(spec.wander >= 0 && spec.wander <= 3)) fail("synth: wander must be in [0, 3] m, got {}", spec.wander);
  if (!(spec.swerve >= 0 && spec.swerve <= 0.1)) fail("synth: swerve must be in [0, 0.1] 1/m, got {}", spec.swerve);
  Rng r(stream_key(spec.seed, static_cast<uint64_t>(spec.index), "spec"));
  const double u_district = r.uniform(), u_scene = r.uniform(), u_w = r.uniform(), u_t = r.uniform();
  if (spec.district.empty()) {
    const auto& ds = districts();
    spec.district = ds[std::min(ds.size() - 1, static_cast<size_t>(u_district * static_cast<double>(ds.size())))].name;
  }
  const District& d = district_by_name(spec.district);
  if (spec.scene.empty()) {
    // Mostly free driving; some episodes start in a set-piece scene.
    spec.scene = u_scene < 0.55 ? "random" : u_scene < 0.70 ? "bend" : u_scene < 0.85 ? "red_light" : "lead_vehicle";
    if (spec.scene == "red_light" && d.light_spacing <= 0) spec.scene = "lead_vehicle";
  }
  if (std::find(kScenes.begin(), kScenes.end(), spec.scene) == kScenes.end())
    fail("synth: unknown scene '{}' (random, bend, red_light, lead_vehicle, straight)", spec.scene);
  auto pick = [](const auto& probs, double u) {
    double acc = 0;
    for (size_t i = 0; i < probs.size(); ++i) {
      acc += probs[i];
      if (u < acc) return i;
    }
    return probs.size() - 1;
  };
  if (spec.weather.empty()) spec.weather = kWeathers[pick(d.weather_p, u_w)];
  if (spec.time_of_day.empty()) spec.time_of_day = kTimesOfDay[pick(d.time_p, u_t)];
  if (weather_index(spec.weather) < 0)
    fail("synth: unknown weather '{}' (clear, overcast, rain, fog, snow)", spec.weather);
  if (time_index(spec.time_of_day) < 0) fail("synth: unknown time of day '{}' (day, dusk, night)", spec.time_of_day);
  return resolve_change(spec);
}


Scene::Scene(const SceneSpec& s)
    : spec_(s),
      district_(&district_by_name(s.district)),
      road_(stream_key(s.seed, static_cast<uint64_t>(s.index), "road"), *district_, s.scene) {
  Rng r(stream_key(s.seed, static_cast<uint64_t>(s.index), "layout"));
  const District& D = *district_;
  layout_.lanes_fwd = r.integer(D.min_lanes, D.max_lanes);
  layout_.lanes_onc = layout_.lanes_fwd > 1 && r.chance(0.3) ? layout_.lanes_fwd - 1 : layout_.lanes_fwd;
  layout_.lane_w = D.bendiness > 0.5 ? r.uniform(3.1, 3.4) : r.uniform(3.3, 3.7);
  const bool parking = r.chance(D.parking_p);
  layout_.parking_fwd = parking ? 2.3 : 0;
  layout_.parking_onc = parking && r.chance(0.7) ? 2.3 : 0;
  layout_.kerbs = D.building_density > 0.05 || D.lamp_p > 0.5;
  layout_.pavement_w = layout_.kerbs ? r.uniform(2.5, 4.5) : r.uniform(1.0, 2.5);
  layout_.centre_solid = r.chance(D.bendiness > 0.5 ? 0.3 : 0.1);
  layout_.edge_style = !layout_.kerbs ? 1 : (!parking && r.chance(0.5)) ? 2 : (r.chance(0.4) ? 1 : 0);
  agent_range_ = kEgoStart + 25 * spec_.seconds + 300;
  road_.ensure(agent_range_ + 400);
  spawn();
}

void Scene::spawn() {
  const uint64_t seed = spec_.seed, idx = static_cast<uint64_t>(spec_.index);
  const District& D = *district_;
  const RoadLayout& L = layout_;
  Rng r(stream_key(seed, idx, "ego"));
  // Ego.
  ego_.target_lane = r.integer(0, L.lanes_fwd - 1);
  ego_.s = kEgoStart;
  ego_.d = ego_.d_ref = L.lane_centre(ego_.target_lane);
  road_.point(ego_.s, ego_.d, ego_.x, ego_.y);
  ego_.h = road_.at(ego_.s).h;
  ego_.v_des = r.uniform(D.speed_min, D.speed_max);
  ego_.next_vdes_t = r.uniform(3, 8);
  ego_.next_lc_t = r.uniform(2, 8);
  if (spec_.scene == "red_light") ego_.v_des = D.speed_min * 0.9;
  ego_.v = ego_.v_des * (spec_.scene == "random" ? r.uniform(0.6, 1.0) : 0.95);
  ego_.k = road_.at(ego_.s).k;

  // Traffic lights (with pedestrian crossings) and speed bumps.
  Rng rl(stream_key(seed, idx, "lights"));
  if (spec_.scene == "red_light" || D.light_spacing > 0) {
    // The red-light scene's light turns amber 0.8 s in, far enough ahead for a comfortable stop.
    const double v = ego_.v;
    double s = spec_.scene == "red_light" ? kEgoStart + std::max(35.0, 0.8 * v + v * v / 4.4 + 8) + rl.uniform(0, 5)
                                          : kEgoStart + rl.uniform(40, std::max(60.0, D.light_spacing));
    const double road_w = L.left_edge() - L.right_edge();
    for (int i = 0; s < agent_range_; ++i) {
      TrafficLight l;
      l.s = s;
      l.crossing = spec_.scene == "red_light" || rl.chance(0.75);
      l.green = rl.uniform(7, 13);
      l.amber = 3;
      l.red = std::max(rl.uniform(10, 18), (road_w + 2) / 1.2 + 5);
      l.offset = rl.uniform(0, l.cycle());
      if (i == 0 && spec_.scene == "red_light") {
        l.offset = l.green - 0.8;  // turns amber 0.8 s into the episode
        l.red = std::max(l.red, 14.0);
      }
      lights_.push_back(l);
      const int nped = l.crossing ? rl.integer(spec_.scene == "red_light" && i == 0 ? 2 : 0, 4) : 0;
      for (int p = 0; p < nped; ++p) {
        Pedestrian pd;
        pd.light = static_cast<int>(lights_.size()) - 1;
        pd.s0 = rl.uniform(1.2, 3.6);
        pd.speed = rl.uniform(1.2, 1.6);
        pd.delay = rl.uniform(0.5, 3.0);
        pd.first_dir = rl.chance(0.5) ? 1 : -1;
        static const std::vector<cv::Vec3b> tops = {bgr(30, 30, 35), bgr(150, 30, 30), bgr(40, 60, 120),
                                                    bgr(200, 200, 190), bgr(90, 110, 60), bgr(200, 140, 40)};
        pd.top = tops[static_cast<size_t>(rl.integer(0, static_cast<int>(tops.size()) - 1))];
        pd.legs = rl.chance(0.6) ? bgr(35, 40, 60) : bgr(30, 30, 30);
        peds_.push_back(pd);
      }
      if (D.light_spacing <= 0) break;  // only the scene's light in a district without signals
      s += D.light_spacing * rl.uniform(0.6, 1.4) + 40;
    }
  }
  Rng rb(stream_key(seed, idx, "bumps"));
  if (D.bump_p > 0) {
    for (double s = kEgoStart + 30; s < agent_range_; s += rb.uniform(30, 200) / D.bump_p * 0.35) {
      bool near_light = spec_.scene == "red_light" && !lights_.empty() && s < lights_[0].s + 10;
      for (auto& l : lights_) near_light |= std::abs(l.s - s) < 30;
      if (!near_light) bumps_.push_back(s);
    }
  }
  // Pavement walkers.
  Rng rw(stream_key(seed, idx, "walkers"));
  if (L.kerbs) {
    const int n = static_cast<int>(agent_range_ / 100.0 * D.building_density * 3);
    for (int i = 0; i < n; ++i) {
      Pedestrian pd;
      pd.light = -1;
      pd.s0 = rw.uniform(kEgoStart, agent_range_);
      const bool left = rw.chance(0.5);
      pd.d0 = left ? L.left_edge() + rw.uniform(0.6, L.pavement_w - 0.4) : L.right_edge() - rw.uniform(0.6, L.pavement_w - 0.4);
      pd.speed = rw.uniform(0.9, 1.5) * (rw.chance(0.5) ? 1 : -1);
      pd.delay = rw.uniform(0, 10);
      pd.top = bgr(rw.integer(20, 200), rw.integer(20, 160), rw.integer(20, 160));
      pd.legs = bgr(30, 32, 40);
      peds_.push_back(pd);
    }
  }

  // Vehicles.
  auto make_vehicle = [&](Rng& rv, bool parked) {
    Vehicle v;
    double u = rv.uniform();
    const double bus_p = D.building_density > 0.5 ? 0.10 : 0.04;
    if (parked) v.kind = u < 0.85 ? VehicleKind::Car : VehicleKind::Van;
    else v.kind = u < 0.70 ? VehicleKind::Car : u < 0.84 ? VehicleKind::Van : u < 0.84 + bus_p ? VehicleKind::Bus : VehicleKind::Truck;
    switch (v.kind) {
      case VehicleKind::Car:
        v.length = rv.uniform(4.0, 4.8), v.width = rv.uniform(1.7, 1.85), v.height = rv.uniform(1.4, 1.6);
        v.colour = car_colour(rv);
        break;
      case VehicleKind::Van:
        v.length = rv.uniform(5.0, 5.8), v.width = 2.0, v.height = rv.uniform(2.2, 2.6);
        v.colour = rv.chance(0.6) ? bgr(235, 235, 232) : car_colour(rv);
        break;
      case VehicleKind::Bus:
        v.length = rv.uniform(10.5, 11.5), v.width = 2.5;
        v.double_decker = D.building_density > 0.3 && rv.chance(0.6);
        v.height = v.double_decker ? 4.3 : 3.1;
        v.colour = rv.chance(0.8) ? bgr(200, 20, 25) : bgr(230, 230, 225);
        break;
      case VehicleKind::Truck:
        v.length = rv.uniform(9, 12), v.width = 2.5, v.height = rv.uniform(3.4, 3.9);
        v.colour = rv.chance(0.5) ? bgr(225, 225, 225) : rv.chance(0.5) ? bgr(40, 70, 140) : bgr(150, 150, 150);
        break;
    }
    v.look = static_cast<uint32_t>(rv.next());
    return v;
  };
  auto add_brakes = [&](Rng& rv, Vehicle& v) {
    for (double t = rv.uniform(2, 14); t < spec_.seconds + 60; t += rv.uniform(6, 20))
      v.brakes.push_back({t, t + rv.uniform(1.5, 3.5)});
  };
  const double lane_density = D.traffic / 100.0;
  Rng rv(stream_key(seed, idx, "vehicles"));
  if (spec_.scene == "lead_vehicle") {
    Vehicle v = make_vehicle(rv, false);
    if (rv.chance(0.5)) {
      VehicleKind ks[] = {VehicleKind::Van, VehicleKind::Bus, VehicleKind::Truck};
      VehicleKind k = ks[rv.integer(0, 2)];
      while (v.kind != k) v = make_vehicle(rv, false);
    }
    v.dir = 1;
    v.s = ego_.s + rv.uniform(16, 24) + v.length / 2;
    v.d = v.lane_d = v.d_target = ego_.d;
    v.v0 = ego_.v_des * rv.uniform(0.85, 1.0);
    v.v = ego_.v * 0.95;
    const double t0 = rv.uniform(2.5, 4.0);
    v.brakes.push_back({t0, t0 + rv.uniform(2.0, 3.0)});
    for (double t = t0 + rv.uniform(8, 14); t < spec_.seconds + 60; t += rv.uniform(8, 16))
      v.brakes.push_back({t, t + rv.uniform(1.5, 3.0)});
    vehicles_.push_back(v);
  }
  for (int lane = 0; lane < L.lanes_fwd; ++lane) {
    double s = ego_.s + rv.uniform(15, 40) + (spec_.scene == "lead_vehicle" && L.lane_centre(lane) == ego_.d ? 40 : 0);
    if (spec_.scene == "straight" || spec_.scene == "bend") s += 60;
    for (; s < agent_range_; s += rv.uniform(0.3, 1.7) / lane_density * L.lanes_fwd + 12) {
      Vehicle v = make_vehicle(rv, false);
      v.dir = 1;
      v.s = s;
      v.d = v.lane_d = v.d_target = L.lane_centre(lane);
      v.v0 = rv.uniform(D.speed_min, D.speed_max) * (v.kind == VehicleKind::Car ? 1.0 : 0.85);
      v.v = v.v0 * rv.uniform(0.7, 1.0);
      add_brakes(rv, v);
      vehicles_.push_back(v);
    }
  }
  const double onc_end = agent_range_ + 15 * spec_.seconds;
  for (int lane = 0; lane < L.lanes_onc; ++lane) {
    for (double s = ego_.s + rv.uniform(-30, 40); s < onc_end; s += rv.uniform(0.4, 1.6) / lane_density * L.lanes_onc + 15) {
      Vehicle v = make_vehicle(rv, false);
      v.dir = -1;
      v.s = s;
      v.d = v.lane_d = v.d_target = L.onc_lane_centre(lane);
      v.v0 = rv.uniform(D.speed_min, D.speed_max);
      v.v = v.v0 * rv.uniform(0.8, 1.0);
      add_brakes(rv, v);
      vehicles_.push_back(v);
    }
  }
  for (int side = 0; side < 2; ++side) {
    const double w = side == 0 ? L.parking_fwd : L.parking_onc;
    if (w <= 0) continue;
    for (double s = ego_.s - 20; s < agent_range_ + 200; s += rv.uniform(5.2, 7.0)) {
      if (!rv.chance(0.55)) {
        s += rv.uniform(0, 8);
        continue;
      }
      bool near_light = false;
      for (auto& l : lights_) near_light |= s > l.s - 25 && s < l.s + 15;
      if (near_light) continue;
      Vehicle v = make_vehicle(rv, true);
      v.dir = 0;
      v.s = s;
      v.d = v.lane_d = v.d_target = side == 0 ? L.left_edge() - w / 2 - 0.05 : L.right_edge() + w / 2 + 0.05;
      v.look |= side == 0 ? 0u : 1u;  // bit 0: parked facing the other way
      vehicles_.push_back(v);
    }
  }
}

const std::vector<Prop>& Scene::props_block(int64_t block) const {
  auto it = props_.find(block);
  if (it != props_.end()) return it->second;
  std::vector<Prop> out;
  const District& D = *district_;
  const RoadLayout& L = layout_;
  Rng r(stream_key(spec_.seed, static_cast<uint64_t>(spec_.index), "props", static_cast<uint64_t>(block + (1 << 20))));
  const double s0 = static_cast<double>(block) * kBlock, s1 = s0 + kBlock;
  auto near_light = [&](double s, double before, double after) {
    for (auto& l : lights_)
      if (s > l.s - before && s < l.s + after) return true;
    return false;
  };
  for (int side = 0; side < 2; ++side) {
    const double sgn = side == 0 ? 1 : -1;
    const double edge = side == 0 ? L.left_edge() : -L.right_edge();
    const double back = edge + L.pavement_w;
    // Street lamps at the kerb, one side offset by half a spacing.
    if (r.chance(D.lamp_p))
      for (double s = s0 + (side == 0 ? 0 : 16); s < s1; s += 32)
        out.push_back({PropKind::Lamp, s, sgn * (edge + 0.5), 0.18, 0.18, 7.0, cv::Vec3b(90, 90, 88), 0});
    // Buildings: a terrace along the block.
    if (r.chance(D.building_density)) {
      const double setback = back + (D.building_density > 0.5 ? r.uniform(0, 1.5) : r.uniform(2, 8));
      for (double s = s0; s < s1;) {
        const double w = r.uniform(7, 22);
        if (r.chance(0.85)) {
          static const std::vector<cv::Vec3b> facades = {bgr(150, 85, 65), bgr(165, 110, 80), bgr(200, 190, 170),
                                                         bgr(120, 120, 125), bgr(225, 220, 210), bgr(110, 75, 60),
                                                         bgr(170, 160, 150), bgr(95, 105, 120)};
          cv::Vec3b c = facades[static_cast<size_t>(r.integer(0, static_cast<int>(facades.size()) - 1))];
          const double h = r.uniform(D.building_h_min, D.building_h_max);
          out.push_back({PropKind::Building, s + w / 2, sgn * (setback + 5), std::min(w, s1 - s) - 0.3, 10, h, c,
                         static_cast<uint32_t>(r.next())});
        }
        s += w;
      }
    }
    // Hedges along rural verges.
    if (r.chance(D.hedge_p) && !near_light(s0 + 25, 60, 60))
      out.push_back({PropKind::Hedge, s0 + 25, sgn * (back + 1.0), kBlock, 1.2, r.uniform(1.4, 2.6),
                     bgr(r.integer(40, 60), r.integer(80, 100), r.integer(35, 50)), 0});
    // Trees.
    const int ntree = static_cast<int>(D.tree_density * r.uniform(0, 6));
    for (int i = 0; i < ntree; ++i) {
      const double s = r.uniform(s0, s1);
      const double dd = D.building_density > 0.5 ? edge + L.pavement_w * r.uniform(0.4, 0.8) : back + r.uniform(1.5, 12);
      out.push_back({PropKind::Tree, s, sgn * dd, r.uniform(2.0, 3.6), 0.35, r.uniform(5, 11),
                     bgr(r.integer(45, 75), r.integer(85, 120), r.integer(35, 55)), static_cast<uint32_t>(r.next())});
    }
    // Occasional signs.
    if (r.chance(0.3)) {
      const double s = r.uniform(s0, s1);
      if (!near_light(s, 10, 10))
        out.push_back({PropKind::Sign, s, sgn * (edge + 0.7), 0.75, 0.08, 2.6, cv::Vec3b(0, 0, 0),
                       static_cast<uint32_t>(r.next())});
    }
  }
  return props_.emplace(block, std::move(out)).first->second;
}

PedPose Scene::pedestrian_pose(const Pedestrian& p, double t) const {
  PedPose q{};
  if (p.light < 0) {  // pavement walker
    q.s = p.s0 + p.speed * (t + p.delay);
    q.d = p.d0;
    q.heading = p.speed > 0 ? 0 : kPi;
    q.walking = true;
    q.on_road = false;
    return q;
  }
  const TrafficLight& l = lights_[static_cast<size_t>(p.light)];
  const double from = layout_.right_edge() - 1.0, to = layout_.left_edge() + 1.0, width = to - from;
  // Cycle index k counts red phases; pedestrians cross during red, alternating direction.
  const double red_start = l.green + l.amber;  // within the cycle
  double tc = t + l.offset - red_start;
  const double k = std::floor(tc / l.cycle());
  const double tau = tc - k * l.cycle();  // time since the last red onset
  const int dir = (static_cast<int64_t>(k) % 2 == 0) ? p.first_dir : -p.first_dir;
  const double walked = std::clamp((tau - p.delay) * p.speed, 0.0, width);
  const double start = dir > 0 ? from : to;
  q.d = start + dir * walked;
  q.s = l.s + p.s0;
  q.walking = walked > 0 && walked < width;
  q.heading = dir > 0 ? kPi / 2 : -kPi / 2;
  q.on_road = q.d > layout_.right_edge() - 0.3 && q.d < layout_.left_edge() + 0.3;
  return q;
}

double Scene::idm(double v, double v_des, double gap, double dv) const {
  const double a_max = 1.6, b = 2.5, s0 = 2.0, T = 1.2;
  const double vd = std::max(v_des, 0.1);
  const double s_star = s0 + std::max(0.0, v * T + v * dv / (2 * std::sqrt(a_max * b)));
  const double g = std::max(gap, 0.1);
  const double a = a_max * (1 - std::pow(v / vd, 4) - (s_star / g) * (s_star / g));
  return std::max(a, -8.0);
}

// Braking towards a stop point `gap` metres ahead: nothing until a constant deceleration of 1.8 m/s^2 is
// needed, then exactly the constant deceleration that stops a metre before the point.
static double stop_accel(double v, double gap) {
  const double room = gap - 1.0;
  if (room <= 0.05) return v > 0.05 ? -8.0 : 0.0;
  const double need = v * v / (2 * room);
  return need < 1.8 ? 1e9 : -std::min(need, 8.0);
}

bool Scene::lane_clear(int lane) const {
  const double dl = layout_.lane_centre(lane);
  for (auto& v : vehicles_)
    if (v.dir == 1 && std::abs(v.d - dl) < 2.0 && v.s > ego_.s - 12 - v.length / 2 && v.s < ego_.s + 25 + v.length / 2)
      return false;
  for (auto& l : lights_)
    if (l.s > ego_.s && l.s < ego_.s + 50) return false;
  return true;
}

ActionStep Scene::policy() {
  const double t = time(), dt = 1.0 / spec_.fps;
  const uint64_t seed = spec_.seed, idx = static_cast<uint64_t>(spec_.index);
  const District& D = *district_;
  while (t >= ego_.next_vdes_t) {
    Rng r(stream_key(seed, idx, "vdes", ego_.vdes_counter++));
    ego_.v_des = r.chance(0.15) ? D.speed_min * r.uniform(0.45, 0.7) : r.uniform(D.speed_min, D.speed_max);
    ego_.next_vdes_t += r.uniform(4, 10);
  }
  const int lane = std::clamp(layout_.lane_of(ego_.d), 0, layout_.lanes_fwd - 1);
  if (layout_.lanes_fwd > 1 && t >= ego_.next_lc_t) {
    Rng r(stream_key(seed, idx, "lane-change", ego_.lc_counter++));
    if (lane != ego_.target_lane) {
      ego_.next_lc_t = t + 1.0;  // still changing lanes
    } else {
      int target = lane + (r.chance(0.5) ? 1 : -1);
      if (target < 0 || target >= layout_.lanes_fwd) target = 2 * lane - target;
      if (lane_clear(target)) {
        ego_.target_lane = target;
        ego_.next_lc_t = t + r.uniform(7, 18);
      } else {
        ego_.next_lc_t = t + r.uniform(1, 2);
      }
    }
  }
  const double d_goal = layout_.lane_centre(ego_.target_lane);
  ego_.d_ref += std::clamp(d_goal - ego_.d_ref, -1.1 * dt, 1.1 * dt);
  if (spec_.wander > 0) {
    // Every 1-4 s a new goal offset in [-wander, wander]; drift there at up to 0.8 m/s. The moments and goals
    // are random, so the steering they cause cannot be predicted from the road ahead.
    while (t >= ego_.next_wander_t) {
      Rng r(stream_key(seed, idx, "wander", ego_.wander_counter++));
      ego_.wander_goal = r.uniform(-spec_.wander, spec_.wander);
      ego_.next_wander_t += r.uniform(1, 4);
    }
    ego_.wander += std::clamp(ego_.wander_goal - ego_.wander, -0.8 * dt, 0.8 * dt);
  }
  // Lateral: pure pursuit towards a point on the reference offset ahead.
  const double v = ego_.v;
  const double look = std::clamp(5 + 0.8 * v, 7.0, 25.0);
  double tx, ty;
  road_.point(ego_.s + look, ego_.d_ref + ego_.wander, tx, ty);
  const double dx = tx - ego_.x, dy = ty - ego_.y;
  const double fwd = dx * std::cos(ego_.h) + dy * std::sin(ego_.h);
  const double lat = -dx * std::sin(ego_.h) + dy * std::cos(ego_.h);
  double k = std::clamp(2 * lat / std::max(1.0, fwd * fwd + lat * lat), -0.2, 0.2);
  if (spec_.swerve > 0) {
    // Open-loop swerves at random moments (SceneSpec::swerve): the first after 0.5-3 s, then 1.5-5 s apart.
    while (t >= ego_.next_swerve_t) {
      Rng r(stream_key(seed, idx, "swerve", ego_.swerve_counter++));
      if (ego_.next_swerve_t < 0) {
        ego_.next_swerve_t = r.uniform(0.5, 3);
        continue;
      }
      ego_.swerve_start = ego_.next_swerve_t;
      ego_.swerve_end = ego_.swerve_start + r.uniform(0.4, 1.6);
      ego_.swerve_k = r.uniform(-spec_.swerve, spec_.swerve);
      ego_.swerve_rate = r.chance(0.5) ? 0.0 : r.uniform(-spec_.swerve, spec_.swerve);
      ego_.next_swerve_t = ego_.swerve_end + r.uniform(1.5, 5);
    }
    if (t < ego_.swerve_end)
      k = std::clamp(ego_.swerve_k + ego_.swerve_rate * (t - ego_.swerve_start), -spec_.swerve, spec_.swerve);
  }

  // Longitudinal: cruise speed, bends, bumps, lead vehicle, red lights, pedestrians.
  // Speed limits ahead (bends, bumps) become a comfortable deceleration profile: v^2 = v_lim^2 + 2 b x.
  double vdes = ego_.v_des;
  const double b_comf = 1.5;
  for (double x = 0; x <= 60; x += 4) {
    const double kk = std::abs(road_.at(ego_.s + x).k);
    if (kk > 1e-4) vdes = std::min(vdes, std::sqrt(1.8 / kk + 2 * b_comf * x));
  }
  for (double b : bumps_) {
    const double x = b - ego_.s;
    if (x > -3 && x < 60) vdes = std::min(vdes, std::sqrt(4.5 * 4.5 + 2 * b_comf * std::max(0.0, x - 2)));
  }
  double a = std::max(idm(v, vdes, 1e9, 0), -b_comf);
  const double front = ego_.s + kEgoFront;
  for (auto& o : vehicles_) {
    if (o.dir == 0) continue;
    const bool in_path = std::abs(o.d - ego_.d) < 2.0 || std::abs(o.d - d_goal) < 2.0;
    if (!in_path) continue;
    const double gap = o.s - o.length / 2 - front;
    if (gap < -1 || gap > 150) continue;
    a = std::min(a, idm(v, vdes, gap, v - o.dir * o.v));
  }
  double ldist;
  const int li = next_light(ldist);
  if (li >= 0) {
    const TrafficLight& l = lights_[static_cast<size_t>(li)];
    const int st = l.state(t);
    const double gap = l.s - front;
    if (gap > -0.5 && (st == 2 || (st == 1 && gap > v * v / (2 * 3.0) - 1.0))) a = std::min(a, stop_accel(v, gap));
  }
  for (auto& p : peds_) {
    if (p.light < 0) continue;
    PedPose q = pedestrian_pose(p, t);
    if (q.on_road && std::abs(q.d - ego_.d) < 3.0) {
      const double gap = q.s - 1.5 - front;
      if (gap > -0.5 && gap < 60) a = std::min(a, stop_accel(v, gap));
    }
  }
  double v_new = std::clamp(v + a * dt, 0.0, 30.0);
  if (v_new < 0.05 && a < 0) v_new = 0;
  return {static_cast<double>(static_cast<float>(v_new)), static_cast<double>(static_cast<float>(k))};
}

int Scene::next_light(double& distance) const {
  int best = -1;
  distance = 0;
  for (size_t i = 0; i < lights_.size(); ++i) {
    const double dd = lights_[i].s - ego_.s;
    if (dd > 0.5 && dd < 80 && (best < 0 || dd < distance)) best = static_cast<int>(i), distance = dd;
  }
  return best;
}

int Scene::lead_vehicle(double& distance) const {
  int best = -1;
  distance = 0;
  for (size_t i = 0; i < vehicles_.size(); ++i) {
    const Vehicle& o = vehicles_[i];
    if (o.dir != 1 || std::abs(o.d - ego_.d) > 1.9) continue;
    const double dd = o.s - o.length / 2 - ego_.s;
    if (dd > 0 && dd < 100 && (best < 0 || dd < distance)) best = static_cast<int>(i), distance = dd;
  }
  return best;
}

void Scene::step(const ActionStep& act) {
  const double t = time(), dt = 1.0 / spec_.fps;
  // Agents (they see the ego's state at time t).
  // Vehicles far from the ego (never visible) are dormant: they keep their speed and ignore each other,
  // which keeps a step O(nearby^2) however long the episode.
  constexpr double kActive = 500;
  std::vector<size_t> active;
  for (size_t i = 0; i < vehicles_.size(); ++i)
    if (std::abs(vehicles_[i].s - ego_.s) < kActive) active.push_back(i);
  std::vector<double> acc(vehicles_.size(), 0.0);
  for (size_t i : active) {
    Vehicle& o = vehicles_[i];
    if (o.dir == 0) continue;
    double v0 = o.v0;
    o.braking = false;
    for (auto& b : o.brakes)
      if (t >= b.first && t < b.second) v0 = o.v0 * 0.25;
    // Swerve away when the ego intrudes into an oncoming vehicle's lane.
    o.swerving = false;
    if (o.dir == -1) {
      const double ahead = o.s - ego_.s;
      if (std::abs(ego_.d - o.lane_d) < 2.8 && ahead > 0 && ahead < 55) {
        o.swerving = true;
        v0 = std::min(v0, o.v0 * 0.35);
      }
      o.d_target = o.swerving ? o.lane_d - 1.7 : o.lane_d;
    }
    double a = idm(o.v, v0, 1e9, 0) * 0.9;
    const double front = o.s + o.dir * o.length / 2;
    for (size_t j : active) {
      const Vehicle& p = vehicles_[j];
      if (j == i || std::abs(p.d - o.d) > 2.0 || p.dir == 0) continue;
      const double gap = o.dir * (p.s - o.s) - (o.length + p.length) / 2;
      if (gap < -0.5 || gap > 120) continue;
      a = std::min(a, idm(o.v, v0, gap, o.v - o.dir * p.dir * p.v));
    }
    if (std::abs(ego_.d - o.d) < 2.2) {  // the ego as an obstacle
      const double gap = o.dir * (ego_.s - o.s) - o.length / 2 - kEgoHalfLen;
      if (gap > -0.5 && gap < 120) a = std::min(a, idm(o.v, v0, gap, o.v - o.dir * ego_.v));
    }
    for (auto& l : lights_) {
      if (std::abs(l.s - o.s) > 100) continue;
      const double stop = o.dir > 0 ? l.s : l.s + 6.0;
      const double gap = o.dir * (stop - front);
      if (gap < -0.5 || gap > 80) continue;
      const int st = l.state(t);
      if (st == 2 || (st == 1 && gap > o.v * o.v / 6.0 - 1.0)) a = std::min(a, stop_accel(o.v, gap));
    }
    for (auto& p : peds_) {
      if (p.light < 0 || std::abs(lights_[static_cast<size_t>(p.light)].s - o.s) > 80) continue;
      PedPose q = pedestrian_pose(p, t);
      if (q.on_road && std::abs(q.d - o.d) < 3.0) {
        const double gap = o.dir * (q.s - front) - 1.5;
        if (gap > -0.5 && gap < 60) a = std::min(a, stop_accel(o.v, gap));
      }
    }
    acc[i] = a;
  }
  for (size_t i = 0; i < vehicles_.size(); ++i) {
    Vehicle& o = vehicles_[i];
    if (o.dir == 0) continue;
    const double v_new = std::max(0.0, o.v + acc[i] * dt);
    o.accel = (v_new - o.v) / dt;
    o.braking = o.accel < -0.6 || (v_new < 0.3 && o.v0 > 0);
    o.s += o.dir * 0.5 * (o.v + v_new) * dt;
    o.v = v_new;
    o.d += std::clamp(o.d_target - o.d, -1.8 * dt, 1.8 * dt);
  }
  // Ego: integrate the action along a circular arc.
  const double v = act.speed, k = act.curvature, ds = v * dt, dh = k * ds;
  const double accel = std::clamp((v - ego_.v) / dt, -8.0, 8.0);
  if (std::abs(dh) < 1e-9) {
    ego_.x += ds * std::cos(ego_.h);
    ego_.y += ds * std::sin(ego_.h);
  } else {
    ego_.x += (std::sin(ego_.h + dh) - std::sin(ego_.h)) / k;
    ego_.y += (std::cos(ego_.h) - std::cos(ego_.h + dh)) / k;
  }
  ego_.h += dh;
  const double s_prev = ego_.s;
  double s_new, d_new;
  road_.project(ego_.x, ego_.y, ego_.s + ds, s_new, d_new);
  ego_.s = s_new;
  ego_.d = d_new;
  // Body motion: pitch springs towards -accel (nose dips when braking), bumps kick it, roll follows the
  // lateral acceleration (the body leans out of the turn).
  const double w = 2 * kPi * 1.3, zeta = 0.45;
  const double pitch_eq = 0.004 * accel;
  double kick = 0;
  for (double b : bumps_) {
    if (s_prev < b && ego_.s >= b) kick += 0.05 * std::min(v, 8.0);             // front wheels
    if (s_prev < b + 2.7 && ego_.s >= b + 2.7) kick -= 0.04 * std::min(v, 8.0);  // rear wheels
  }
  ego_.pitch_rate += (w * w * (pitch_eq - ego_.pitch) - 2 * zeta * w * ego_.pitch_rate) * dt + kick;
  ego_.pitch += ego_.pitch_rate * dt;
  const double roll_eq = std::clamp(0.006 * v * v * k, -0.05, 0.05);
  ego_.roll += (roll_eq - ego_.roll) * std::min(1.0, 4.0 * dt);
  ego_.accel = accel;
  ego_.v = v;
  ego_.k = k;
  ++frame_;
  road_.ensure(ego_.s + 450);
}

const std::string& Scene::weather() const {
  const bool changed = spec_.change_at > 0 && !spec_.change_weather.empty() && time() >= spec_.change_at;
  return changed ? spec_.change_weather : spec_.weather;
}

const std::string& Scene::time_of_day() const {
  const bool changed = spec_.change_at > 0 && !spec_.change_time_of_day.empty() && time() >= spec_.change_at;
  return changed ? spec_.change_time_of_day : spec_.time_of_day;
}

bool Scene::caption_changed() const { return spec_.change_at > 0 && time() >= spec_.change_at - spec_.change_lead; }

nlohmann::json Scene::labels(const ActionStep& a) const {
  using nlohmann::json;
  json j;
  j["weather"] = weather();
  j["time_of_day"] = time_of_day();
  j["district"] = spec_.district;
  double ldist;
  const int li = next_light(ldist);
  if (li >= 0) {
    j["light_state"] = light_state_name(lights_[static_cast<size_t>(li)].state(time()));
    j["light_distance_m"] = ldist;
  } else {
    j["light_state"] = "none";
    j["light_distance_m"] = nullptr;
  }
  double lead_d;
  const int lead = lead_vehicle(lead_d);
  if (lead >= 0) {
    const Vehicle& o = vehicles_[static_cast<size_t>(lead)];
    j["lead_distance_m"] = lead_d;
    j["lead_close"] = lead_d < 20;
    j["lead_type"] = vehicle_name(o.kind);
    j["lead_braking"] = o.braking;
  } else {
    j["lead_distance_m"] = nullptr;
    j["lead_close"] = false;
    j["lead_type"] = nullptr;
    j["lead_braking"] = false;
  }
  const int lane = layout_.lane_of(ego_.d);
  j["ego_lane"] = lane;
  j["lanes"] = layout_.lanes_fwd;
  j["lane_offset_m"] = ego_.d - layout_.lane_centre(std::max(lane, 0));
  j["target_lane"] = ego_.target_lane;
  j["speed"] = a.speed;
  j["curvature"] = a.curvature;
  j["accel"] = (a.speed - ego_.v) * spec_.fps;
  const double k_ahead = road_.at(ego_.s + 25).k;
  j["road_ahead"] = k_ahead > 1.0 / 400 ? "left_bend" : k_ahead < -1.0 / 400 ? "right_bend" : "straight";
  int crossing = 0;
  for (auto& p : peds_)
    if (p.light >= 0) {
      PedPose q = pedestrian_pose(p, time());
      if (q.on_road && q.s > ego_.s && q.s < ego_.s + 60) ++crossing;
    }
  j["pedestrians_crossing"] = crossing;
  bool onc = false;
  std::string onc_type;
  for (auto& o : vehicles_)
    if (o.dir == -1 && o.s > ego_.s + 3 && o.s < ego_.s + 40) onc = true, onc_type = vehicle_name(o.kind);
  j["oncoming_close"] = onc;
  j["oncoming_type"] = onc ? json(onc_type) : json(nullptr);
  bool bump = false;
  for (double b : bumps_) bump |= b > ego_.s && b < ego_.s + 30;
  j["speed_bump_ahead"] = bump;
  return j;
}

}  // namespace gaia::synth
