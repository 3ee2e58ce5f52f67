#include "gaia/data/ingest.h"

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

EpisodeMeta ingest_video(const fs::path& video, const fs::path& dataset, const IngestOptions& opt,
                         const std::function<void(int64_t, int64_t)>& progress) {
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
  VideoFrame vf;
  int64_t total = opt.max_frames > 0 ? std::min(opt.max_frames, src.frame_count_hint()) : src.frame_count_hint();
  while ((opt.max_frames <= 0 || writer.frames_written() < opt.max_frames) && src.next(&vf)) {
    FrameRecord r;
    r.bgr = resize_center_crop(vf.bgr, opt.height, opt.width);
    r.time_s = vf.time_s;
    if (have_signals) {
      r.speed = static_cast<float>(sig.speed_at(vf.time_s));
      r.curvature = static_cast<float>(sig.curvature_at(vf.time_s));
      r.caption = sig.caption_at(vf.time_s);
    }
    writer.append(r);
    if (progress) progress(writer.frames_written(), std::max(total, writer.frames_written()));
  }
  if (writer.frames_written() == 0) fail("{}: video has no decodable frames", video.string());
  writer.commit();
  return writer.meta();
}

}  // namespace gaia::data
