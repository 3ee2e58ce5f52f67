// gaia ingest VIDEO|KITTI_DRIVE [--signals CSV | --gps TRACK] [--meta key=value ...] [--allow-partial] --out DATASET
// gaia ingest DIR --manifest clips.csv [--motion video] --out DATASET: every clip of a folder, resumable
#include <algorithm>
#include <cstdio>
#include <memory>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/data/ingest.h"
#include "gaia/data/kitti.h"
#include "gaia/data/manifest.h"
#include "gaia/data/video_io.h"

namespace gaia::app {

namespace {

void print_motion(const data::IngestResult& res, const std::string& prefix) {
  std::string gaps;
  for (auto& [why, n] : res.motion_gaps) gaps += fmt::format("{}{} {}", gaps.empty() ? "" : ", ", n, why);
  std::printf("%smotion from video: %lld of %lld frames given a speed, %.1f ms a frame%s\n", prefix.c_str(),
              (long long)res.frames_estimated, (long long)res.meta.num_frames, res.motion_ms_per_frame,
              gaps.empty() ? "" : (" (no speed or no curvature: " + gaps + ")").c_str());
  if (!res.motion_agreement.empty())
    std::printf("%smotion from video against %s: %s\n", prefix.c_str(), res.meta.signals_source.c_str(),
                res.motion_agreement.c_str());
}

// One line when repeated frames were dropped: how many, and the camera's rate against the container's.
void print_repeats(const data::IngestResult& res, const std::string& name) {
  if (res.repeats_dropped == 0) return;
  std::printf("%s: dropped %lld of %lld frames that repeat the one before (%.4g fps container, %.4g Hz camera)\n",
              name.c_str(), (long long)res.repeats_dropped, (long long)res.frames_decoded, res.container_fps,
              res.meta.fps);
}

// Every clip a manifest lists, one episode each; a clip that fails is one line and the others go on.
void ingest_manifest(const fs::path& dir, const fs::path& manifest_file, const fs::path& out,
                     const data::IngestOptions& base, const Config& c) {
  if (!fs::is_directory(dir)) fail("{}: not a folder of clips", dir.string());
  const fs::path csv = data::find_manifest(manifest_file, dir);
  const data::Manifest m = data::read_manifest(csv, dir);
  if (!base.id.empty()) fail("--id names one clip; a manifest names its clips by file");
  if (base.fps > 0) fail("--fps is for one clip; a manifest states each clip's rate in its 'fps' column");
  int done = 0, skipped = 0;
  std::vector<std::string> failed;
  auto ingested = [&](const data::ManifestRow& row) {
    return !base.overwrite && fs::exists(out / "episodes" / row.id / "episode.json");
  };
  const int64_t already = std::count_if(m.rows.begin(), m.rows.end(), ingested);
  // A resumed run's bar starts at the clips already there: its rate and ETA are of this run's clips.
  ProgressBar bar(int64_t(m.rows.size()), "ingest", true, already);
  for (size_t i = 0; i < m.rows.size(); ++i) {
    const data::ManifestRow& row = m.rows[i];
    if (ingested(row)) {
      ++skipped;
      continue;
    }
    bar.update(already + done + int64_t(failed.size()), row.id);
    try {
      if (!fs::exists(row.path))
        fail("{}:{} (clip {}): column 'file': {} does not exist", m.file.string(), row.line, row.file,
             row.path.string());
      data::IngestOptions o = base;
      o.id = row.id;
      o.meta = row.columns;
      o.caption = [row](double t) { return data::manifest_caption(row, t); };
      o.min_seconds = double(c.world.context_steps - 1) / c.data.world_fps;
      const bool kitti = data::is_kitti_drive(row.path);
      if (row.fps > 0 && !kitti) {
        const double stated = fs::is_directory(row.path) ? 0 : data::VideoSource(row.path).fps();
        if (stated > 0 && std::abs(stated - row.fps) > 0.01 * stated) o.retime_fps = row.fps;
        else o.fps = row.fps;
      }
      auto res = kitti ? data::ingest_kitti(row.path, out, o) : data::ingest_video(row.path, out, o);
      for (auto& w : res.warnings) std::fprintf(stderr, "gaia: warning: %s\n", w.c_str());
      print_repeats(res, row.id);
      if (o.retime_fps > 0)
        std::printf("%s: timed at the manifest's %.4g fps, not the container's\n", row.id.c_str(), o.retime_fps);
      if (o.motion_video) print_motion(res, row.id + ": ");
      ++done;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "gaia: error: %s\n", e.what());
      failed.push_back(row.id);
    }
  }
  bar.finish();
  std::printf("ingested %d clips, %d already there, %zu failed -> %s\n", done, skipped, failed.size(),
              out.string().c_str());
  if (!failed.empty()) {
    std::string names;
    for (auto& f : failed) names += (names.empty() ? "" : ", ") + f;
    fail("{} of {} clips failed ({}); the others are in {}", failed.size(), m.rows.size(), names, out.string());
  }
}

}  // namespace

void register_ingest(CLI::App& app) {
  auto* cmd = app.add_subcommand("ingest", "add a video (file, image directory or KITTI raw drive) as an episode of a "
                                           "dataset");
  auto flags = std::make_shared<SharedFlags>();
  auto video = std::make_shared<std::string>();
  auto opt = std::make_shared<data::IngestOptions>();
  auto signals = std::make_shared<std::string>();
  auto metas = std::make_shared<std::vector<std::string>>();
  cmd->add_option("VIDEO", *video, "video file (anything FFmpeg decodes), a directory of PNG/JPEG frames, or a KITTI "
                  "raw drive (image_02/, oxts/: its speed and yaw rate are read); with --manifest, the folder of "
                  "clips")->required();
  auto manifest = std::make_shared<std::string>();
  cmd->add_option("--manifest", *manifest, "CSV with a row per clip of the folder VIDEO (columns file, fps, weather, "
                  "time_of_day, road, source_repo, place, ...: docs/your-drives.md): every clip ingested, each row's "
                  "columns its metadata and caption; clips already in the dataset are skipped (resumable)");
  auto keep_repeats = std::make_shared<bool>(false);
  cmd->add_flag("--keep-repeats", *keep_repeats, "keep frames that repeat the one before (by default they are "
                "dropped and the true timestamps kept: a 100 fps container holding a 20 Hz camera gives 20 Hz)");
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
  add_shared_flags(cmd, flags.get(), "dataset directory (created if missing)", WithPrecision::kNo);
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
    o.drop_repeats = !*keep_repeats;
    if (!manifest->empty()) {
      ingest_manifest(*video, *manifest, flags->out, o, c);
      return;
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
    print_repeats(res, *video);
    if (o.motion_video) print_motion(res, "");
    const data::EpisodeMeta& m = res.meta;
    std::printf("ingested %s: %lld frames at %.3g fps, resized to %dx%d (the config's data.height x data.width), %s; "
                "signals: %s -> %s/episodes/%s\n", video->c_str(), (long long)m.num_frames, m.fps, m.height, m.width,
                m.frame_codec.c_str(), m.signals_source.empty() ? "none" : m.signals_source.c_str(),
                flags->out.c_str(), m.id.c_str());
  });
}

}  // namespace gaia::app
