#include "gaia/data/manifest.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "gaia/core/error.h"
#include "gaia/core/text.h"
#include "gaia/core/hash.h"
#include "gaia/data/ingest.h"
#include "gaia/data/signals.h"
#include "gaia/synth/caption.h"

namespace gaia::data {

const std::vector<std::string>& manifest_values(const std::string& column) {
  static const std::map<std::string, std::vector<std::string>> v = {
      {"weather", {"clear", "overcast", "rain", "fog", "snow"}},
      {"time_of_day", {"day", "dusk", "night"}},
      {"road", {"city", "highway", "rural", "residential", "parking", "tunnel"}}};
  static const std::vector<std::string> any;
  auto it = v.find(column);
  return it == v.end() ? any : it->second;
}

namespace {

std::string join(const std::vector<std::string>& v) {
  std::string out;
  for (const auto& s : v) out += (out.empty() ? "" : ", ") + s;
  return out;
}

bool valid_id(const std::string& id) {
  return !id.empty() && std::all_of(id.begin(), id.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

}  // namespace

fs::path find_manifest(const fs::path& csv, const fs::path& clips) {
  if (!fs::exists(csv) && csv.is_relative() && fs::exists(clips / csv)) return clips / csv;
  return csv;
}

Manifest read_manifest(const fs::path& csv, const fs::path& clips) {
  if (!fs::is_regular_file(csv)) fail("{}: no such manifest file", csv.string());
  Manifest m;
  m.file = csv;
  std::istringstream in(read_file(csv));
  std::string line;
  int ln = 0;
  std::set<std::string> ids;
  while (std::getline(in, line)) {
    ++ln;
    if (trim(line).empty()) continue;
    const std::string where = fmt::format("{}:{}", csv.string(), ln);
    auto cells = split_csv_line(line, where);
    for (auto& c : cells) c = trim(c);
    if (m.header.empty()) {
      m.header = cells;
      if (std::find(m.header.begin(), m.header.end(), "file") == m.header.end())
        fail("{}: the header has no 'file' column (columns: {})", where, join(m.header));
      continue;
    }
    if (cells.size() != m.header.size())
      fail("{}: {} cells where the header names {} columns", where, cells.size(), m.header.size());
    ManifestRow r;
    r.line = ln;
    for (size_t i = 0; i < cells.size(); ++i) {
      const std::string& col = m.header[i];
      if (col == "file") r.file = cells[i];
      else if (!cells[i].empty()) r.columns[col] = cells[i];
    }
    if (r.file.empty()) fail("{}: column 'file' is empty", where);
    const std::string clip = fmt::format("{} (clip {})", where, r.file);
    r.path = clips / r.file;
    fs::path name = fs::path(r.file);
    if (name.filename().empty()) name = name.parent_path();
    r.id = name.stem().string();
    if (!valid_id(r.id)) fail("{}: episode id '{}' (the file name) may hold only A-Z a-z 0-9 _ - .", clip, r.id);
    if (!ids.insert(r.id).second) fail("{}: episode id '{}' appears twice in the manifest", clip, r.id);
    for (const char* col : {"weather", "time_of_day", "road"}) {
      const auto& ok = manifest_values(col);
      std::string v = r.get(col);
      std::transform(v.begin(), v.end(), v.begin(), ::tolower);
      if (v.empty()) continue;
      if (std::find(ok.begin(), ok.end(), v) == ok.end())
        fail("{}: column '{}' is '{}': expected one of {} (or empty)", clip, col, r.get(col), join(ok));
      r.columns[col] = v;
    }
    const std::string fps = r.get("fps");
    if (!fps.empty()) {
      size_t used = 0;
      try {
        r.fps = std::stod(fps, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != fps.size() || !(r.fps > 0 && r.fps <= kMaxIngestFps))
        fail("{}: column 'fps' is '{}': expected a frame rate in (0, {}]", clip, fps, kMaxIngestFps);
      r.columns.erase("fps");
    }
    m.rows.push_back(std::move(r));
  }
  if (m.header.empty()) fail("{}: empty manifest (no header)", csv.string());
  if (m.rows.empty()) fail("{}: the manifest lists no clips", csv.string());
  return m;
}

std::string manifest_caption(const ManifestRow& row, double time_s) {
  static const std::map<std::string, std::string> road = {
      {"city", "in the city"},           {"highway", "on a highway"},   {"rural", "on a country road"},
      {"residential", "on a residential street"}, {"parking", "in a parking garage"}, {"tunnel", "in a tunnel"}};
  // The id's hash, then the second: the same words on every machine.
  const uint64_t key = fnv1a(row.id) ^ (uint64_t(std::max(0.0, time_s)) * 0x9E3779B97F4A7C15ull);
  const std::string w = row.weather(), t = row.time_of_day();
  std::string out = !w.empty() && !t.empty() ? synth::conditions_caption(w, t, key) : w + t;
  auto it = road.find(row.road());
  if (it != road.end()) out += (out.empty() ? "" : ", ") + it->second;
  return out;
}

}  // namespace gaia::data
