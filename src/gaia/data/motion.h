#pragma once
// Ego-motion from video alone (monocular visual odometry), for drives without a CAN log, GPS track or OXTS:
// speed (m/s) and curvature (1/m, + = left) for every frame, stored like measured signals with
// signals_source "estimated" and a per-frame confidence (docs/formats.md).
//
// Each frame with the latest one at least baseline_s before it, at their recorded resolution (halved while wider
// than max_width):
//   1. corners (Shi-Tomasi) tracked by pyramidal Lucas-Kanade, kept when the backward track returns within a pixel;
//      corners that stay still while the car moves are fixed to the camera, left out of the geometry and, once they
//      have stood still in several pairs, out of the corner search
//   2. essential matrix with RANSAC, recoverPose: the rotation gives the yaw rate without any scale
//   3. inlier tracks below the horizon triangulated with the unit-length translation; a plane fitted to them with
//      RANSAC is the road, and its distance from the camera, against the true camera height, gives the scale
//   speed = scale / dt; each frame then takes the median of the pairs centred within smooth_s / 2 of its step;
//   curvature = yaw rate / speed (>= kMinMotionSpeed).
// Where it cannot tell, the value is NaN and `reason` says why: too few tracks (night, glare, a blank frame),
// no consistent motion, no road plane, standing still.
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "gaia/core/fs.h"

namespace gaia::data {

inline constexpr double kMinMotionSpeed = 1.0;  // m/s: slower than this, a curvature says little
inline constexpr double kKittiCameraHeight = 1.65;  // m: KITTI's camera rig (Geiger et al. 2013)

struct CameraIntrinsics {
  double focal_px = 0, cx = 0, cy = 0;  // at `width` x `height`; focal 0 = unknown (from MotionOptions::hfov_deg)
  int width = 0, height = 0;
};

struct MotionOptions {
  double camera_height = 1.4;  // metres above the road: a dashcam behind the mirror (KITTI drives: kKittiCameraHeight)
  bool camera_height_stated = false;  // false: a source that knows its own (KITTI) may replace it
  double hfov_deg = 70;        // horizontal field of view when the focal length is unknown (dashcams: 60-120)
  int max_width = 1280;        // frames wider than this are halved before tracking
  // Centred median window over the per-pair estimates: a tenth of a second's yaw is noisy where the scene has little
  // texture (fog, night), and a car's yaw rate changes over seconds.
  double smooth_s = 1.0;
  double baseline_s = 0.1;     // frames this far apart are paired: a longer baseline, a steadier triangulation
  int max_features = 800;      // corners tracked per pair
};

struct MotionEstimate {
  // Per frame; frame i's values describe the motion from frame i to i + 1, as a recorded action does (the last
  // frame copies the one before).
  std::vector<double> time_s, speed, yaw_rate, curvature, confidence;  // confidence in [0, 1]
  std::vector<std::string> reason;  // "" where speed and curvature are known, else why not
  double ms_per_frame = 0;          // tracking and geometry cost, wall clock
  int64_t frames_with_speed() const;
  int64_t frames_with_curvature() const;
};

// Streams frames in order; finish() smooths and returns the estimate.
class MotionEstimator {
 public:
  MotionEstimator(const CameraIntrinsics& camera, const MotionOptions& opt);
  void add(const cv::Mat& bgr, double time_s);
  MotionEstimate finish() const;
  // The focal length in pixels of a frame `width` wide under `opt` (its field of view when focal_px is unknown).
  static double focal_for(const CameraIntrinsics& camera, const MotionOptions& opt, int width);

 private:
  struct Pair {
    double speed, yaw_rate, confidence;
    std::string reason;
    double t_mid = 0;  // the middle of the two frames' times
  };
  Pair measure(const cv::Mat& prev, const cv::Mat& cur, double dt);

  CameraIntrinsics camera_;
  MotionOptions opt_;
  double scale_ = 1;  // working size / recorded size
  std::vector<std::pair<double, cv::Mat>> recent_;  // (time, grey frame) back to baseline_s before the newest
  std::vector<double> times_;
  std::vector<Pair> pairs_;
  // Per cell of the working frame, how often its corners stood still while the car moved: cells fixed to the camera
  // (a watermark, a timestamp, raindrops, the hood) are left out of the corner search, whose budget is the scene's.
  cv::Mat fixed_votes_;
  double seconds_ = 0;
};

class Episode;
// The estimate for an episode already ingested, from its stored frames (at the dataset's size: coarser than at
// ingest, where --motion video sees the recorded frames).
MotionEstimate estimate_episode_motion(const Episode& ep, const CameraIntrinsics& camera, const MotionOptions& opt,
                                       const std::function<void(int64_t, int64_t)>& progress = {});
// Stores an estimate as the episode's signals: speed.npy, curvature.npy, motion_confidence.npy, then episode.json
// with signals_source "estimated" (each file replaced atomically).
void write_estimated_signals(const Episode& ep, const MotionEstimate& m);

// How far two estimates of the same drive agree, over frames where both are known: median relative speed
// error, curvature sign agreement where |curvature| >= 0.002 1/m, mean absolute yaw-rate error.
struct MotionAgreement {
  int64_t frames = 0, curvature_frames = 0;
  double median_speed_rel_error = 0, curvature_sign_agreement = 0, yaw_rate_mae = 0;
  std::string summary() const;
};
MotionAgreement compare_motion(const std::vector<double>& speed_a, const std::vector<double>& curvature_a,
                               const std::vector<double>& speed_b, const std::vector<double>& curvature_b);

}  // namespace gaia::data
