#include "gaia/data/signals.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "gaia/core/error.h"

namespace gaia::data {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string trim(const std::string& s) {
  size_t a = s.find_first_not_of(" \t\r"), b = s.find_last_not_of(" \t\r");
  return a == std::string::npos ? "" : s.substr(a, b - a + 1);
}

// Linear interpolation over the samples whose value is present (NaN cells are skipped).
double interp(const std::vector<double>& t, const std::vector<double>& v, double x) {
  size_t hi = static_cast<size_t>(std::lower_bound(t.begin(), t.end(), x) - t.begin());
  if (hi < t.size() && t[hi] == x && !std::isnan(v[hi])) return v[hi];
  // nearest present sample on each side
  size_t r = hi;
  while (r < t.size() && std::isnan(v[r])) ++r;
  size_t l = hi;
  while (l > 0 && std::isnan(v[l - 1])) --l;
  if (r >= t.size() || l == 0) return kNaN;
  size_t li = l - 1;
  double w = (x - t[li]) / (t[r] - t[li]);
  return v[li] + w * (v[r] - v[li]);
}
}  // namespace

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (size_t i = 0; i < line.size(); ++i) {
    char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') { cur += '"'; ++i; }
      else if (c == '"') quoted = false;
      else cur += c;
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      out.push_back(cur);
      cur.clear();
    } else if (c != '\r') {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

Signals read_signals_csv(const fs::path& csv) {
  if (!fs::exists(csv)) fail("{}: no such signals file", csv.string());
  std::istringstream in(read_file(csv));
  std::string line;
  const std::string p = csv.string();
  if (!std::getline(in, line)) fail("{}: empty file (expected header time_s,speed,curvature[,caption])", p);
  auto header = split_csv_line(line);
  for (auto& h : header) h = trim(h);
  bool ok = header.size() >= 3 && header[0] == "time_s" && header[1] == "speed" && header[2] == "curvature" &&
            (header.size() == 3 || (header.size() == 4 && header[3] == "caption"));
  if (!ok) fail("{}:1: header must be time_s,speed,curvature[,caption], got '{}'", p, trim(line));
  Signals s;
  s.has_caption = header.size() == 4;
  int lineno = 1;
  auto parse = [&](const std::string& cell, const char* col, bool required) -> double {
    std::string c = trim(cell);
    if (c.empty()) {
      if (required) fail("{}:{}: column {} is empty", p, lineno, col);
      return kNaN;
    }
    size_t used = 0;
    double v;
    try {
      v = std::stod(c, &used);
    } catch (const std::exception&) {
      fail("{}:{}: column {}: '{}' is not a number", p, lineno, col, c);
    }
    if (used != c.size()) fail("{}:{}: column {}: '{}' is not a number", p, lineno, col, c);
    if (!std::isfinite(v)) fail("{}:{}: column {} is {} (leave the cell empty for a missing value)", p, lineno, col, c);
    return v;
  };
  while (std::getline(in, line)) {
    ++lineno;
    if (trim(line).empty()) continue;
    auto cells = split_csv_line(line);
    if (cells.size() != header.size())
      fail("{}:{}: expected {} columns, found {}", p, lineno, header.size(), cells.size());
    double t = parse(cells[0], "time_s", true);
    if (!s.time_s.empty() && !(t > s.time_s.back())) fail("{}:{}: time_s must increase ({} after {})", p, lineno, t, s.time_s.back());
    s.time_s.push_back(t);
    s.speed.push_back(parse(cells[1], "speed", false));
    s.curvature.push_back(parse(cells[2], "curvature", false));
    if (s.has_caption) s.caption.push_back(cells[3]);
  }
  if (s.time_s.empty()) fail("{}: no rows after the header", p);
  return s;
}

double Signals::speed_at(double t) const { return interp(time_s, speed, t); }
double Signals::curvature_at(double t) const { return interp(time_s, curvature, t); }

std::string Signals::caption_at(double t) const {
  if (!has_caption) return "";
  size_t i = static_cast<size_t>(std::upper_bound(time_s.begin(), time_s.end(), t) - time_s.begin());
  return i == 0 ? "" : caption[i - 1];
}

}  // namespace gaia::data
