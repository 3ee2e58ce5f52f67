#pragma once
// `gaia ingest`: a video (+ optional signals CSV and metadata) becomes one episode of a dataset.
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "gaia/data/episode.h"
#include "gaia/data/motion.h"

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
  fs::path gps;                     // optional GPS track (NMEA or GPX; data/gps.h) instead of a CSV
  double gps_offset = 0;            // video time 0 is this many seconds after the track's first fix
  fs::path poses;                   // camera poses (KITTI odometry poses.txt: data/kitti.h), one per frame
  std::map<std::string, std::string> meta;  // weather, time_of_day, latitude, longitude, source, anything else
  std::string id;                   // episode id; default: the video's file name stem
  std::string frame_codec = "jpg";  // raw | png | jpg
  int64_t max_frames = 0;           // 0 = all
  bool overwrite = false;
  bool allow_partial = false;       // keep the frames of a truncated/damaged video (a warning) instead of failing
  // Drop frames that repeat the one before (data/repeats.h) and keep the true timestamps; the episode's fps
  // becomes the camera's. Video files and image directories; a KITTI drive's frames are the camera's own.
  bool drop_repeats = true;
  // A frame rate that replaces the container's, timing frames by index (a manifest's stated rate for a container
  // whose own is wrong); 0 = none. Unlike `fps`, it may disagree with the rate the video states.
  double retime_fps = 0;
  std::function<std::string(double time_s)> caption;  // each frame's caption where the signals give none
  double min_seconds = 0;           // fail (writing nothing) when the kept frames span less than this
  // --motion video: estimate speed and curvature from the frames at their recorded resolution (data/motion.h).
  // Without other signals they become the episode's (signals_source "estimated"); beside them, ingest reports
  // how far the two agree and keeps the measured ones.
  bool motion_video = false;
  MotionOptions motion;
  CameraIntrinsics camera;          // known intrinsics (KITTI calib); else from motion.hfov_deg
};

struct IngestResult {
  EpisodeMeta meta;
  int64_t container_frames = 0;     // the frame count the container states (0 = none)
  int64_t frames_decoded = 0;       // frames the source gave, repeats included
  int64_t repeats_dropped = 0;      // frames that repeated the one before (drop_repeats)
  double container_fps = 0;         // the rate the source states (or --fps); meta.fps is the camera's
  int64_t frames_with_speed = 0;    // frames that got a speed from the signals (CSV, GPS, KITTI OXTS)
  double signal_coverage = 0;       // frames_with_speed / frames; 0 without signals
  std::vector<std::string> warnings;  // one line each, for the app to print as "gaia: warning: ..."
  // With motion_video: the estimate, and its agreement with the measured signals when there were any.
  int64_t frames_estimated = 0;       // frames given a speed by the estimate
  double motion_ms_per_frame = 0;
  std::string motion_agreement;       // "" without measured signals
  std::map<std::string, int64_t> motion_gaps;  // reason -> frames without an estimated speed or curvature
};

// Streams the video into a staging episode (nothing is kept in memory) and commits it atomically. Fails, leaving
// no episode, when the video decodes to fewer frames than its container states (unless allow_partial), when the
// signals (CSV or GPS track) give no frame a speed, or when the dataset's episodes have another frame size; warns
// when the signals cover fewer than kLowSignalCoverage of the frames.
IngestResult ingest_video(const fs::path& video, const fs::path& dataset, const IngestOptions& opt,
                          const std::function<void(int64_t done, int64_t total)>& progress = {});

// A KITTI raw drive (data/kitti.h): its camera images at their recorded times, OXTS speed and curvature
// (signals_source "kitti-oxts"), the first fix's latitude/longitude. A drive without oxts/ fails unless
// opt.signals or opt.gps gives the signals instead. --fps is the drive's own (from its timestamps).
IngestResult ingest_kitti(const fs::path& drive, const fs::path& dataset, const IngestOptions& opt,
                          const std::function<void(int64_t done, int64_t total)>& progress = {});

// Applies --meta key=value pairs to the typed fields (latitude/longitude must parse as numbers).
void apply_meta(EpisodeMeta* m, const std::map<std::string, std::string>& kv);

}  // namespace gaia::data
