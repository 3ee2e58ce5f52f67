#pragma once
// The road: a centre line defined by a curvature profile kappa(s) over arc length s (straights, clothoid
// bends left and right, S-curves), plus a cross-section layout. World frame: x east, y north, heading
// counter-clockwise from +x, so positive curvature turns left. Road coordinates (s, d): d is the lateral
// offset from the centre line, positive to the left. Traffic drives on the left (London): the ego's lanes
// are at d > 0, oncoming lanes at d < 0.
#include <cstdint>
#include <string>
#include <vector>

namespace gaia::synth {

struct District;

struct RoadLayout {
  int lanes_fwd = 1, lanes_onc = 1;  // lanes in the ego's direction / oncoming
  double lane_w = 3.5;
  double parking_fwd = 0, parking_onc = 0;  // width of a kerbside parking strip (0 = none)
  double pavement_w = 3.0;
  bool centre_solid = false;  // double solid white centre line instead of a dashed one
  int edge_style = 1;         // 0 none, 1 solid white edge line, 2 double yellow (no waiting)
  bool kerbs = true;          // raised kerbs and pavements (false: grass verge, rural)

  double left_edge() const { return lanes_fwd * lane_w + parking_fwd; }     // ego-side kerb
  double right_edge() const { return -(lanes_onc * lane_w + parking_onc); }  // oncoming-side kerb
  // Ego-direction lane centre; lane 0 is the kerb-side (leftmost) lane.
  double lane_centre(int lane) const { return (lanes_fwd - lane - 0.5) * lane_w; }
  // Oncoming lane centre; lane 0 is next to the centre line.
  double onc_lane_centre(int lane) const { return -(lane + 0.5) * lane_w; }
  // Lane index (0 = kerb side) that contains offset d; values >= lanes_fwd are on the oncoming side,
  // -1 is beyond the ego-side lane edge.
  int lane_of(double d) const;
};

struct RoadPose {
  double x, y, h, k;  // position (m), heading (rad), curvature (1/m)
};

class Road {
 public:
  // `scene` "bend" puts a bend shortly after the start; "straight" keeps the first 400 m straight.
  Road(uint64_t key, const District& district, const std::string& scene);
  // Extends the centre line to at least s_max; the existing part never changes (prefix-stable).
  void ensure(double s_max);
  double length() const { return (static_cast<double>(xs_.size()) - 1) * kStep; }
  RoadPose at(double s) const;  // interpolated; extrapolates straight beyond the ends
  double curvature(double s) const { return at(s).k; }
  double max_abs_curvature(double s0, double s1) const;
  // Road coordinates of the world point (x, y), searching near s_hint.
  void project(double x, double y, double s_hint, double& s, double& d) const;
  // World position of road coordinates (s, d).
  void point(double s, double d, double& x, double& y) const;

  static constexpr double kStep = 0.5;

 private:
  struct Segment {
    double s0, len, k0, k1;
  };
  void add_segment(double len, double k0, double k1);
  void add_bend(double sign, double radius, double angle);
  void generate_next();
  void fill_samples();

  uint64_t key_;
  double bendiness_;
  uint64_t counter_ = 0;
  std::vector<Segment> segs_;
  double seg_end_ = 0;
  std::vector<double> xs_, ys_, hs_, ks_;
};

}  // namespace gaia::synth
