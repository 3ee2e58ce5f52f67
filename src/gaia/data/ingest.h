#pragma once
// `gaia ingest`: a video (+ optional signals CSV and metadata) becomes one episode of a dataset.
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "gaia/data/episode.h"

namespace gaia::data {

inline constexpr double kMaxIngestFps = 1000;  // --fps must lie in (0, kMaxIngestFps]
// Containers over- or under-state their frame count by a frame or two; fewer decoded than this below the stated
// count is a truncated or damaged file.
inline constexpr int64_t kFrameCountTolerance = 2;
// Below this fraction of frames with a speed, ingest warns that the CSV hardly covers the clip.
inline constexpr double kLowSignalCoverage = 0.5;

struct IngestOptions {
  int height = 72, width = 128;     // from the config's data.height / data.width
  double fps = 0;                   // 0 = the container's; else in (0, 1000] (required for image directories)
  fs::path signals;                 // optional time_s,speed,curvature[,caption] CSV
  std::map<std::string, std::string> meta;  // weather, time_of_day, latitude, longitude, source, anything else
  std::string id;                   // episode id; default: the video's file name stem
  std::string frame_codec = "jpg";  // raw | png | jpg
  int64_t max_frames = 0;           // 0 = all
  bool overwrite = false;
  bool allow_partial = false;       // keep the frames of a truncated/damaged video (a warning) instead of failing
};

struct IngestResult {
  EpisodeMeta meta;
  int64_t container_frames = 0;     // the frame count the container states (0 = none)
  int64_t frames_with_speed = 0;    // frames that got a speed from the signals CSV
  double signal_coverage = 0;       // frames_with_speed / frames; 0 without a CSV
  std::vector<std::string> warnings;  // one line each, for the app to print as "gaia: warning: ..."
};

// Streams the video into a staging episode (nothing is kept in memory) and commits it atomically. Fails, leaving
// no episode, when the video decodes to fewer frames than its container states (unless allow_partial) or when a
// signals CSV gives no frame a speed; warns when it covers fewer than kLowSignalCoverage of them.
IngestResult ingest_video(const fs::path& video, const fs::path& dataset, const IngestOptions& opt,
                          const std::function<void(int64_t done, int64_t total)>& progress = {});

// Applies --meta key=value pairs to the typed fields (latitude/longitude must parse as numbers).
void apply_meta(EpisodeMeta* m, const std::map<std::string, std::string>& kv);

}  // namespace gaia::data
