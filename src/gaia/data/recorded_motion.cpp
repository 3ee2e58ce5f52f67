#include "gaia/data/recorded_motion.h"

#include <cmath>
#include <memory>

#include "gaia/core/error.h"
#include "gaia/data/kitti.h"
#include "gaia/data/video_io.h"

namespace gaia::data {

MotionEstimate estimate_recorded_motion(const Episode& ep, const MotionOptions& opt,
                                        const std::function<void(int64_t, int64_t)>& progress) {
  const EpisodeMeta& m = ep.meta();
  if (m.is_procedural()) return estimate_episode_motion(ep, {}, opt, progress);
  const std::string coarse = fmt::format("estimating from its stored {}x{} frames would be far off", m.height, m.width);
  auto it = m.extra.find("recording");
  if (it == m.extra.end())
    fail("{}: its metadata names no recording (ingested by an older gaia), and {}: ingest it again with --motion "
         "video", m.id, coarse);
  const fs::path rec = it->second;
  if (!fs::exists(rec))
    fail("{}: its recording {} is not at hand, and {}: put the recording back there, or ingest it again with "
         "--motion video", m.id, rec.string(), coarse);
  CameraIntrinsics camera;
  MotionOptions o = opt;
  std::unique_ptr<VideoSource> src;
  std::vector<double> kitti_times;
  if (is_kitti_drive(rec)) {
    const KittiDrive d = read_kitti_drive(rec);
    if (d.focal_px > 0) camera = CameraIntrinsics{d.focal_px, d.cx, d.cy, d.image_width, d.image_height};
    if (!o.camera_height_stated) o.camera_height = kKittiCameraHeight;
    src = std::make_unique<VideoSource>(d.images, d.fps);
    kitti_times = d.image_time_s;
  } else {
    auto f = m.extra.find("recording_fps");
    const double fps = f == m.extra.end() ? 0 : std::stod(f->second);
    src = std::make_unique<VideoSource>(rec, fps, m.extra.count("recording_retimed") > 0);
  }
  MotionEstimator est(camera, o);
  VideoFrame vf;
  int64_t i = 0, k = 0;
  while (i < ep.size() && src->next(&vf)) {
    const double t = kitti_times.empty() ? vf.time_s : kitti_times.at(size_t(k));
    ++k;
    if (std::abs(t - ep.time_s(i)) > 1e-6) continue;  // a repeat that ingest dropped
    est.add(vf.bgr, t);
    ++i;
    if (progress) progress(i, ep.size());
  }
  if (i != ep.size())
    fail("{}: its recording {} holds {} of its {} frames at their times: it has changed since it was ingested; "
         "ingest it again", m.id, rec.string(), i, ep.size());
  return est.finish();
}

}  // namespace gaia::data
