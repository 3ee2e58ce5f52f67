#include "gaia/data/ingest.h"

#include <algorithm>
#include <cmath>

#include "gaia/core/error.h"
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

}  // namespace

IngestResult ingest_video(const fs::path& video, const fs::path& dataset, const IngestOptions& opt,
                          const std::function<void(int64_t, int64_t)>& progress) {
  check_fps(opt.fps);
  VideoSource src(video, opt.fps);
  Signals sig;
  bool have_signals = !opt.signals.empty();
  if (have_signals) sig = read_signals_csv(opt.signals);
  EpisodeMeta meta;
  meta.id = opt.id.empty() ? video.stem().string() : opt.id;
  if (meta.id.empty()) meta.id = video.filename().string();
  meta.fps = src.fps();
  meta.height = opt.height;
  meta.width = opt.width;
  meta.frame_codec = opt.frame_codec;
  meta.source = video.filename().string();
  apply_meta(&meta, opt.meta);
  EpisodeWriter writer(dataset, meta, opt.overwrite);
  IngestResult res;
  res.container_frames = std::max<int64_t>(0, src.frame_count_hint());
  VideoFrame vf;
  double first_t = 0, last_t = 0;
  int64_t total = opt.max_frames > 0 ? std::min(opt.max_frames, src.frame_count_hint()) : src.frame_count_hint();
  while ((opt.max_frames <= 0 || writer.frames_written() < opt.max_frames) && src.next(&vf)) {
    FrameRecord r;
    r.bgr = resize_center_crop(vf.bgr, opt.height, opt.width);
    r.time_s = vf.time_s;
    if (have_signals) {
      r.speed = static_cast<float>(sig.speed_at(vf.time_s));
      r.curvature = static_cast<float>(sig.curvature_at(vf.time_s));
      r.caption = sig.caption_at(vf.time_s);
      if (!std::isnan(r.speed)) ++res.frames_with_speed;
    }
    if (writer.frames_written() == 0) first_t = vf.time_s;
    last_t = vf.time_s;
    writer.append(r);
    if (progress) progress(writer.frames_written(), std::max(total, writer.frames_written()));
  }
  const int64_t n = writer.frames_written();
  if (n == 0) fail("{}: video has no decodable frames", video.string());
  std::string cut = truncation(video, n, res.container_frames, opt.max_frames);
  if (!cut.empty() && !opt.allow_partial) fail("{}; --allow-partial keeps the {}", cut, n);
  if (!cut.empty()) res.warnings.push_back(fmt::format("{}; kept the {} (--allow-partial)", cut, n));
  if (have_signals) {
    res.signal_coverage = double(res.frames_with_speed) / double(n);
    const std::string csv = opt.signals.string();
    if (res.frames_with_speed == 0)
      fail("{}: gives none of the {} frames of {} a speed (signals span [{}, {}] s, the video [{}, {}] s)", csv, n,
           video.string(), sig.time_s.front(), sig.time_s.back(), first_t, last_t);
    if (res.signal_coverage < kLowSignalCoverage)
      res.warnings.push_back(fmt::format("{}: covers only {:.1f}% of the frames of {} ({} of {} got a speed)", csv,
                                         100 * res.signal_coverage, video.string(), res.frames_with_speed, n));
  }
  writer.commit();
  res.meta = writer.meta();
  return res;
}

}  // namespace gaia::data
