// gaia ingest VIDEO|KITTI_DRIVE [--signals CSV | --gps TRACK] [--meta key=value ...] [--allow-partial] --out DATASET
#include <cstdio>
#include <memory>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/data/ingest.h"
#include "gaia/data/kitti.h"

namespace gaia::app {

void register_ingest(CLI::App& app) {
  auto* cmd = app.add_subcommand("ingest", "add a video (file, image directory or KITTI raw drive) as an episode of a "
                                           "dataset");
  auto flags = std::make_shared<SharedFlags>();
  auto video = std::make_shared<std::string>();
  auto opt = std::make_shared<data::IngestOptions>();
  auto signals = std::make_shared<std::string>();
  auto metas = std::make_shared<std::vector<std::string>>();
  cmd->add_option("VIDEO", *video, "video file (anything FFmpeg decodes), a directory of PNG/JPEG frames, or a KITTI "
                  "raw drive (image_02/, oxts/: its speed and yaw rate are read)")->required();
  cmd->add_option("--signals", *signals, "CSV with columns time_s,speed,curvature[,caption]");
  cmd->add_option("--gps", opt->gps, "GPS track (NMEA log or .gpx): speed and curvature from successive fixes, and "
                  "the episode's latitude/longitude");
  cmd->add_option("--poses", opt->poses, "camera poses, one 3x4 [R | c] row of 12 numbers per frame (KITTI odometry "
                  "poses.txt, or a SLAM trajectory): speed and curvature from successive poses");
  cmd->add_option("--gps-offset", opt->gps_offset, "video time 0 is this many seconds after the track's first fix "
                  "(default 0: they start together)")->check(number_in({-1e9, 1e9}));
  cmd->add_option("--meta", *metas, "episode metadata key=value: weather, time_of_day, latitude, longitude, source, ...");
  cmd->add_option("--id", opt->id, "episode id (default: the video's file name)");
  cmd->add_option("--fps", opt->fps, "frame rate (required for image directories and videos that state none; must match the rate a video states)")
      ->check(number_in({0, data::kMaxIngestFps, true, false}));
  cmd->add_option("--codec", opt->frame_codec, "frame storage: raw | png | jpg")->check(CLI::IsMember({"raw", "png", "jpg"}));
  cmd->add_option("--max-frames", opt->max_frames, "stop after this many frames (0 = all)");
  cmd->add_flag("--overwrite", opt->overwrite, "replace an existing episode with the same id");
  cmd->add_flag("--allow-partial", opt->allow_partial,
                "keep the frames of a truncated or damaged video (with a warning) instead of failing");
  auto motion = std::make_shared<std::string>("none");
  cmd->add_option("--motion", *motion, "video: estimate speed and curvature from the frames (visual odometry) where "
                  "no signals are given, or report how far it agrees with them where they are")
      ->check(CLI::IsMember({"none", "video"}));
  add_motion_flags(cmd, &opt->motion);
  add_shared_flags(cmd, flags.get(), "dataset directory (created if missing)");
  cmd->callback([=] {
    Config c = resolve_config(*flags);
    apply_threads(c);
    if (flags->out.empty()) fail("gaia ingest: --out DATASET is required");
    data::IngestOptions o = *opt;
    o.height = c.data.height;
    o.width = c.data.width;
    o.signals = *signals;
    o.motion_video = *motion == "video";
    for (auto& kv : *metas) {
      auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0) fail("--meta '{}': expected key=value", kv);
      o.meta[kv.substr(0, eq)] = kv.substr(eq + 1);
    }
    std::unique_ptr<ProgressBar> bar;  // the frame count is only known once the video is open
    auto progress = [&](int64_t done, int64_t total) {
      if (!bar) bar = std::make_unique<ProgressBar>(total, "ingest");
      bar->update(done);
    };
    auto res = data::is_kitti_drive(*video) ? data::ingest_kitti(*video, flags->out, o, progress)
                                            : data::ingest_video(*video, flags->out, o, progress);
    if (bar) bar->finish();
    for (auto& w : res.warnings) std::fprintf(stderr, "gaia: warning: %s\n", w.c_str());
    if (o.motion_video) {
      std::string gaps;
      for (auto& [why, n] : res.motion_gaps) gaps += fmt::format("{}{} {}", gaps.empty() ? "" : ", ", n, why);
      std::printf("motion from video: %lld of %lld frames given a speed, %.1f ms a frame%s\n",
                  (long long)res.frames_estimated, (long long)res.meta.num_frames, res.motion_ms_per_frame,
                  gaps.empty() ? "" : (" (no speed or no curvature: " + gaps + ")").c_str());
      if (!res.motion_agreement.empty())
        std::printf("motion from video against %s: %s\n", res.meta.signals_source.c_str(), res.motion_agreement.c_str());
    }
    const data::EpisodeMeta& m = res.meta;
    std::printf("ingested %s: %lld frames at %.3g fps, resized to %dx%d (the config's data.height x data.width), %s; "
                "signals: %s -> %s/episodes/%s\n", video->c_str(), (long long)m.num_frames, m.fps, m.height, m.width,
                m.frame_codec.c_str(), m.signals_source.empty() ? "none" : m.signals_source.c_str(),
                flags->out.c_str(), m.id.c_str());
  });
}

}  // namespace gaia::app
