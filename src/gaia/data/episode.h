#pragma once
// Episode store (docs/formats.md, schema version 1). A dataset is a directory:
//
//   DATASET/dataset.json              {"format": "gaia-episodes", "schema_version": 1}
//   DATASET/episodes/<id>/episode.json  metadata: fps, size, frame codec, weather, time of day, lat/lon, source
//   DATASET/episodes/<id>/frames.bin    frames at native fps: raw RGB uint8 [N,H,W,3], or concatenated PNG/JPEG
//   DATASET/episodes/<id>/frames_index.npy  int64 [N+1] byte offsets into frames.bin (all codecs)
//   DATASET/episodes/<id>/time_s.npy    float64 [N] timestamps
//   DATASET/episodes/<id>/speed.npy     float32 [N] m/s, NaN = missing (never zero-filled)
//   DATASET/episodes/<id>/curvature.npy float32 [N] 1/m (positive = turning left), NaN = missing
//   DATASET/episodes/<id>/captions.jsonl one JSON string per frame ("" = no caption)
//   DATASET/episodes/<id>/labels.jsonl  optional, one JSON object per frame (structured labels, e.g. synth)
//
// Episodes are written into a staging directory and renamed into place, so a dataset never holds a torn
// episode. Reading streams: frames are decoded one at a time from a memory map; nothing loads a whole dataset.
// Frames need OpenCV: a build without video (cmake -DGAIA_WITH_VIDEO=OFF, which defines GAIA_NO_VIDEO) reads
// episodes' metadata and signals but neither writes nor decodes frames.
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#ifndef GAIA_NO_VIDEO
#include <opencv2/core.hpp>
#endif

#include "gaia/core/fs.h"

namespace gaia::data {

constexpr int kEpisodeSchemaVersion = 1;

// Metadata key of a counterfactual replay (`gaia synth counterfactuals`): the id of the drive it replays.
inline constexpr const char* kReplayOfKey = "replay_of";

struct EpisodeMeta {
  std::string id;                 // directory name; [A-Za-z0-9_.-]
  double fps = 25.0;              // native frame rate (paper §3: 25 Hz)
  int height = 0, width = 0;
  std::string frame_codec = "raw";  // raw | png | jpg
  std::string weather;            // clear, overcast, rain, fog, snow, ... ("" = unknown)
  std::string time_of_day;        // day, dusk, night ("" = unknown)
  double latitude = std::numeric_limits<double>::quiet_NaN();
  double longitude = std::numeric_limits<double>::quiet_NaN();
  std::string source;             // e.g. the video path or "synth:seed=3"
  // Where speed and curvature came from: "csv", "kitti-oxts", "gps", "estimated" (visual odometry), "synth"
  // (the simulator's truth); "" = none or not recorded. Lets balancing and evaluation tell estimates apart.
  std::string signals_source;
  std::map<std::string, std::string> extra;  // free-form --meta key=value pairs
  int64_t num_frames = 0;         // filled by the writer

  nlohmann::json to_json() const;
  static EpisodeMeta from_json(const nlohmann::json& j, const std::string& where);
  bool has_location() const { return latitude == latitude && longitude == longitude; }
  // Whether `extra` holds any of `keys` (the --without-meta filters of calibration and counterfactual replays).
  bool has_any_extra(const std::vector<std::string>& keys) const {
    for (const auto& k : keys)
      if (extra.count(k)) return true;
    return false;
  }
  bool is_replay() const { return extra.count(kReplayOfKey) > 0; }
  // Frames rendered by `gaia synth` (or replayed from its drives) rather than recorded by a camera: the "footage"
  // feature of balancing and the label of the realism probe.
  bool is_procedural() const { return source.rfind("synth:", 0) == 0; }
};

#ifndef GAIA_NO_VIDEO
// Per-frame record handed to the writer. Frames are BGR CV_8UC3 (OpenCV's convention) of the episode's size.
struct FrameRecord {
  cv::Mat bgr;
  double time_s = 0;
  float speed = std::numeric_limits<float>::quiet_NaN();      // NaN = missing
  float curvature = std::numeric_limits<float>::quiet_NaN();  // NaN = missing
  std::string caption;
  nlohmann::json labels;  // null when absent
};
#endif

// Creates DATASET/dataset.json if needed (atomically) and checks an existing one.
void ensure_dataset(const fs::path& dataset);

class EpisodeWriter {
 public:
  // Streams frames to a staging directory inside DATASET/episodes; commit() renames it into place.
  EpisodeWriter(const fs::path& dataset, EpisodeMeta meta, bool overwrite = false);
  ~EpisodeWriter();
#ifndef GAIA_NO_VIDEO
  void append(const FrameRecord& f);
#endif
  int64_t frames_written() const { return static_cast<int64_t>(times_.size()); }
  void commit();  // throws if no frames were written
  const EpisodeMeta& meta() const { return meta_; }
  const std::vector<float>& speeds() const { return speed_; }          // of the frames appended so far
  const std::vector<float>& curvatures() const { return curvature_; }
  // Replaces every frame's speed and curvature before commit (ego-motion estimated once all frames are seen),
  // with a per-frame confidence in [0, 1] (motion_confidence.npy) and the new signals_source.
  void set_signals(const std::vector<float>& speed, const std::vector<float>& curvature,
                   const std::vector<float>& confidence, const std::string& source);

 private:
  fs::path dataset_;
  EpisodeMeta meta_;
  bool overwrite_;
  std::unique_ptr<StagingDir> staging_;
  FILE* frames_ = nullptr;
  int64_t offset_ = 0;
  std::vector<int64_t> offsets_{0};
  std::vector<double> times_;
  std::vector<float> speed_, curvature_, confidence_;
  std::vector<std::string> captions_;
  std::vector<nlohmann::json> labels_;
  bool any_labels_ = false;
};

class Episode {
 public:
  explicit Episode(const fs::path& dir);  // validates sizes of every array against num_frames
  const EpisodeMeta& meta() const { return meta_; }
  int64_t size() const { return meta_.num_frames; }
#ifndef GAIA_NO_VIDEO
  cv::Mat frame_bgr(int64_t i) const;  // random access, decoded on demand
#endif
  double time_s(int64_t i) const { return times_.at(static_cast<size_t>(i)); }
  float speed(int64_t i) const { return speed_.at(static_cast<size_t>(i)); }
  float curvature(int64_t i) const { return curvature_.at(static_cast<size_t>(i)); }
  const std::string& caption(int64_t i) const { return captions_.at(static_cast<size_t>(i)); }
  bool has_labels() const { return !labels_.empty(); }
  const nlohmann::json& labels(int64_t i) const { return labels_.at(static_cast<size_t>(i)); }
  const std::vector<double>& times() const { return times_; }
  const std::vector<float>& speeds() const { return speed_; }
  const std::vector<float>& curvatures() const { return curvature_; }
  const fs::path& dir() const { return dir_; }

 private:
  fs::path dir_;
  EpisodeMeta meta_;
  std::shared_ptr<MappedFile> frames_;
  std::vector<int64_t> offsets_;
  std::vector<double> times_;
  std::vector<float> speed_, curvature_;
  std::vector<std::string> captions_;
  std::vector<nlohmann::json> labels_;
};

// A dataset directory: the list of episode ids plus lazy access to each episode.
class Dataset {
 public:
  explicit Dataset(const fs::path& root);  // throws naming the path if it is not a gaia dataset
  const std::vector<std::string>& ids() const { return ids_; }
  size_t size() const { return ids_.size(); }
  Episode episode(size_t i) const { return Episode(root_ / "episodes" / ids_.at(i)); }
  EpisodeMeta meta(size_t i) const;  // reads episode.json only (cheap)
  const fs::path& root() const { return root_; }

 private:
  fs::path root_;
  std::vector<std::string> ids_;
};

}  // namespace gaia::data
