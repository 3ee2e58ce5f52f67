#include "gaia/synth/road.h"

#include <algorithm>
#include <cmath>

#include "gaia/synth/district.h"
#include "gaia/synth/rng.h"

namespace gaia::synth {

int RoadLayout::lane_of(double d) const {
  double from_kerb = lanes_fwd * lane_w - d;
  if (from_kerb < 0) return -1;
  return static_cast<int>(std::floor(from_kerb / lane_w));
}

Road::Road(uint64_t key, const District& district, const std::string& scene)
    : key_(key), bendiness_(district.bendiness) {
  xs_ = {0.0};
  ys_ = {0.0};
  hs_ = {0.0};
  ks_ = {0.0};
  Rng rng(mix64(key_ ^ 0x51));
  if (scene == "bend") {
    add_segment(85, 0, 0);  // ego starts at s = 60
    add_bend(rng.chance(0.5) ? 1 : -1, rng.uniform(70, 140), rng.uniform(50, 80) * kPi / 180);
  } else if (scene == "straight" || scene == "red_light" || scene == "lead_vehicle") {
    add_segment(scene == "straight" ? 460 : 160, 0, 0);
  } else {
    add_segment(rng.uniform(70, 130), 0, 0);
  }
  ensure(600);
}

void Road::add_segment(double len, double k0, double k1) {
  segs_.push_back({seg_end_, len, k0, k1});
  seg_end_ += len;
}

void Road::add_bend(double sign, double radius, double angle) {
  const double k = sign / radius;
  const double trans = std::min(25.0, 0.4 * angle * radius);
  // Clothoid in and out (each turns k*trans/2), constant arc for the rest of the angle.
  const double arc = std::max(0.0, angle * radius - trans);
  add_segment(trans, 0, k);
  if (arc > 0) add_segment(arc, k, k);
  add_segment(trans, k, 0);
}

void Road::generate_next() {
  Rng rng(stream_key(key_, 0, "road-segment", counter_++));
  const double b = bendiness_;
  const int type = rng.weighted({1.0 - 0.6 * b, 0.35 + 0.5 * b, 0.1 + 0.4 * b});
  const double rmin = 60 + 140 * (1 - b), rmax = 250 + 350 * (1 - b);
  if (type == 0) {
    add_segment(rng.uniform(40, 220) * (1.0 - 0.6 * b), 0, 0);
  } else if (type == 1) {
    add_bend(rng.chance(0.5) ? 1 : -1, rng.uniform(rmin, rmax), rng.uniform(15, 75) * kPi / 180);
    add_segment(rng.uniform(15, 60), 0, 0);
  } else {
    const double sgn = rng.chance(0.5) ? 1 : -1;
    const double r = rng.uniform(rmin, rmax), a = rng.uniform(15, 45) * kPi / 180;
    add_bend(sgn, r, a);
    add_segment(rng.uniform(0, 20), 0, 0);
    add_bend(-sgn, r * rng.uniform(0.8, 1.25), a * rng.uniform(0.8, 1.2));
    add_segment(rng.uniform(15, 60), 0, 0);
  }
}

void Road::fill_samples() {
  size_t seg = 0;
  while (true) {
    const double s = static_cast<double>(xs_.size()) * kStep;
    if (s > seg_end_) break;
    while (seg + 1 < segs_.size() && s >= segs_[seg].s0 + segs_[seg].len) ++seg;
    const Segment& g = segs_[seg];
    const double u = std::clamp((s - g.s0) / g.len, 0.0, 1.0);
    const double k = g.k0 + (g.k1 - g.k0) * u;
    const double h0 = hs_.back(), k0 = ks_.back();
    const double h1 = h0 + 0.5 * (k0 + k) * kStep;
    const double hm = 0.5 * (h0 + h1);
    xs_.push_back(xs_.back() + kStep * std::cos(hm));
    ys_.push_back(ys_.back() + kStep * std::sin(hm));
    hs_.push_back(h1);
    ks_.push_back(k);
  }
}

void Road::ensure(double s_max) {
  if (length() >= s_max) return;
  while (seg_end_ < s_max + 1) generate_next();
  fill_samples();
}

RoadPose Road::at(double s) const {
  const double len = length();
  if (s <= 0) {
    return {xs_[0] + s * std::cos(hs_[0]), ys_[0] + s * std::sin(hs_[0]), hs_[0], 0.0};
  }
  if (s >= len) {
    const double e = s - len, h = hs_.back();
    return {xs_.back() + e * std::cos(h), ys_.back() + e * std::sin(h), h, 0.0};
  }
  const double f = s / kStep;
  const size_t i = static_cast<size_t>(f);
  const double u = f - static_cast<double>(i);
  const size_t j = std::min(i + 1, xs_.size() - 1);
  return {xs_[i] + (xs_[j] - xs_[i]) * u, ys_[i] + (ys_[j] - ys_[i]) * u, hs_[i] + (hs_[j] - hs_[i]) * u,
          ks_[i] + (ks_[j] - ks_[i]) * u};
}

double Road::max_abs_curvature(double s0, double s1) const {
  double m = 0;
  for (double s = s0; s <= s1; s += 2.0) m = std::max(m, std::abs(at(s).k));
  return m;
}

void Road::project(double x, double y, double s_hint, double& s, double& d) const {
  s = s_hint;
  RoadPose p = at(s);
  for (int it = 0; it < 8; ++it) {
    const double ex = x - p.x, ey = y - p.y;
    const double step = std::clamp(ex * std::cos(p.h) + ey * std::sin(p.h), -25.0, 25.0);
    s += step;
    p = at(s);
    if (std::abs(step) < 1e-7) break;
  }
  d = -(x - p.x) * std::sin(p.h) + (y - p.y) * std::cos(p.h);
}

void Road::point(double s, double d, double& x, double& y) const {
  const RoadPose p = at(s);
  x = p.x - d * std::sin(p.h);
  y = p.y + d * std::cos(p.h);
}

}  // namespace gaia::synth
