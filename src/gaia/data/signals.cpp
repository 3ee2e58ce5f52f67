#include "gaia/data/signals.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>

#include "gaia/core/error.h"
#include "gaia/core/text.h"
#include "gaia/core/numbers.h"

namespace gaia::data {

namespace {

// [+-] digits [. digits] [(e|E) [+-] digits], with at least one mantissa digit: what people mean by a number
// in a CSV. strtod would also take hex, inf, nan and locale forms.
bool is_plain_decimal(const std::string& s) {
  size_t i = 0, digits = 0;
  auto digit = [&](size_t k) { return k < s.size() && std::isdigit(static_cast<unsigned char>(s[k])); };
  if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
  for (; digit(i); ++i) ++digits;
  if (i < s.size() && s[i] == '.')
    for (++i; digit(i); ++i) ++digits;
  if (digits == 0) return false;
  if (i < s.size() && (s[i] == 'e' || s[i] == 'E')) {
    ++i;
    if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
    if (!digit(i)) return false;
    while (digit(i)) ++i;
  }
  return i == s.size();
}

// One numeric cell; NaN when empty. `where` is "file:line".
double parse_number(const std::string& cell, const std::string& where, const char* col) {
  const std::string c = trim(cell);
  if (c.empty()) return kNaN;
  if (!is_plain_decimal(c)) {
    const std::string l = lower(c);
    if (l.find("inf") != std::string::npos || l.find("nan") != std::string::npos)
      fail("{}: column {}: '{}' is not finite (leave the cell empty for a missing value)", where, col, c);
    fail("{}: column {}: '{}' is not a plain decimal number (digits, optional '.', optional exponent)", where, col, c);
  }
  const char* first = c.data() + (c[0] == '+' ? 1 : 0);
  double v = 0;
  auto r = std::from_chars(first, c.data() + c.size(), v);
  if (r.ec == std::errc::result_out_of_range) fail("{}: column {}: '{}' is out of the range of a double (not finite)", where, col, c);
  if (r.ec != std::errc() || r.ptr != c.data() + c.size() || !std::isfinite(v))
    fail("{}: column {}: '{}' is not a finite number", where, col, c);
  return v;
}

void check_range(double v, const std::string& cell, const std::string& where, const char* col, double lo, double hi,
                 const char* unit, const char* why) {
  if (!std::isnan(v) && !(v >= lo && v <= hi))
    fail("{}: column {}: {} is outside the allowed range [{}, {}] {}{}", where, col, trim(cell), lo, hi, unit, why);
}

// Linear interpolation between the two rows around x. A missing neighbour makes the result missing (NaN
// propagates): a gap is never bridged, and nothing is extrapolated past the first or last row.
double interp(const std::vector<double>& t, const std::vector<double>& v, double x) {
  if (t.empty() || !(x >= t.front() && x <= t.back())) return kNaN;
  size_t hi = static_cast<size_t>(std::lower_bound(t.begin(), t.end(), x) - t.begin());
  if (t[hi] == x) return v[hi];
  size_t lo = hi - 1;  // hi > 0: x > t.front()
  double w = (x - t[lo]) / (t[hi] - t[lo]);
  return v[lo] + w * (v[hi] - v[lo]);
}
}  // namespace

std::vector<std::string> split_csv_line(const std::string& line, const std::string& where) {
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
  if (quoted) fail("{}: unterminated quote (a quoted cell must close with \" on the same line)", where);
  out.push_back(cur);
  return out;
}

Signals read_signals_csv(const fs::path& csv) {
  if (!fs::exists(csv)) fail("{}: no such signals file", csv.string());
  std::istringstream in(read_file(csv));
  std::string line;
  const std::string p = csv.string();
  if (!std::getline(in, line)) fail("{}: empty file (expected header time_s,speed,curvature[,caption])", p);
  auto header = split_csv_line(line, p + ":1");
  for (auto& h : header) h = trim(h);
  bool ok = header.size() >= 3 && header[0] == "time_s" && header[1] == "speed" && header[2] == "curvature" &&
            (header.size() == 3 || (header.size() == 4 && header[3] == "caption"));
  if (!ok) fail("{}:1: header must be time_s,speed,curvature[,caption], got '{}'", p, trim(line));
  Signals s;
  s.has_caption = header.size() == 4;
  int lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (trim(line).empty()) continue;
    const std::string where = fmt::format("{}:{}", p, lineno);
    auto cells = split_csv_line(line, where);
    if (cells.size() != header.size())
      fail("{}: expected {} columns, found {}", where, header.size(), cells.size());
    double t = parse_number(cells[0], where, "time_s");
    if (std::isnan(t)) fail("{}: column time_s is empty", where);
    if (!s.time_s.empty() && !(t > s.time_s.back()))
      fail("{}: column time_s: {} is not after the previous row's {} (times must strictly increase)", where,
           trim(cells[0]), s.time_s.back());
    double v = parse_number(cells[1], where, "speed");
    check_range(v, cells[1], where, "speed", 0, kMaxSpeed, "m/s", " (reversing is not modelled)");
    double k = parse_number(cells[2], where, "curvature");
    check_range(k, cells[2], where, "curvature", -kMaxCurvature, kMaxCurvature, "1/m", "");
    s.time_s.push_back(t);
    s.speed.push_back(v);
    s.curvature.push_back(k);
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
