#pragma once
// The procedural driving world's state and dynamics: road, traffic lights, speed bumps, other agents (with
// simple reactive behaviour), the ego vehicle and its driving policy. Rendering lives in render.h.
//
// Sign conventions (docs/synth.md): world x east, y north, heading counter-clockwise; curvature > 0 turns
// left; road lateral offset d > 0 is left of the road centre line; left-hand traffic, so the ego's lanes are
// at d > 0; lane 0 is the kerb-side (leftmost) lane. Camera pitch > 0 is nose up; roll > 0 means the body
// leans right (out of a left turn), which rotates the image content counter-clockwise.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "gaia/synth/district.h"
#include "gaia/synth/road.h"

namespace gaia::synth {

// One control step of the ego: speed (m/s) and path curvature (1/m, positive = turning left) held for one
// frame interval. These are the recorded actions.
struct ActionStep {
  double speed = 0, curvature = 0;
};

// Everything that determines a world. Random fields are resolved by resolve_spec before construction.
struct SceneSpec {
  uint64_t seed = 0;
  int index = 0;
  std::string district, weather, time_of_day, scene;  // scene: random, bend, red_light, lead_vehicle, straight
  double fps = 25, seconds = 10;
  // Lateral wander of the ego's driver within its lane, in metres (0 = a lane-keeping driver). With a lane
  // keeper the recorded curvature is the road's, which a world model can read off the video, so it learns to
  // ignore its action inputs; a driver that drifts to a new offset at random moments makes steering carry
  // information the frames do not (docs/synth.md, "Wander").
  double wander = 0;
  // Swerves: every 1.5-5 s the driver lets go of the lane and steers open loop for 0.4-1.6 s, a curvature drawn
  // in [-swerve, swerve] 1/m plus, half the time, a drift of up to swerve 1/m per second; then pure pursuit
  // brings it back (0 = never). Recorded drives then contain what the action evaluation commands (strong turns, a
  // pull off the lane), so a world model can learn what such actions look like, not only what a lane keeper does.
  double swerve = 0;
  // A change of conditions mid-drive (change_at 0 = none): from change_at seconds the world is drawn and labelled
  // under change_weather / change_time_of_day (each "" = kept; "random" = another value than the drive's own,
  // drawn from the seed and index), and the captions name the new conditions change_lead seconds before, so
  // that the words lead the scene as a text prompt leads a world model's rollout (docs/synth.md, "Changes").
  double change_at = 0, change_lead = 1.0;
  std::string change_weather, change_time_of_day;
};

// Fills empty district / weather / time_of_day / scene deterministically from (seed, index) and checks the
// rest; throws gaia::Error naming an unknown value.
SceneSpec resolve_spec(SceneSpec spec);

enum class VehicleKind { Car, Van, Bus, Truck };
const char* vehicle_name(VehicleKind k);

struct Vehicle {
  VehicleKind kind = VehicleKind::Car;
  int dir = 1;  // +1 ego direction, -1 oncoming, 0 parked
  double s = 0, d = 0, v = 0, v0 = 0, accel = 0;
  double lane_d = 0, d_target = 0;  // lane centre and current lateral goal
  double length = 4.4, width = 1.8, height = 1.5;
  cv::Vec3b colour;
  bool double_decker = false;
  uint32_t look = 0;  // random bits for details
  std::vector<std::pair<double, double>> brakes;  // (start, end) times of braking events
  bool braking = false, swerving = false;
};

struct TrafficLight {
  double s = 0;  // stop line for the ego direction (oncoming stop line is on the far side of the crossing)
  double green = 10, amber = 3, red = 12, offset = 0;
  bool crossing = true;
  int state(double t) const;  // 0 green, 1 amber, 2 red
  double cycle() const { return green + amber + red; }
};
const char* light_state_name(int state);  // "green", "amber", "red"

struct Pedestrian {
  int light = -1;         // crossing pedestrian at this light, or -1 for a pavement walker
  double s0 = 0, d0 = 0;  // crossing: offset along the crossing / walker: start s and pavement offset
  double speed = 1.3, delay = 1;
  int first_dir = 1;
  cv::Vec3b top, legs;
};
struct PedPose {
  double s, d, heading;  // heading relative to the road direction
  bool on_road, walking;
};

enum class PropKind { Tree, Building, Lamp, Hedge, Sign };
struct Prop {
  PropKind kind;
  double s, d, w, depth, h;  // along-road width, depth away from the road, height
  cv::Vec3b colour;
  uint32_t bits;
};

struct Ego {
  double x = 0, y = 0, h = 0, s = 0, d = 0;
  double v = 0, k = 0, accel = 0;  // last applied action and resulting acceleration
  double pitch = 0, pitch_rate = 0, roll = 0;
  int target_lane = 0;
  double d_ref = 0;
  double v_des = 10, next_vdes_t = 0, next_lc_t = 0;
  uint64_t vdes_counter = 0, lc_counter = 0;
  double wander = 0, wander_goal = 0, next_wander_t = 0;  // current / goal offset from d_ref (m), next decision
  uint64_t wander_counter = 0;
  double swerve_k = 0, swerve_rate = 0, swerve_start = 0, swerve_end = -1, next_swerve_t = -1;
  uint64_t swerve_counter = 0;
};

class Scene {
 public:
  explicit Scene(const SceneSpec& resolved_spec);

  const SceneSpec& spec() const { return spec_; }
  const District& district() const { return *district_; }
  const RoadLayout& layout() const { return layout_; }
  const Road& road() const { return road_; }
  int64_t frame() const { return frame_; }
  double time() const { return static_cast<double>(frame_) / spec_.fps; }
  // The conditions the current frame is drawn and labelled under (the spec's, or its change's once reached), and
  // the ones its caption names (the change's from change_lead seconds before it).
  const std::string& weather() const;
  const std::string& time_of_day() const;
  bool caption_changed() const;
  const Ego& ego() const { return ego_; }
  const std::vector<Vehicle>& vehicles() const { return vehicles_; }
  const std::vector<Pedestrian>& pedestrians() const { return peds_; }
  const std::vector<TrafficLight>& lights() const { return lights_; }
  const std::vector<double>& bumps() const { return bumps_; }
  const std::vector<Prop>& props_block(int64_t block) const;  // 50 m blocks, generated lazily
  static constexpr double kBlock = 50.0;
  PedPose pedestrian_pose(const Pedestrian& p, double t) const;

  // The ego's driving policy: lane keeping, lane changes, cruise / follow / stop at red. Advances its own
  // decision state, so call it once per frame before step().
  ActionStep policy();
  // Advances one frame: agents react to the ego, then the ego integrates the action (exact circular arc).
  void step(const ActionStep& a);

  // Structured labels of the current frame given the action taken in it.
  nlohmann::json labels(const ActionStep& a) const;
  int lead_vehicle(double& distance) const;   // index into vehicles(), -1 if none within 100 m
  int next_light(double& distance) const;     // index into lights(), -1 if none within 80 m

 private:
  void spawn();
  double idm(double v, double v_des, double gap, double dv) const;
  bool lane_clear(int lane) const;

  SceneSpec spec_;
  const District* district_;
  RoadLayout layout_;
  Road road_;
  int64_t frame_ = 0;
  Ego ego_;
  std::vector<Vehicle> vehicles_;
  std::vector<Pedestrian> peds_;
  std::vector<TrafficLight> lights_;
  std::vector<double> bumps_;
  double agent_range_ = 0;
  mutable std::map<int64_t, std::vector<Prop>> props_;
};

}  // namespace gaia::synth
