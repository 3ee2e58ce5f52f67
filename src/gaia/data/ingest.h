#pragma once
// `gaia ingest`: a video (+ optional signals CSV and metadata) becomes one episode of a dataset.
#include <functional>
#include <map>
#include <string>

#include "gaia/data/episode.h"

namespace gaia::data {

struct IngestOptions {
  int height = 72, width = 128;     // from the config's data.height / data.width
  double fps = 0;                   // > 0 overrides the container (required for image directories)
  fs::path signals;                 // optional time_s,speed,curvature[,caption] CSV
  std::map<std::string, std::string> meta;  // weather, time_of_day, latitude, longitude, source, anything else
  std::string id;                   // episode id; default: the video's file name stem
  std::string frame_codec = "jpg";  // raw | png | jpg
  int64_t max_frames = 0;           // 0 = all
  bool overwrite = false;
};

// Streams the video into a staging episode (nothing is kept in memory) and commits it atomically.
EpisodeMeta ingest_video(const fs::path& video, const fs::path& dataset, const IngestOptions& opt,
                         const std::function<void(int64_t done, int64_t total)>& progress = {});

// Applies --meta key=value pairs to the typed fields (latitude/longitude must parse as numbers).
void apply_meta(EpisodeMeta* m, const std::map<std::string, std::string>& kv);

}  // namespace gaia::data
