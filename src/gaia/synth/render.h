#pragma once
// Forward-camera rendering of a Scene: pinhole camera 1.45 m above the road on the ego, with pitch and roll
// from the body motion; flat ground layer (road, markings, pavements) lit and fogged per pixel; 3-D objects
// (vehicles, pedestrians, trees, buildings, lamps, signals) painted far to near with anti-aliased polygons;
// weather overlays (rain streaks, snow flakes). Deterministic: the same world state gives the same pixels.
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "gaia/synth/scene.h"

namespace gaia::synth {

struct CameraModel {
  double height = 1.45;       // metres above the road
  double hfov_deg = 70;       // horizontal field of view
  double base_pitch = -0.065; // rad, slightly nose down: horizon a little above the image centre
};

class Renderer {
 public:
  Renderer(int height, int width, CameraModel cam = {});
  // Draws the world's current frame into `out` (BGR CV_8UC3, height x width).
  void render(const Scene& world, cv::Mat& out);
  // Reference mode for benchmarks: exact per-pixel exp() for fog and lighting instead of lookup tables.
  void set_naive(bool on) { naive_ = on; }
  int height() const { return h_; }
  int width() const { return w_; }

 private:
  int h_, w_;
  CameraModel cam_;
  bool naive_ = false;
  std::vector<float> noise_;  // 256x256 tileable value noise for ground texture
  cv::Mat glow_;              // 65x65 float radial falloff
};

}  // namespace gaia::synth
