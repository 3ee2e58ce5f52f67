#include "gaia/data/ingest.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include "gaia/core/error.h"
#include "gaia/data/gps.h"
#include "gaia/data/kitti.h"
#include "gaia/data/repeats.h"
#include "gaia/data/signals.h"
#include "gaia/data/video_io.h"

namespace gaia::data {

void apply_meta(EpisodeMeta* m, const std::map<std::string, std::string>& kv) {
  for (auto& [k, v] : kv) {
    if (k == "weather") m->weather = v;
    else if (k == "time_of_day") m->time_of_day = v;
    else if (k == "source") m->source = v;
    else if (k == "latitude" || k == "longitude") {
      double x;
      try {
        size_t used;
        x = std::stod(v, &used);
        if (used != v.size()) throw std::invalid_argument(v);
      } catch (const std::exception&) {
        fail("--meta {}={}: not a number", k, v);
      }
      bool bad = k == "latitude" ? !(x >= -90 && x <= 90) : !(x >= -180 && x <= 180);
      if (bad) fail("--meta {}={}: out of range", k, v);
      (k == "latitude" ? m->latitude : m->longitude) = x;
    } else {
      m->extra[k] = v;
    }
  }
}

namespace {

void check_fps(double fps) {
  if (fps != 0 && !(fps > 0 && fps <= kMaxIngestFps))
    fail("--fps {}: must be in (0, {}] frames per second", fps, kMaxIngestFps);
}

// Fewer frames than the container states, beyond its usual slack, means the file ends early or holds damaged
// data. Stopping at --max-frames is not truncation.
std::string truncation(const fs::path& video, int64_t decoded, int64_t stated, int64_t max_frames) {
  if (stated <= 0 || (max_frames > 0 && decoded >= max_frames)) return "";
  const int64_t expected = max_frames > 0 ? std::min(stated, max_frames) : stated;
  if (decoded >= expected - kFrameCountTolerance) return "";
  return fmt::format("{}: decoded {} of {} frames: the file is truncated or damaged", video.string(), decoded, stated);
}

// Where an episode's signals come from: at most one source, read before any frame is written.
struct SignalSource {
  Signals sig;
  std::string file, kind;  // kind: EpisodeMeta::signals_source
  bool present() const { return !kind.empty(); }
};

SignalSource signals_of(const IngestOptions& opt, double fps) {
  if (int(!opt.signals.empty()) + int(!opt.gps.empty()) + int(!opt.poses.empty()) > 1)
    fail("--signals, --gps and --poses: give one source of speed and curvature");
  SignalSource s;
  if (!opt.signals.empty()) {
    s.sig = read_signals_csv(opt.signals);
    s.file = opt.signals.string();
    s.kind = "csv";
  } else if (!opt.gps.empty()) {
    if (!std::isfinite(opt.gps_offset)) fail("--gps-offset must be a finite number of seconds");
    const GpsTrack t = read_gps_track(opt.gps);
    s.sig = track_signals(t, t.fixes.front().t_s + opt.gps_offset);
    s.file = opt.gps.string();
    s.kind = "gps";
  } else if (!opt.poses.empty()) {
    s.sig = pose_signals(opt.poses, fps);
    s.file = opt.poses.string();
    s.kind = "poses";
  }
  return s;
}

// One dataset, one frame size: the world model and the tokenizer see every episode at the same size.
void check_frame_size(const fs::path& dataset, int height, int width) {
  if (!fs::exists(dataset / "dataset.json") || !fs::is_directory(dataset / "episodes")) return;
  Dataset ds(dataset);
  if (ds.size() == 0) return;
  const EpisodeMeta m = ds.meta(0);
  if (m.height != height || m.width != width)
    fail("{}: its episodes are {}x{}, this config ingests at {}x{} (data.height x data.width); use the config the "
         "dataset was made with, or another --out", dataset.string(), m.height, m.width, height, width);
}

// Which of the first `max_frames` frames (0 = all) of `video` repeat the one before, and the camera's rate from
// the times of the others: a pass over the video alone.
std::vector<bool> repeats_of(const fs::path& video, const IngestOptions& opt, double* camera_fps) {
  VideoSource src(video, opt.retime_fps > 0 ? opt.retime_fps : opt.fps, opt.retime_fps > 0);
  std::vector<double> change, times;
  cv::Mat prev;
  VideoFrame vf;
  while ((opt.max_frames <= 0 || int64_t(change.size()) < opt.max_frames) && src.next(&vf)) {
    cv::Mat t = change_thumbnail(vf.bgr);
    change.push_back(prev.empty() ? 0.0 : frame_change(prev, t));
    times.push_back(vf.time_s);
    prev = t;
  }
  std::vector<bool> repeats = find_repeats(change);
  std::vector<double> kept;
  for (size_t i = 0; i < times.size(); ++i)
    if (!repeats[i]) kept.push_back(times[i]);
  const double rate = kept_frame_rate(kept);
  if (kept.size() < times.size() && rate > 0) *camera_fps = std::min(rate, *camera_fps);
  return repeats;
}

// The shared body of every ingest: frames from `src` (at `times` when given, else the source's clock) less the
// `repeats` flagged, signals interpolated to each frame, written and committed as one episode.
IngestResult ingest_from(VideoSource& src, const fs::path& video, const SignalSource& sig, EpisodeMeta meta,
                         const fs::path& dataset, const IngestOptions& opt, const std::vector<double>* times,
                         const std::vector<bool>* repeats, const std::function<void(int64_t, int64_t)>& progress) {
  check_frame_size(dataset, opt.height, opt.width);
  meta.height = opt.height;
  meta.width = opt.width;
  meta.frame_codec = opt.frame_codec;
  meta.signals_source = sig.kind;
  apply_meta(&meta, opt.meta);
  EpisodeWriter writer(dataset, meta, opt.overwrite);
  IngestResult res;
  res.container_frames = std::max<int64_t>(0, src.frame_count_hint());
  res.container_fps = src.fps();
  std::unique_ptr<MotionEstimator> motion;
  if (opt.motion_video) motion = std::make_unique<MotionEstimator>(opt.camera, opt.motion);
  VideoFrame vf;
  double first_t = 0, last_t = 0;
  int64_t total = opt.max_frames > 0 ? std::min(opt.max_frames, src.frame_count_hint()) : src.frame_count_hint();
  int64_t& decoded = res.frames_decoded;
  while ((opt.max_frames <= 0 || decoded < opt.max_frames) && src.next(&vf)) {
    const int64_t index = decoded++;
    if (repeats && size_t(index) < repeats->size() && (*repeats)[size_t(index)]) {
      ++res.repeats_dropped;
      continue;
    }
    FrameRecord r;
    r.bgr = resize_center_crop(vf.bgr, opt.height, opt.width);
    r.time_s = times ? times->at(size_t(index)) : vf.time_s;
    if (sig.present()) {
      r.speed = static_cast<float>(sig.sig.speed_at(r.time_s));
      r.curvature = static_cast<float>(sig.sig.curvature_at(r.time_s));
      r.caption = sig.sig.caption_at(r.time_s);
      if (!std::isnan(r.speed)) ++res.frames_with_speed;
    }
    if (r.caption.empty() && opt.caption) r.caption = opt.caption(r.time_s);
    if (writer.frames_written() == 0) first_t = r.time_s;
    last_t = r.time_s;
    if (motion) motion->add(vf.bgr, r.time_s);  // the recorded frame, before the resize
    writer.append(r);
    if (progress) progress(decoded, std::max(total, decoded));
  }
  const int64_t n = writer.frames_written();
  if (n == 0) fail("{}: video has no decodable frames", video.string());
  std::string cut = truncation(video, decoded, res.container_frames, opt.max_frames);
  if (!cut.empty() && !opt.allow_partial) fail("{}; --allow-partial keeps the {}", cut, decoded);
  if (!cut.empty()) res.warnings.push_back(fmt::format("{}; kept the {} (--allow-partial)", cut, decoded));
  if (last_t - first_t < opt.min_seconds)
    fail("{}: its {} frames span {:.2f} s, shorter than the {:.2f} s of one training window", video.string(), n,
         last_t - first_t, opt.min_seconds);

  if (sig.present()) {
    res.signal_coverage = double(res.frames_with_speed) / double(n);
    if (res.frames_with_speed == 0)
      fail("{}: gives none of the {} frames of {} a speed (signals span [{}, {}] s, the video [{}, {}] s)", sig.file, n,
           video.string(), sig.sig.time_s.front(), sig.sig.time_s.back(), first_t, last_t);
    if (res.signal_coverage < kLowSignalCoverage)
      res.warnings.push_back(fmt::format("{}: covers only {:.1f}% of the frames of {} ({} of {} got a speed)", sig.file,
                                         100 * res.signal_coverage, video.string(), res.frames_with_speed, n));
  }
  if (motion) {
    const MotionEstimate m = motion->finish();
    res.frames_estimated = m.frames_with_speed();
    res.motion_ms_per_frame = m.ms_per_frame;
    for (size_t i = 0; i < m.reason.size(); ++i)
      if (!m.reason[i].empty()) ++res.motion_gaps[m.reason[i]];
    const auto still = res.motion_gaps.find("standing still");
    if (still != res.motion_gaps.end() && still->second == int64_t(m.reason.size()))
      res.warnings.push_back(fmt::format("{}: the camera never moves (a parked car?): every frame reads as standing "
                                         "still, so these frames teach no steering", video.string()));
    if (sig.present()) {
      const std::vector<double> vs(writer.speeds().begin(), writer.speeds().end()),
          ks(writer.curvatures().begin(), writer.curvatures().end());
      res.motion_agreement = compare_motion(m.speed, m.curvature, vs, ks).summary();
    } else {
      std::vector<float> v(m.speed.begin(), m.speed.end()), k(m.curvature.begin(), m.curvature.end()),
          c(m.confidence.begin(), m.confidence.end());
      writer.set_signals(v, k, c, "estimated");
      if (res.frames_estimated == 0)
        res.warnings.push_back(fmt::format("{}: the video gave no frame a speed estimate ({}); its actions stay "
                                           "missing", video.string(), m.reason.empty() ? "" : m.reason.back()));
    }
  }
  writer.commit();
  res.meta = writer.meta();
  return res;
}

}  // namespace

IngestResult ingest_video(const fs::path& video, const fs::path& dataset, const IngestOptions& opt,
                          const std::function<void(int64_t, int64_t)>& progress) {
  check_fps(opt.fps);
  check_fps(opt.retime_fps);
  VideoSource src(video, opt.retime_fps > 0 ? opt.retime_fps : opt.fps, opt.retime_fps > 0);
  const SignalSource sig = signals_of(opt, src.fps());
  EpisodeMeta meta;
  meta.id = opt.id.empty() ? video.stem().string() : opt.id;
  if (meta.id.empty()) meta.id = video.filename().string();
  meta.fps = src.fps();
  meta.source = video.filename().string();
  // The recording itself, so that later steps (gaia data motion) can go back to its full-resolution frames.
  meta.extra["recording"] = fs::absolute(video).lexically_normal().string();
  if (opt.retime_fps > 0 || opt.fps > 0)
    meta.extra["recording_fps"] = fmt::format("{}", opt.retime_fps > 0 ? opt.retime_fps : opt.fps);
  if (opt.retime_fps > 0) meta.extra["recording_retimed"] = "1";
  std::vector<bool> repeats;
  if (opt.drop_repeats) repeats = repeats_of(video, opt, &meta.fps);  // meta.fps: the camera's rate
  return ingest_from(src, video, sig, meta, dataset, opt, nullptr, opt.drop_repeats ? &repeats : nullptr, progress);
}

IngestResult ingest_kitti(const fs::path& drive, const fs::path& dataset, const IngestOptions& opt,
                          const std::function<void(int64_t, int64_t)>& progress) {
  const KittiDrive d = read_kitti_drive(drive);
  if (opt.fps > 0) fail("--fps: a KITTI drive's rate comes from its timestamps ({:.3g} Hz)", d.fps);
  SignalSource sig = signals_of(opt, d.fps);
  if (!sig.present() && d.has_oxts()) {
    sig.sig = d.oxts;
    sig.file = (drive / "oxts").string();
    sig.kind = "kitti-oxts";
  } else if (!sig.present() && !opt.motion_video) {
    fail("{}: no oxts/ folder (KITTI's GPS/IMU record), so no speed or curvature; give --signals, --gps or "
         "--motion video, or ingest {} as images with --fps", drive.string(), d.images.string());
  }
  IngestOptions o = opt;
  if (d.focal_px > 0) o.camera = CameraIntrinsics{d.focal_px, d.cx, d.cy, d.image_width, d.image_height};
  if (!o.motion.camera_height_stated) o.motion.camera_height = kKittiCameraHeight;
  VideoSource src(d.images, d.fps);
  EpisodeMeta meta;
  fs::path name = drive;
  if (name.filename().empty()) name = name.parent_path();  // "drive/" names the drive too
  meta.id = opt.id.empty() ? name.filename().string() : opt.id;
  meta.fps = d.fps;
  meta.source = "kitti:" + name.filename().string();
  if (d.has_oxts()) {
    meta.latitude = d.latitude;
    meta.longitude = d.longitude;
  }
  meta.extra["recording"] = fs::absolute(drive).lexically_normal().string();
  return ingest_from(src, d.images, sig, meta, dataset, o, &d.image_time_s, nullptr, progress);
}

}  // namespace gaia::data
