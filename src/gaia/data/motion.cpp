#include "gaia/data/motion.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <random>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "gaia/core/error.h"
#include "gaia/core/numbers.h"
#include "gaia/core/npy.h"
#include "gaia/data/episode.h"

namespace gaia::data {

namespace {

constexpr int kMinTracks = 20;          // fewer tracked corners than this: the frame is too dark, blank or blurred
constexpr int kMinInliers = 30;         // fewer epipolar inliers: no consistent rigid motion
constexpr int kMinRoadPoints = 8;       // triangulated points on the fitted road plane
constexpr double kStillFlowPx = 0.15;   // median track motion (working pixels) below which the car stands
constexpr double kFixedFlowPx = 0.3;    // a track moving less than this (working pixels) is left out of the geometry
constexpr int kFixedCell = 8;           // working pixels a side of the cells that vote on being fixed to the camera
constexpr double kFixedVotes = 4;       // net votes that leave a cell out of the corner search
constexpr double kFixedFade = 0.98;     // the votes' decay per pair
constexpr double kMaxRoadTilt = 0.45;   // rad: the road plane's normal within this of the camera's down axis
constexpr double kMinForward = 0.8;     // |t_z| of the unit translation: the camera moves mostly forward
constexpr double kRoadTolerance = 0.06; // a point is on the plane within this share of the camera's height

double median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return std::isnan(x); }), v.end());
  if (v.empty()) return kNaN;
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + long(m), v.end());
  if (v.size() % 2) return v[m];
  const double hi = v[m];
  return (*std::max_element(v.begin(), v.begin() + long(m)) + hi) / 2;
}

cv::Mat gray_of(const cv::Mat& bgr, double scale) {
  cv::Mat g;
  if (bgr.channels() == 3) cv::cvtColor(bgr, g, cv::COLOR_BGR2GRAY);
  else if (bgr.channels() == 4) cv::cvtColor(bgr, g, cv::COLOR_BGRA2GRAY);
  else g = bgr.clone();
  if (scale != 1) cv::resize(g, g, cv::Size(), scale, scale, cv::INTER_AREA);
  return g;
}

// Distance from the camera to the road plane, in the units of `pts` (unit baseline): RANSAC over planes whose
// normal is near the camera's down axis, refined as the median distance of the plane's inliers. NaN when no plane
// holds kMinRoadPoints points.
double road_distance(const std::vector<cv::Point3d>& pts, int* support) {
  *support = 0;
  if (int(pts.size()) < kMinRoadPoints) return kNaN;
  std::mt19937 rng(12345);  // deterministic: the same frames give the same estimate
  std::uniform_int_distribution<size_t> pick(0, pts.size() - 1);
  cv::Vec3d best_n;
  double best_d = kNaN;
  for (int it = 0; it < 200; ++it) {
    const cv::Point3d a = pts[pick(rng)], b = pts[pick(rng)], c = pts[pick(rng)];
    cv::Vec3d n = cv::Vec3d(b - a).cross(cv::Vec3d(c - a));
    const double len = cv::norm(n);
    if (len < 1e-12) continue;
    n /= len;
    if (n[1] < 0) n = -n;                               // pointing down (camera y axis)
    if (std::acos(std::min(1.0, n[1])) > kMaxRoadTilt) continue;
    const double d = n.dot(cv::Vec3d(a));               // the camera is d above the plane
    if (!(d > 0)) continue;
    int count = 0;
    for (const auto& p : pts)
      if (std::abs(n.dot(cv::Vec3d(p)) - d) < kRoadTolerance * d) ++count;
    if (count > *support) {
      *support = count;
      best_n = n;
      best_d = d;
    }
  }
  if (*support < kMinRoadPoints) return kNaN;
  std::vector<double> ds;
  for (const auto& p : pts)
    if (std::abs(best_n.dot(cv::Vec3d(p)) - best_d) < kRoadTolerance * best_d) ds.push_back(best_n.dot(cv::Vec3d(p)));
  return median(ds);
}

}  // namespace

int64_t MotionEstimate::frames_with_speed() const {
  return std::count_if(speed.begin(), speed.end(), [](double x) { return !std::isnan(x); });
}
int64_t MotionEstimate::frames_with_curvature() const {
  return std::count_if(curvature.begin(), curvature.end(), [](double x) { return !std::isnan(x); });
}

double MotionEstimator::focal_for(const CameraIntrinsics& camera, const MotionOptions& opt, int width) {
  if (camera.focal_px > 0 && camera.width > 0) return camera.focal_px * double(width) / camera.width;
  if (!(opt.hfov_deg > 1 && opt.hfov_deg < 179)) fail("--hfov must be in (1, 179) degrees, got {}", opt.hfov_deg);
  return double(width) / 2 / std::tan(opt.hfov_deg / 2 * kPi / 180);
}

MotionEstimator::MotionEstimator(const CameraIntrinsics& camera, const MotionOptions& opt) : camera_(camera), opt_(opt) {
  if (!(opt.camera_height > 0.2 && opt.camera_height < 10))
    fail("--camera-height must be in (0.2, 10) metres, got {}", opt.camera_height);
  if (!(opt.smooth_s >= 0 && opt.smooth_s <= 10)) fail("motion smoothing must be in [0, 10] s, got {}", opt.smooth_s);
  if (opt.max_width < 64) fail("motion: max_width must be >= 64, got {}", opt.max_width);
}

void MotionEstimator::add(const cv::Mat& bgr, double time_s) {
  if (bgr.empty()) fail("motion: empty frame at {} s", time_s);
  const auto t0 = std::chrono::steady_clock::now();
  if (times_.empty()) {
    scale_ = 1;
    while (bgr.cols * scale_ > opt_.max_width) scale_ /= 2;
    if (camera_.width == 0) {  // intrinsics of this video's own frames
      camera_.width = bgr.cols;
      camera_.height = bgr.rows;
    }
  } else if (!(time_s > times_.back())) {
    fail("motion: frame times must increase ({} s after {} s)", time_s, times_.back());
  }
  cv::Mat g = gray_of(bgr, scale_);
  if (!recent_.empty()) {
    // The latest earlier frame at least baseline_s back (at the start of a video, the earliest there is).
    size_t j = 0;
    for (size_t k = 0; k < recent_.size(); ++k)
      if (time_s - recent_[k].first >= opt_.baseline_s) j = k;
    Pair p = measure(recent_[j].second, g, time_s - recent_[j].first);
    p.t_mid = (time_s + recent_[j].first) / 2;
    pairs_.push_back(p);
    recent_.erase(recent_.begin(), recent_.begin() + long(j));  // older frames are never paired again
  }
  recent_.emplace_back(time_s, g);
  times_.push_back(time_s);
  seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

MotionEstimator::Pair MotionEstimator::measure(const cv::Mat& prev, const cv::Mat& cur, double dt) {
  Pair out{kNaN, kNaN, 0.0, ""};
  const double f = focal_for(camera_, opt_, prev.cols);
  const double sx = double(prev.cols) / camera_.width, sy = double(prev.rows) / camera_.height;
  const double cx = camera_.focal_px > 0 ? camera_.cx * sx : prev.cols / 2.0;
  const double cy = camera_.focal_px > 0 ? camera_.cy * sy : prev.rows / 2.0;
  const cv::Matx33d K(f, 0, cx, 0, f, cy, 0, 0, 1);

  std::vector<cv::Point2f> p0, p1, back, low;
  // Corners over the whole frame, and as many again below the horizon with a lower bar: the road surface is
  // weakly textured, and its points set the scale.
  const double spacing = std::max(4.0, prev.cols / 160.0);
  if (fixed_votes_.empty())
    fixed_votes_ = cv::Mat::zeros((prev.rows + kFixedCell - 1) / kFixedCell, (prev.cols + kFixedCell - 1) / kFixedCell,
                                  CV_32F);
  cv::Mat search;  // 255 where corners are looked for: every cell not yet found fixed to the camera
  cv::resize(fixed_votes_ < kFixedVotes, search, cv::Size(fixed_votes_.cols * kFixedCell, fixed_votes_.rows * kFixedCell),
             0, 0, cv::INTER_NEAREST);
  search = search(cv::Rect(0, 0, prev.cols, prev.rows)).clone();
  cv::goodFeaturesToTrack(prev, p0, opt_.max_features / 2, 0.005, spacing, search);
  cv::Mat below = cv::Mat::zeros(prev.size(), CV_8U);
  below.rowRange(std::min(prev.rows - 1, int(cy + 0.05 * prev.rows)), prev.rows).setTo(255);
  cv::goodFeaturesToTrack(prev, low, opt_.max_features / 2, 0.001, spacing, below & search);
  p0.insert(p0.end(), low.begin(), low.end());
  if (int(p0.size()) < kMinTracks) {
    out.reason = "too few tracks";
    return out;
  }
  std::vector<uchar> ok1, ok2;
  std::vector<float> err;
  const cv::Size win(21, 21);
  cv::calcOpticalFlowPyrLK(prev, cur, p0, p1, ok1, err, win, 3);
  cv::calcOpticalFlowPyrLK(cur, prev, p1, back, ok2, err, win, 3);
  std::vector<cv::Point2f> a, b;
  std::vector<double> flow;
  for (size_t i = 0; i < p0.size(); ++i)
    if (ok1[i] && ok2[i] && cv::norm(back[i] - p0[i]) < 1.0) {
      a.push_back(p0[i]);
      b.push_back(p1[i]);
      flow.push_back(cv::norm(p1[i] - p0[i]));
    }
  if (int(a.size()) < kMinTracks) {
    out.reason = "too few tracks";
    return out;
  }
  // Nothing moves, not even the fastest fifth of the tracks: the car stands, unless the tracks that do move show the
  // camera going forward over the road (people walking past a standing car do not). Corners fixed to the camera (a
  // hood, a watermark, a timestamp, raindrops on the screen) never move: where they are most of the tracks they would
  // read as standing still and outvote the road in the essential matrix, so the geometry takes the moving tracks.
  std::vector<double> sorted = flow;
  std::sort(sorted.begin(), sorted.end());
  const bool mostly_still = sorted[sorted.size() * 4 / 5] < kStillFlowPx;
  auto standing_still = [&] {
    out.speed = 0;
    out.yaw_rate = 0;
    out.confidence = 0.5;
    out.reason = "standing still";
    return out;
  };
  const std::vector<cv::Point2f> all = a;  // every track, for the votes on cells fixed to the camera
  const std::vector<double> all_flow = flow;
  {
    std::vector<cv::Point2f> ma, mb;
    std::vector<double> mflow;
    // Left out: where most tracks stand, the still ones; else those in cells seen fixed to the camera before.
    for (size_t i = 0; i < a.size(); ++i)
      if (mostly_still ? flow[i] >= kFixedFlowPx
                       : flow[i] >= kFixedFlowPx ||
                             fixed_votes_.at<float>(int(a[i].y) / kFixedCell, int(a[i].x) / kFixedCell) < 1) {
        ma.push_back(a[i]);
        mb.push_back(b[i]);
        mflow.push_back(flow[i]);
      }
    if (int(ma.size()) < kMinInliers) {
      if (mostly_still) return standing_still();
      out.reason = "no consistent motion";
      return out;
    }
    a.swap(ma);
    b.swap(mb);
    flow.swap(mflow);
  }
  cv::Mat inl;
  cv::Mat E = cv::findEssentialMat(a, b, K, cv::RANSAC, 0.999, 1.0, inl);
  if (E.rows != 3 || E.cols != 3) {
    if (mostly_still) return standing_still();
    out.reason = "no consistent motion";
    return out;
  }
  cv::Mat R, t;
  const int inliers = cv::recoverPose(E, a, b, K, R, t, inl);
  if (inliers < kMinInliers) {
    if (mostly_still) return standing_still();
    out.reason = "no consistent motion";
    return out;
  }
  // A car moves along its camera's axis: a translation mostly sideways or vertical is a wrong pose (fog, glare,
  // a scene of one far plane), not a motion to report.
  if (std::abs(t.at<double>(2)) < kMinForward) {
    if (mostly_still) return standing_still();
    out.reason = "no consistent motion";
    return out;
  }
  // recoverPose gives x2 = R x1 + t. A left turn rotates the camera about its down axis so that R = Ry(+psi).
  const double yaw = std::atan2(R.at<double>(0, 2), R.at<double>(2, 2));
  out.yaw_rate = yaw / dt;
  const double inlier_share = double(inliers) / double(a.size());

  // Triangulate inlier tracks below the horizon with a unit baseline: the road ahead (the middle of the frame)
  // first, the whole width (verges, pavements) when the road itself has too few corners. Tracks that do not move
  // (a visible hood or dashboard) are left out.
  const double still = std::max(0.5, 0.2 * median(flow));
  cv::Mat Rt;
  cv::hconcat(R, t, Rt);
  const cv::Mat P0 = cv::Mat(cv::Matx34d(f, 0, cx, 0, 0, f, cy, 0, 0, 0, 1, 0)), P1 = cv::Mat(K) * Rt;
  auto road_points = [&](double half_width) {
    std::vector<cv::Point2f> ga, gb;
    for (int i = 0; i < inl.rows; ++i) {
      const cv::Point2f& p = a[size_t(i)];
      if (inl.at<uchar>(i) && p.y > cy + 0.08 * prev.rows && std::abs(p.x - cx) < half_width * prev.cols &&
          cv::norm(b[size_t(i)] - p) > still) {
        ga.push_back(p);
        gb.push_back(b[size_t(i)]);
      }
    }
    std::vector<cv::Point3d> pts;
    if (int(ga.size()) < kMinRoadPoints) return pts;
    cv::Mat X;
    cv::triangulatePoints(P0, P1, ga, gb, X);
    X.convertTo(X, CV_64F);
    for (int i = 0; i < X.cols; ++i) {
      const double w = X.at<double>(3, i);
      if (std::abs(w) < 1e-12) continue;
      cv::Point3d p(X.at<double>(0, i) / w, X.at<double>(1, i) / w, X.at<double>(2, i) / w);
      if (p.z > 0 && p.y > 0 && p.z < 200) pts.push_back(p);  // ahead of and below the camera, not at infinity
    }
    return pts;
  };
  int support = 0;
  double d = road_distance(road_points(0.4), &support);
  if (std::isnan(d)) d = road_distance(road_points(0.5), &support);
  if (std::isnan(d)) {
    if (mostly_still) return standing_still();
    out.reason = "no road plane";
    out.confidence = 0.25 * inlier_share;
    return out;
  }
  out.speed = opt_.camera_height / d / dt;  // |t| = 1 in the triangulation's units
  // The camera moved over the road: still corners vote their cells fixed to it, moving ones vote them free (a
  // standing car with people walking past never votes). Old votes fade, so a far point that stood on a straight road
  // is looked at again.
  fixed_votes_ *= kFixedFade;
  for (size_t i = 0; i < all.size(); ++i) {
    float& v = fixed_votes_.at<float>(int(all[i].y) / kFixedCell, int(all[i].x) / kFixedCell);
    v = all_flow[i] >= kFixedFlowPx ? std::max(0.0f, v - 2) : std::min(v + 1, 2 * float(kFixedVotes));
  }
  out.confidence = std::clamp(inlier_share * std::min(1.0, support / 30.0), 0.0, 1.0);
  return out;
}

MotionEstimate MotionEstimator::finish() const {
  MotionEstimate m;
  const size_t n = times_.size();
  m.time_s = times_;
  m.speed.assign(n, kNaN);
  m.yaw_rate.assign(n, kNaN);
  m.curvature.assign(n, kNaN);
  m.confidence.assign(n, 0.0);
  m.reason.assign(n, n < 2 ? "one frame" : "");
  if (n < 2) return m;
  for (size_t i = 0; i < n; ++i) {
    // Frame i's step runs to frame i + 1 (the last frame's is the one before it).
    const double mid = i + 1 < n ? (times_[i] + times_[i + 1]) / 2 : (times_[i - 1] + times_[i]) / 2;
    std::vector<double> v, w, c;
    std::map<std::string, int> why;
    int total = 0;
    auto take = [&](const Pair& p) {
      ++total;
      if (!std::isnan(p.speed)) v.push_back(p.speed);
      if (!std::isnan(p.yaw_rate)) w.push_back(p.yaw_rate);
      c.push_back(std::isnan(p.speed) ? 0.0 : p.confidence);
      if (!p.reason.empty()) ++why[p.reason];
    };
    // Pairs come in time order: only those near the step are visited.
    const double half = opt_.smooth_s / 2;
    const auto first = std::lower_bound(pairs_.begin(), pairs_.end(), mid - half - 1e-9,
                                        [](const Pair& p, double t) { return p.t_mid < t; });
    for (auto it = first; it != pairs_.end() && it->t_mid <= mid + half + 1e-9; ++it)
      if (std::abs(it->t_mid - mid) <= half) take(*it);
    if (total == 0) {  // a window shorter than the pairs' spacing: the nearest pair (the earlier one on a tie)
      const auto after = std::lower_bound(pairs_.begin(), pairs_.end(), mid,
                                          [](const Pair& p, double t) { return p.t_mid < t; });
      const auto before = after == pairs_.begin() ? after : after - 1;
      take(after == pairs_.end() || std::abs(before->t_mid - mid) <= std::abs(after->t_mid - mid) ? *before : *after);
    }
    // Known when at least half of the window's pairs are.
    if (2 * int(v.size()) >= total) m.speed[i] = median(v);
    if (2 * int(w.size()) >= total) m.yaw_rate[i] = median(w);
    double conf = 0;
    for (double x : c) conf += x / double(c.size());
    m.confidence[i] = std::isnan(m.speed[i]) ? 0.0 : conf;
    std::string top;
    for (const auto& [r, k] : why)
      if (top.empty() || k > why[top]) top = r;
    if (std::isnan(m.speed[i]) || std::isnan(m.yaw_rate[i])) m.reason[i] = top.empty() ? "no estimate" : top;
    if (m.speed[i] >= kMinMotionSpeed && !std::isnan(m.yaw_rate[i])) m.curvature[i] = m.yaw_rate[i] / m.speed[i];
    else if (!std::isnan(m.speed[i]) && m.reason[i].empty()) m.reason[i] = "standing still";
  }
  m.ms_per_frame = 1000 * seconds_ / double(n);
  return m;
}

MotionEstimate estimate_episode_motion(const Episode& ep, const CameraIntrinsics& camera, const MotionOptions& opt,
                                       const std::function<void(int64_t, int64_t)>& progress) {
  MotionEstimator est(camera, opt);
  for (int64_t i = 0; i < ep.size(); ++i) {
    est.add(ep.frame_bgr(i), ep.time_s(i));
    if (progress) progress(i + 1, ep.size());
  }
  return est.finish();
}

void write_estimated_signals(const Episode& ep, const MotionEstimate& m) {
  const int64_t n = ep.size();
  if (int64_t(m.speed.size()) != n) fail("{}: an estimate of {} frames for {}", ep.dir().string(), m.speed.size(), n);
  auto f32 = [](const std::vector<double>& v) { return std::vector<float>(v.begin(), v.end()); };
  npy_write(ep.dir() / "speed.npy", npy_make(DType::F32, {n}, f32(m.speed)));
  npy_write(ep.dir() / "curvature.npy", npy_make(DType::F32, {n}, f32(m.curvature)));
  npy_write(ep.dir() / "motion_confidence.npy", npy_make(DType::F32, {n}, f32(m.confidence)));
  EpisodeMeta meta = ep.meta();
  meta.signals_source = "estimated";
  write_file_atomic(ep.dir() / "episode.json", meta.to_json().dump(2) + "\n");
}

std::string MotionAgreement::summary() const {
  return fmt::format("{} frames: median speed difference {:.1f}%, curvature sign agrees on {:.1f}% of {} turning "
                     "frames, yaw rate differs by {:.4f} rad/s on average",
                     frames, 100 * median_speed_rel_error, 100 * curvature_sign_agreement, curvature_frames,
                     yaw_rate_mae);
}

MotionAgreement compare_motion(const std::vector<double>& speed_a, const std::vector<double>& curvature_a,
                               const std::vector<double>& speed_b, const std::vector<double>& curvature_b) {
  const size_t n = std::min({speed_a.size(), curvature_a.size(), speed_b.size(), curvature_b.size()});
  MotionAgreement g;
  std::vector<double> rel;
  double yaw_err = 0;
  int64_t yaw_n = 0, sign_ok = 0;
  for (size_t i = 0; i < n; ++i) {
    // a is the estimate, b the reference.
    if (!std::isnan(speed_a[i]) && !std::isnan(speed_b[i]) && speed_b[i] >= kMinMotionSpeed) {
      rel.push_back(std::abs(speed_a[i] - speed_b[i]) / speed_b[i]);
      ++g.frames;
    }
    if (!std::isnan(curvature_a[i]) && !std::isnan(curvature_b[i]) && !std::isnan(speed_a[i]) &&
        !std::isnan(speed_b[i])) {
      yaw_err += std::abs(curvature_a[i] * speed_a[i] - curvature_b[i] * speed_b[i]);
      ++yaw_n;
      if (std::abs(curvature_b[i]) >= 0.002) {
        ++g.curvature_frames;
        if ((curvature_a[i] > 0) == (curvature_b[i] > 0)) ++sign_ok;
      }
    }
  }
  g.median_speed_rel_error = rel.empty() ? kNaN : median(rel);
  g.curvature_sign_agreement = g.curvature_frames ? double(sign_ok) / double(g.curvature_frames) : kNaN;
  g.yaw_rate_mae = yaw_n ? yaw_err / double(yaw_n) : kNaN;
  return g;
}

}  // namespace gaia::data
