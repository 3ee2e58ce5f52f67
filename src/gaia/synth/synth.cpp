#include "gaia/synth/synth.h"

#include <cmath>
#include <cstdlib>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "gaia/core/error.h"
#include "gaia/synth/caption.h"
#include "gaia/synth/rng.h"

namespace gaia::synth {

namespace {

constexpr const char* kSynthVersion = "1";

SceneSpec spec_from(const SynthOptions& o, int index) {
  if (o.height < 16 || o.width < 16 || o.height > 4096 || o.width > 4096)
    fail("synth: frame size {}x{} must be between 16 and 4096", o.height, o.width);
  SceneSpec s;
  s.seed = o.seed;
  s.index = index;
  s.district = o.district;
  s.weather = o.weather;
  s.time_of_day = o.time_of_day;
  s.scene = o.scene;
  s.fps = o.fps;
  s.seconds = o.seconds;
  s.wander = o.wander;
  s.swerve = o.swerve;
  s.change_at = o.change_at;
  s.change_lead = o.change_lead;
  s.change_weather = o.change_weather;
  s.change_time_of_day = o.change_time_of_day;
  return resolve_spec(s);
}

int64_t num_frames(const SynthOptions& o) { return std::max<int64_t>(1, std::llround(o.seconds * o.fps)); }

const std::string& need(const data::EpisodeMeta& m, const std::string& key, const fs::path& where) {
  auto it = m.extra.find(key);
  if (it == m.extra.end())
    fail("{}: not a synth episode (extra.{} is missing), so it cannot be replayed", where.string(), key);
  return it->second;
}

double parse_double(const std::string& s, const std::string& what) {
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || end != s.c_str() + s.size() || !std::isfinite(v)) fail("{}: '{}' is not a finite number", what, s);
  return v;
}

}  // namespace

std::string episode_id(uint64_t seed, int index) { return fmt::format("synth-s{}-e{:05d}", seed, index); }

Simulator::Simulator(const SynthOptions& opt, int index)
    : opt_(opt), index_(index), world_(std::make_unique<Scene>(spec_from(opt, index))), renderer_(opt.height, opt.width) {}

data::EpisodeMeta Simulator::meta() const {
  const SceneSpec& s = world_->spec();
  data::EpisodeMeta m;
  m.id = episode_id(s.seed, s.index);
  m.fps = s.fps;
  m.height = opt_.height;
  m.width = opt_.width;
  m.frame_codec = opt_.frame_codec;
  m.weather = s.weather;
  m.time_of_day = s.time_of_day;
  const District& d = world_->district();
  Rng r(stream_key(s.seed, static_cast<uint64_t>(s.index), "location"));
  const double a = r.uniform(0, 2 * kPi), rad = d.radius_deg * std::sqrt(r.uniform());
  m.latitude = d.lat + rad * std::sin(a);
  m.longitude = d.lon + rad * std::cos(a) / std::cos(d.lat * kPi / 180);
  m.source = fmt::format("synth:seed={},episode={}", s.seed, s.index);
  m.signals_source = "synth";  // the simulator's own speed and curvature
  m.extra["synth_version"] = kSynthVersion;
  m.extra["synth_seed"] = std::to_string(s.seed);
  m.extra["synth_index"] = std::to_string(s.index);
  m.extra["synth_seconds"] = fmt::format("{}", s.seconds);
  m.extra["synth_scene"] = s.scene;
  if (s.wander > 0) m.extra["synth_wander"] = fmt::format("{}", s.wander);
  if (s.swerve > 0) m.extra["synth_swerve"] = fmt::format("{}", s.swerve);
  m.extra["synth_district"] = s.district;
  if (s.change_at > 0) {  // the episode's weather and time_of_day are its start's; the frames' labels follow the change
    m.extra["synth_change_at"] = fmt::format("{}", s.change_at);
    m.extra["synth_change_lead"] = fmt::format("{}", s.change_lead);
    m.extra["synth_change_weather"] = s.change_weather;
    m.extra["synth_change_time_of_day"] = s.change_time_of_day;
  }
  m.extra["district"] = s.district;
  m.extra["lanes"] = std::to_string(world_->layout().lanes_fwd);
  return m;
}

cv::Mat Simulator::render() {
  cv::Mat img;
  renderer_.render(*world_, img);
  return img;
}

data::FrameRecord Simulator::record(const ActionStep& a, bool with_image) {
  data::FrameRecord f;
  if (with_image) f.bgr = render();
  f.time_s = world_->time();
  f.speed = static_cast<float>(a.speed);
  f.curvature = static_cast<float>(a.curvature);
  f.labels = world_->labels(a);
  const SceneSpec& s = world_->spec();
  // What the caption names: the labels, or the change's conditions from change_lead before it (a copy only then).
  nlohmann::json said;
  const nlohmann::json* named = &f.labels;
  if (world_->caption_changed()) {
    said = f.labels;
    if (!s.change_weather.empty()) said["weather"] = s.change_weather;
    if (!s.change_time_of_day.empty()) said["time_of_day"] = s.change_time_of_day;
    named = &said;
  }
  f.caption = make_caption(*named, stream_key(s.seed, static_cast<uint64_t>(s.index), "caption",
                                              static_cast<uint64_t>(world_->frame())));
  return f;
}

data::EpisodeMeta write_episode(const fs::path& dataset, const SynthOptions& opt, int index,
                                std::function<void(int64_t, int64_t)> progress) {
  Simulator sim(opt, index);
  data::EpisodeWriter writer(dataset, sim.meta(), opt.overwrite);
  const int64_t n = num_frames(opt);
  for (int64_t i = 0; i < n; ++i) {
    const ActionStep a = sim.policy();
    writer.append(sim.record(a));
    sim.step(a);
    if (progress) progress(i + 1, n);
  }
  writer.commit();
  return writer.meta();
}

data::EpisodeMeta replay(const data::Episode& original, int64_t from, const std::vector<ActionStep>& actions,
                         const fs::path& out_dataset, const std::string& out_id, bool overwrite) {
  const data::EpisodeMeta& m = original.meta();
  const fs::path where = original.dir();
  SynthOptions o;
  o.height = m.height;
  o.width = m.width;
  o.fps = m.fps;
  o.frame_codec = m.frame_codec;
  o.weather = m.weather;
  o.time_of_day = m.time_of_day;
  const std::string& version = need(m, "synth_version", where);
  if (version != kSynthVersion) fail("{}: synth_version {} cannot be replayed by this gaia (version {})", where.string(), version, kSynthVersion);
  o.seed = std::strtoull(need(m, "synth_seed", where).c_str(), nullptr, 10);
  const int index = static_cast<int>(parse_double(need(m, "synth_index", where), where.string() + ": synth_index"));
  o.seconds = parse_double(need(m, "synth_seconds", where), where.string() + ": synth_seconds");
  o.scene = need(m, "synth_scene", where);
  o.district = need(m, "synth_district", where);
  if (auto w = m.extra.find("synth_wander"); w != m.extra.end())
    o.wander = parse_double(w->second, where.string() + ": synth_wander");
  if (auto w = m.extra.find("synth_swerve"); w != m.extra.end())
    o.swerve = parse_double(w->second, where.string() + ": synth_swerve");
  if (auto c = m.extra.find("synth_change_at"); c != m.extra.end()) {
    o.change_at = parse_double(c->second, where.string() + ": synth_change_at");
    o.change_lead = parse_double(need(m, "synth_change_lead", where), where.string() + ": synth_change_lead");
    o.change_weather = need(m, "synth_change_weather", where);
    o.change_time_of_day = need(m, "synth_change_time_of_day", where);
  }
  o.overwrite = overwrite;
  // A replay starts mid-drive, so its recorded actions cannot rebuild the world from the start: replay its source.
  if (m.is_replay())
    fail("{}: is itself a replay (of {}); replay that episode instead", where.string(), m.extra.at(data::kReplayOfKey));
  if (from < 0 || from > original.size())
    fail("{}: replay start frame {} is outside [0, {}]", where.string(), from, original.size());
  if (actions.empty()) fail("replay of {}: no actions given", m.id);
  for (size_t i = 0; i < actions.size(); ++i)
    if (!std::isfinite(actions[i].speed) || !std::isfinite(actions[i].curvature) || actions[i].speed < 0 ||
        actions[i].speed > 70 || std::abs(actions[i].curvature) > 1)
      fail("replay of {}: action {} (speed {}, curvature {}) is out of range (speed 0..70 m/s, |curvature| <= 1/m)",
           m.id, i, actions[i].speed, actions[i].curvature);
  Simulator sim(o, index);
  for (int64_t i = 0; i < from; ++i) {
    const float sp = original.speed(i), cu = original.curvature(i);
    if (!std::isfinite(sp) || !std::isfinite(cu)) fail("{}: frame {} has no recorded action", where.string(), i);
    sim.step({static_cast<double>(sp), static_cast<double>(cu)});
  }
  data::EpisodeMeta meta = sim.meta();
  meta.id = out_id;
  meta.source = m.source + fmt::format(",replay_from={}", from);
  meta.extra[data::kReplayOfKey] = m.id;
  meta.extra["replay_from"] = std::to_string(from);
  data::EpisodeWriter writer(out_dataset, meta, overwrite);
  for (const ActionStep& a0 : actions) {
    const ActionStep a{static_cast<double>(static_cast<float>(a0.speed)), static_cast<double>(static_cast<float>(a0.curvature))};
    writer.append(sim.record(a));
    sim.step(a);
  }
  writer.commit();
  return writer.meta();
}

std::vector<ActionStep> read_actions_csv(const fs::path& csv) {
  const std::string text = read_file(csv);
  std::istringstream in(text);
  std::string line;
  int lineno = 0, i_speed = -1, i_curv = -1;
  size_t ncols = 0;
  std::vector<ActionStep> out;
  auto split = [](const std::string& l) {
    std::vector<std::string> cols;
    std::string cur;
    for (char c : l) {
      if (c == ',') cols.push_back(cur), cur.clear();
      else if (c != '\r') cur += c;
    }
    cols.push_back(cur);
    for (auto& c : cols) {
      const size_t a = c.find_first_not_of(" \t"), b = c.find_last_not_of(" \t");
      c = a == std::string::npos ? "" : c.substr(a, b - a + 1);
    }
    return cols;
  };
  while (std::getline(in, line)) {
    ++lineno;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const auto cols = split(line);
    if (i_speed < 0) {
      for (size_t i = 0; i < cols.size(); ++i) {
        if (cols[i] == "speed") i_speed = static_cast<int>(i);
        if (cols[i] == "curvature") i_curv = static_cast<int>(i);
      }
      if (i_speed < 0 || i_curv < 0)
        fail("{}:{}: the header must name the columns speed and curvature (got '{}')", csv.string(), lineno, line);
      ncols = cols.size();
      continue;
    }
    if (cols.size() != ncols)
      fail("{}:{}: {} columns, the header has {}", csv.string(), lineno, cols.size(), ncols);
    const std::string at = fmt::format("{}:{}", csv.string(), lineno);
    ActionStep a;
    a.speed = parse_double(cols[static_cast<size_t>(i_speed)], at + ": speed");
    a.curvature = parse_double(cols[static_cast<size_t>(i_curv)], at + ": curvature");
    if (a.speed < 0) fail("{}: speed {} is negative", at, a.speed);
    out.push_back(a);
  }
  if (i_speed < 0) fail("{}: empty file (expected a header with speed,curvature)", csv.string());
  if (out.empty()) fail("{}: no actions after the header", csv.string());
  return out;
}

cv::Mat preview_frame(const SynthOptions& opt, int index, double t_seconds) {
  Simulator sim(opt, index);
  const int64_t n = std::llround(t_seconds * opt.fps);
  for (int64_t i = 0; i < n; ++i) sim.step(sim.policy());
  return sim.render();
}

cv::Mat contact_sheet(const std::vector<cv::Mat>& frames, const std::vector<std::string>& labels, int cols,
                      int cell_width) {
  if (frames.empty()) fail("contact_sheet: no frames");
  if (cols < 1 || cell_width < 8) fail("contact_sheet: cols must be >= 1 and cell_width >= 8");
  const int ch = static_cast<int>(std::lround(static_cast<double>(frames[0].rows) * cell_width / frames[0].cols));
  const int text_h = labels.empty() ? 0 : std::max(12, cell_width / 18);
  const int rows = static_cast<int>((frames.size() + static_cast<size_t>(cols) - 1) / static_cast<size_t>(cols));
  const int pad = 4;
  cv::Mat sheet(rows * (ch + text_h + pad) + pad, cols * (cell_width + pad) + pad, CV_8UC3, cv::Scalar(24, 24, 24));
  for (size_t i = 0; i < frames.size(); ++i) {
    const int r = static_cast<int>(i) / cols, c = static_cast<int>(i) % cols;
    const int x = pad + c * (cell_width + pad), y = pad + r * (ch + text_h + pad);
    cv::Mat cell;
    cv::resize(frames[i], cell, cv::Size(cell_width, ch), 0, 0, cv::INTER_AREA);
    cell.copyTo(sheet(cv::Rect(x, y, cell_width, ch)));
    if (i < labels.size())
      cv::putText(sheet, labels[i], cv::Point(x + 2, y + ch + text_h - 4), cv::FONT_HERSHEY_SIMPLEX,
                  text_h / 30.0, cv::Scalar(230, 230, 230), 1, cv::LINE_AA);
  }
  return sheet;
}

}  // namespace gaia::synth
