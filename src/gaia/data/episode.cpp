#include "gaia/data/episode.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>

#ifndef GAIA_NO_VIDEO
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#endif

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/core/npy.h"

namespace gaia::data {

using nlohmann::json;

namespace {

json nan_to_null(double v) { return std::isnan(v) ? json(nullptr) : json(v); }

double null_to_nan(const json& j) {
  return j.is_number() ? j.get<double>() : std::numeric_limits<double>::quiet_NaN();
}

// An id is one safe path component: it names a directory under DATASET/episodes, and names starting with '.'
// are reserved for staging directories (and would make `.`/`..` escape the dataset).
void check_episode_id(const std::string& id) {
  // A loop, not std::regex: the regex recurses per character and a long id from a file would overflow the stack.
  auto ok_char = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.'; };
  const bool ok = !id.empty() && id.size() <= 200 && id[0] != '.' && std::all_of(id.begin(), id.end(), ok_char);
  if (!ok)
    fail("episode id '{}' must be 1-200 letters, digits, '-', '_' and '.', and must not start with '.'",
         id.substr(0, 240));
}

// An integer field in [lo, hi]: a float (1e10) or an out-of-range number is an error, never a wrapped int.
int64_t integer_field(const json& j, const char* key, int64_t lo, int64_t hi, const std::string& where) {
  const json& v = j.at(key);
  if (!v.is_number_integer()) fail("{}: '{}' must be an integer, got {}", where, key, v.dump());
  // nlohmann keeps non-negative numbers unsigned: compare in the number's own type.
  const bool ok = v.is_number_unsigned()
                      ? v.get<uint64_t>() <= uint64_t(hi) && (lo <= 0 || v.get<uint64_t>() >= uint64_t(lo))
                      : v.get<int64_t>() >= lo && v.get<int64_t>() <= hi;
  if (!ok) fail("{}: '{}' = {} is out of range [{}, {}]", where, key, v.dump(), lo, hi);
  return v.get<int64_t>();
}

}  // namespace

json EpisodeMeta::to_json() const {
  json j = {{"schema_version", kEpisodeSchemaVersion},
            {"id", id},
            {"fps", fps},
            {"height", height},
            {"width", width},
            {"frame_codec", frame_codec},
            {"num_frames", num_frames},
            {"weather", weather},
            {"time_of_day", time_of_day},
            {"latitude", nan_to_null(latitude)},
            {"longitude", nan_to_null(longitude)},
            {"source", source},
            {"extra", extra}};
  if (!signals_source.empty()) j["signals_source"] = signals_source;
  return j;
}

EpisodeMeta EpisodeMeta::from_json(const json& j, const std::string& where) {
  EpisodeMeta m;
  try {
    const int64_t v = integer_field(j, "schema_version", 0, 1 << 20, where);
    if (v != kEpisodeSchemaVersion) fail("{}: schema_version {} is not supported (this gaia reads {})", where, v, kEpisodeSchemaVersion);
    m.id = j.at("id").get<std::string>();
    m.fps = j.at("fps").get<double>();
    m.height = int(integer_field(j, "height", 1, 16384, where));
    m.width = int(integer_field(j, "width", 1, 16384, where));
    m.frame_codec = j.at("frame_codec").get<std::string>();
    m.num_frames = integer_field(j, "num_frames", 0, int64_t(1) << 40, where);
    m.weather = j.value("weather", "");
    m.time_of_day = j.value("time_of_day", "");
    m.latitude = null_to_nan(j.value("latitude", json(nullptr)));
    m.longitude = null_to_nan(j.value("longitude", json(nullptr)));
    m.source = j.value("source", "");
    m.signals_source = j.value("signals_source", "");
    if (j.contains("extra")) m.extra = j.at("extra").get<std::map<std::string, std::string>>();
  } catch (const json::exception& e) {
    fail("{}: bad episode metadata ({})", where, e.what());
  }
  check_episode_id(m.id);
  if (!(m.fps > 0 && m.fps <= 1000)) fail("{}: fps must be in (0, 1000], got {}", where, m.fps);
  if (!(std::isnan(m.latitude) || std::abs(m.latitude) <= 90) || !(std::isnan(m.longitude) || std::abs(m.longitude) <= 180))
    fail("{}: latitude must be in [-90, 90] and longitude in [-180, 180] (or null)", where);
  if (m.height <= 0 || m.width <= 0) fail("{}: height/width must be positive", where);
  if (m.frame_codec != "raw" && m.frame_codec != "png" && m.frame_codec != "jpg")
    fail("{}: frame_codec '{}' is not raw, png or jpg", where, m.frame_codec);
  return m;
}

void ensure_dataset(const fs::path& dataset) {
  fs::path f = dataset / "dataset.json";
  if (fs::exists(f)) {
    json j = read_json(f);
    if (j.value("format", "") != "gaia-episodes")
      fail("{}: not a gaia episode dataset (format is '{}')", f.string(), j.value("format", ""));
    return;
  }
  if (fs::exists(dataset) && !fs::is_directory(dataset)) fail("{}: exists and is not a directory", dataset.string());
  fs::create_directories(dataset / "episodes");
  write_file_atomic(f, json({{"format", "gaia-episodes"}, {"schema_version", kEpisodeSchemaVersion}}).dump(2) + "\n");
}

EpisodeWriter::EpisodeWriter(const fs::path& dataset, EpisodeMeta meta, bool overwrite)
    : dataset_(dataset), meta_(std::move(meta)), overwrite_(overwrite) {
  check_episode_id(meta_.id);
  if (meta_.height <= 0 || meta_.width <= 0) fail("episode {}: height and width must be set", meta_.id);
  if (meta_.frame_codec != "raw" && meta_.frame_codec != "png" && meta_.frame_codec != "jpg")
    fail("episode {}: frame codec '{}' is not raw, png or jpg", meta_.id, meta_.frame_codec);
  ensure_dataset(dataset_);
  remove_stale_temporaries(dataset_ / "episodes");  // what killed writers left behind
  fs::path final_dir = dataset_ / "episodes" / meta_.id;
  if (fs::exists(final_dir) && !overwrite_) fail("{}: episode already exists", final_dir.string());
  staging_ = std::make_unique<StagingDir>(final_dir);
  frames_ = std::fopen((staging_->path() / "frames.bin").c_str(), "wb");
  if (!frames_) fail("{}: cannot create frames.bin", staging_->path().string());
}

EpisodeWriter::~EpisodeWriter() {
  if (frames_) std::fclose(frames_);
}

#ifndef GAIA_NO_VIDEO
void EpisodeWriter::append(const FrameRecord& f) {
  if (f.bgr.type() != CV_8UC3 || f.bgr.rows != meta_.height || f.bgr.cols != meta_.width)
    fail("episode {}: frame {} is {}x{} (type {}), expected {}x{} BGR uint8", meta_.id, times_.size(), f.bgr.rows,
         f.bgr.cols, f.bgr.type(), meta_.height, meta_.width);
  if (!times_.empty() && !(f.time_s > times_.back()))
    fail("episode {}: timestamps must increase (frame {} at {} s)", meta_.id, times_.size(), f.time_s);
  std::vector<uchar> buf;
  if (meta_.frame_codec == "raw") {
    cv::Mat rgb;
    cv::cvtColor(f.bgr, rgb, cv::COLOR_BGR2RGB);
    buf.assign(rgb.data, rgb.data + rgb.total() * 3);
  } else if (meta_.frame_codec == "png") {
    cv::imencode(".png", f.bgr, buf, {cv::IMWRITE_PNG_COMPRESSION, 1});
  } else {
    cv::imencode(".jpg", f.bgr, buf, {cv::IMWRITE_JPEG_QUALITY, 95});
  }
  if (std::fwrite(buf.data(), 1, buf.size(), frames_) != buf.size())
    fail("{}: write failed (disk full?)", (staging_->path() / "frames.bin").string());
  offset_ += static_cast<int64_t>(buf.size());
  offsets_.push_back(offset_);
  times_.push_back(f.time_s);
  speed_.push_back(f.speed);
  curvature_.push_back(f.curvature);
  captions_.push_back(f.caption);
  labels_.push_back(f.labels);
  if (!f.labels.is_null()) any_labels_ = true;
}
#endif

void EpisodeWriter::set_signals(const std::vector<float>& speed, const std::vector<float>& curvature,
                                const std::vector<float>& confidence, const std::string& source) {
  if (speed.size() != times_.size() || curvature.size() != times_.size() || confidence.size() != times_.size())
    fail("episode {}: {} signal values for {} frames", meta_.id, speed.size(), times_.size());
  speed_ = speed;
  curvature_ = curvature;
  confidence_ = confidence;
  meta_.signals_source = source;
}

void EpisodeWriter::commit() {
  if (times_.empty()) fail("episode {}: no frames were written", meta_.id);
  std::fclose(frames_);
  frames_ = nullptr;
  const fs::path& d = staging_->path();
  const int64_t n = static_cast<int64_t>(times_.size());
  meta_.num_frames = n;
  npy_write(d / "frames_index.npy", npy_make(DType::I64, {n + 1}, offsets_));
  npy_write(d / "time_s.npy", npy_make(DType::F64, {n}, times_));
  npy_write(d / "speed.npy", npy_make(DType::F32, {n}, speed_));
  npy_write(d / "curvature.npy", npy_make(DType::F32, {n}, curvature_));
  if (!confidence_.empty()) npy_write(d / "motion_confidence.npy", npy_make(DType::F32, {n}, confidence_));
  std::string caps;
  for (auto& c : captions_) caps += json(c).dump() + "\n";
  write_file_atomic(d / "captions.jsonl", caps);
  if (any_labels_) {
    std::string lab;
    for (auto& l : labels_) lab += l.dump() + "\n";
    write_file_atomic(d / "labels.jsonl", lab);
  }
  write_file_atomic(d / "episode.json", meta_.to_json().dump(2) + "\n");  // written last: marks completeness
  staging_->commit(overwrite_);
}


Episode::Episode(const fs::path& dir) : dir_(dir) {
  fs::path mf = dir / "episode.json";
  if (!fs::exists(mf)) fail("{}: missing (not a complete episode)", mf.string());
  meta_ = EpisodeMeta::from_json(read_json(mf), mf.string());
  const size_t n = static_cast<size_t>(meta_.num_frames);
  auto check_len = [&](const fs::path& p, size_t got, size_t want) {
    if (got != want) fail("{}: has {} entries, episode.json says {}", p.string(), got, want);
  };
  offsets_ = npy_read(dir / "frames_index.npy").to_int64();
  check_len(dir / "frames_index.npy", offsets_.size(), n + 1);
  times_ = npy_read(dir / "time_s.npy").to_double();
  check_len(dir / "time_s.npy", times_.size(), n);
  for (const char* name : {"speed.npy", "curvature.npy"}) {
    std::vector<double> v = npy_read(dir / name).to_double();
    check_len(dir / name, v.size(), n);
    (std::string(name) == "speed.npy" ? speed_ : curvature_).assign(v.begin(), v.end());
  }
  captions_.clear();
  for (auto& line : read_lines(dir / "captions.jsonl")) {
    try {
      captions_.push_back(json::parse(line).get<std::string>());
    } catch (const std::exception&) {
      fail("{}: line {} is not a JSON string", (dir / "captions.jsonl").string(), captions_.size() + 1);
    }
  }
  check_len(dir / "captions.jsonl", captions_.size(), n);
  if (fs::exists(dir / "labels.jsonl")) {
    for (auto& line : read_lines(dir / "labels.jsonl")) {
      try {
        labels_.push_back(json::parse(line));
      } catch (const std::exception&) {
        fail("{}: line {} is not JSON", (dir / "labels.jsonl").string(), labels_.size() + 1);
      }
    }
    check_len(dir / "labels.jsonl", labels_.size(), n);
  }
  frames_ = std::make_shared<MappedFile>(dir / "frames.bin");
  if (static_cast<size_t>(offsets_.back()) != frames_->size())
    fail("{}: {} bytes, index expects {} (truncated?)", (dir / "frames.bin").string(), frames_->size(), offsets_.back());
  if (meta_.frame_codec == "raw") {
    const int64_t fb = int64_t(meta_.height) * meta_.width * 3;
    for (size_t i = 0; i < n; ++i)
      if (offsets_[i + 1] - offsets_[i] != fb) fail("{}: frame {} has the wrong size for raw {}x{}", (dir / "frames_index.npy").string(), i, meta_.height, meta_.width);
  }
}

#ifndef GAIA_NO_VIDEO
cv::Mat Episode::frame_bgr(int64_t i) const {
  if (i < 0 || i >= meta_.num_frames) fail("{}: frame {} out of range [0, {})", dir_.string(), i, meta_.num_frames);
  const uint8_t* p = frames_->data() + offsets_[static_cast<size_t>(i)];
  const size_t len = static_cast<size_t>(offsets_[static_cast<size_t>(i) + 1] - offsets_[static_cast<size_t>(i)]);
  cv::Mat out;
  if (meta_.frame_codec == "raw") {
    cv::Mat rgb(meta_.height, meta_.width, CV_8UC3, const_cast<uint8_t*>(p));
    cv::cvtColor(rgb, out, cv::COLOR_RGB2BGR);
  } else {
    out = cv::imdecode(cv::Mat(1, static_cast<int>(len), CV_8U, const_cast<uint8_t*>(p)), cv::IMREAD_COLOR);
    if (out.empty() || out.rows != meta_.height || out.cols != meta_.width)
      fail("{}: frame {} cannot be decoded (corrupt frames.bin?)", dir_.string(), i);
  }
  return out;
}
#endif

Dataset::Dataset(const fs::path& root) : root_(root) {
  if (!fs::exists(root)) fail("{}: no such dataset directory", root.string());
  fs::path f = root / "dataset.json";
  if (!fs::exists(f)) fail("{}: not a gaia dataset (no dataset.json; create one with gaia ingest or gaia synth)", root.string());
  json j = read_json(f);
  if (j.value("format", "") != "gaia-episodes") fail("{}: format is not gaia-episodes", f.string());
  if (fs::exists(root / "episodes"))
    for (auto& e : fs::directory_iterator(root / "episodes")) {
      std::string name = e.path().filename().string();
      // Staging and moved-aside copies (".tmp-id-PID-N", "id.old-PID-N") are not episodes.
      if (e.is_directory() && temporary_owner(name) == 0 && fs::exists(e.path() / "episode.json")) ids_.push_back(name);
    }
  std::sort(ids_.begin(), ids_.end());
}

EpisodeMeta Dataset::meta(size_t i) const {
  fs::path mf = root_ / "episodes" / ids_.at(i) / "episode.json";
  return EpisodeMeta::from_json(read_json(mf), mf.string());
}

}  // namespace gaia::data
