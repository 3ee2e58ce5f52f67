#include "gaia/data/gps.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include <pugixml.hpp>

#include "gaia/core/civil_time.h"
#include "gaia/core/error.h"
#include "gaia/core/numbers.h"

namespace gaia::data {

namespace {

constexpr double kEarthRadius = 6371000.0;  // metres, mean
constexpr double kKnot = 1852.0 / 3600.0;   // m/s

bool to_double(const std::string& s, double* out) {
  if (s.empty()) return false;
  char* end = nullptr;
  *out = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size() && std::isfinite(*out);
}

// NMEA ddmm.mmmm / dddmm.mmmm with its hemisphere letter -> signed degrees.
bool nmea_angle(const std::string& v, const std::string& hemi, double* deg) {
  double x;
  if (!to_double(v, &x) || x < 0) return false;
  const double d = std::floor(x / 100), m = x - 100 * d;
  if (m >= 60) return false;
  *deg = d + m / 60;
  if (hemi == "S" || hemi == "W") *deg = -*deg;
  else if (hemi != "N" && hemi != "E") return false;
  return true;
}

// hhmmss[.ss] -> seconds since midnight.
bool nmea_time(const std::string& v, double* s) {
  double x;
  if (v.size() < 6 || !to_double(v, &x)) return false;
  const double h = std::floor(x / 10000), m = std::floor((x - h * 10000) / 100), sec = x - h * 10000 - m * 100;
  if (h > 23 || m > 59 || sec >= 61) return false;
  *s = h * 3600 + m * 60 + sec;
  return true;
}

std::vector<std::string> fields_of(const std::string& body) {
  std::vector<std::string> f;
  std::stringstream ss(body);
  std::string x;
  while (std::getline(ss, x, ',')) f.push_back(x);
  if (!body.empty() && body.back() == ',') f.push_back("");
  return f;
}

// Keeps the first fix of each time; fails naming the file under two fixes.
GpsTrack finish(GpsTrack t, const fs::path& file) {
  std::stable_sort(t.fixes.begin(), t.fixes.end(), [](const GpsFix& a, const GpsFix& b) { return a.t_s < b.t_s; });
  std::vector<GpsFix> out;
  for (const auto& f : t.fixes)
    if (out.empty() || f.t_s > out.back().t_s) out.push_back(f);
  t.fixes = std::move(out);
  if (t.fixes.size() < 2)
    fail("{}: holds {} usable GPS fix{} (need two or more{})", file.string(), t.fixes.size(),
         t.fixes.size() == 1 ? "" : "es",
         t.skipped_lines ? fmt::format("; {} sentences skipped for bad checksums or no fix", t.skipped_lines) : "");
  return t;
}

// ISO 8601 as GPX writes it: YYYY-MM-DDTHH:MM:SS[.fff][Z|+hh:mm|-hh:mm] -> UTC seconds.
bool iso_time(const std::string& s, double* out) {
  int y, mo, d, h, mi;
  double sec;
  int used = 0;
  if (std::sscanf(s.c_str(), "%4d-%2d-%2dT%2d:%2d:%lf%n", &y, &mo, &d, &h, &mi, &sec, &used) != 6) return false;
  if (mo < 1 || mo > 12 || d < 1 || d > 31 || h > 23 || mi > 59 || !(sec >= 0 && sec < 61)) return false;
  double t = utc_seconds(y, mo, d, h, mi, sec);
  const std::string zone = s.substr(size_t(used));
  if (zone.empty() || zone == "Z") {
    *out = t;
    return true;
  }
  int zh, zm;
  if (zone.size() == 6 && (zone[0] == '+' || zone[0] == '-') && std::sscanf(zone.c_str() + 1, "%2d:%2d", &zh, &zm) == 2) {
    const double off = (zh * 3600 + zm * 60) * (zone[0] == '+' ? 1 : -1);
    *out = t - off;
    return true;
  }
  return false;
}

}  // namespace

double gps_distance(double lat1, double lon1, double lat2, double lon2) {
  const double r = kPi / 180, dlat = (lat2 - lat1) * r, dlon = (lon2 - lon1) * r;
  const double a = std::pow(std::sin(dlat / 2), 2) + std::cos(lat1 * r) * std::cos(lat2 * r) * std::pow(std::sin(dlon / 2), 2);
  return 2 * kEarthRadius * std::asin(std::min(1.0, std::sqrt(a)));
}

GpsTrack read_nmea(const fs::path& file) {
  GpsTrack rmc, gga;
  double last_gga = -1, day = 0;
  for (std::string line : read_lines(file)) {
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    const size_t dollar = line.find('$');
    if (dollar == std::string::npos) continue;  // not a sentence (blank lines, logger comments)
    line = line.substr(dollar);
    std::string body = line.substr(1);
    const size_t star = body.find('*');
    if (star != std::string::npos) {
      unsigned sum = 0, want = 0;
      for (size_t i = 0; i < star; ++i) sum ^= static_cast<unsigned char>(body[i]);
      if (std::sscanf(body.c_str() + star + 1, "%2x", &want) != 1 || sum != want) {
        ++rmc.skipped_lines;
        continue;
      }
      body = body.substr(0, star);
    }
    auto f = fields_of(body);
    if (f.empty() || f[0].size() != 5) continue;
    const std::string type = f[0].substr(2);
    GpsFix x;
    double tod;
    if (type == "RMC") {
      if (f.size() < 10 || f[2] != "A" || !nmea_time(f[1], &tod) || !nmea_angle(f[3], f[4], &x.lat) ||
          !nmea_angle(f[5], f[6], &x.lon) || f[9].size() != 6 ||
          f[9].find_first_not_of("0123456789") != std::string::npos) {
        ++rmc.skipped_lines;
        continue;
      }
      const int dd = std::stoi(f[9].substr(0, 2)), mm = std::stoi(f[9].substr(2, 2)), yy = std::stoi(f[9].substr(4, 2));
      if (dd < 1 || dd > 31 || mm < 1 || mm > 12) {
        ++rmc.skipped_lines;
        continue;
      }
      x.t_s = utc_seconds(yy < 80 ? 2000 + yy : 1900 + yy, mm, dd, 0, 0, tod);
      double knots;
      if (to_double(f[7], &knots)) x.speed = knots * kKnot;
      rmc.fixes.push_back(x);
    } else if (type == "GGA") {
      if (f.size() < 7 || f[6].empty() || f[6] == "0" || !nmea_time(f[1], &tod) || !nmea_angle(f[2], f[3], &x.lat) ||
          !nmea_angle(f[4], f[5], &x.lon)) {
        ++gga.skipped_lines;
        continue;
      }
      if (last_gga >= 0 && tod + day < last_gga - 43200) day += 86400;  // past midnight
      x.t_s = tod + day;
      last_gga = x.t_s;
      gga.fixes.push_back(x);
    }
  }
  // RMC carries the date and the speed: prefer it; GGA alone still gives positions.
  const int64_t skipped = rmc.skipped_lines + gga.skipped_lines;
  GpsTrack t = rmc.fixes.size() >= 2 ? std::move(rmc) : std::move(gga);
  t.skipped_lines = skipped;
  return finish(std::move(t), file);
}

GpsTrack read_gpx(const fs::path& file) {
  if (!fs::exists(file)) fail("{}: no such file", file.string());
  pugi::xml_document doc;
  const auto r = doc.load_file(file.c_str());
  if (!r) fail("{}: not a GPX file ({} at byte {})", file.string(), r.description(), r.offset);
  GpsTrack t;
  for (const auto& node : doc.select_nodes("//trkpt")) {
    const auto p = node.node();
    GpsFix x;
    const std::string time = p.child_value("time");
    if (!to_double(p.attribute("lat").value(), &x.lat) || !to_double(p.attribute("lon").value(), &x.lon) ||
        std::abs(x.lat) > 90 || std::abs(x.lon) > 180 || !iso_time(time, &x.t_s)) {
      ++t.skipped_lines;
      continue;
    }
    double v;
    if (to_double(p.child_value("speed"), &v) && v >= 0) x.speed = v;
    t.fixes.push_back(x);
  }
  return finish(std::move(t), file);
}

GpsTrack read_gps_track(const fs::path& file) {
  if (!fs::exists(file)) fail("{}: no such GPS track", file.string());
  return file.extension() == ".gpx" ? read_gpx(file) : read_nmea(file);
}

Signals track_signals(const GpsTrack& track, double t0) {
  const auto& fx = track.fixes;
  const size_t n = fx.size();
  // Local plane around the first fix (metres east, north) and the path length to each fix.
  const double lat0 = fx.empty() ? 0 : fx[0].lat, k = kPi / 180 * kEarthRadius;
  std::vector<double> e(n), nn(n), s(n, 0.0);
  for (size_t i = 0; i < n; ++i) {
    e[i] = (fx[i].lon - fx[0].lon) * k * std::cos(lat0 * kPi / 180);
    nn[i] = (fx[i].lat - lat0) * k;
    if (i) s[i] = s[i - 1] + std::hypot(e[i] - e[i - 1], nn[i] - nn[i - 1]);
  }
  Signals out;
  for (size_t i = 0; i < n; ++i) {
    // The nearest fixes at least a chord of path before and after i, within kGpsMaxChordSeconds.
    size_t a = i, b = i;
    while (a > 0 && s[i] - s[a] < kGpsChordMetres && fx[i].t_s - fx[a - 1].t_s <= kGpsMaxChordSeconds) --a;
    while (b + 1 < n && s[b] - s[i] < kGpsChordMetres && fx[b + 1].t_s - fx[i].t_s <= kGpsMaxChordSeconds) ++b;
    const bool before = s[i] - s[a] >= kGpsChordMetres, after = s[b] - s[i] >= kGpsChordMetres;
    double speed = fx[i].speed, curv = kNaN;
    if (std::isnan(speed)) {
      const size_t lo = i > 0 ? i - 1 : i, hi = i + 1 < n ? i + 1 : i;
      if (hi > lo) speed = (s[hi] - s[lo]) / (fx[hi].t_s - fx[lo].t_s);
    }
    if (before && after) {
      const double h1 = std::atan2(nn[i] - nn[a], e[i] - e[a]), h2 = std::atan2(nn[b] - nn[i], e[b] - e[i]);
      const double turn = std::remainder(h2 - h1, 2 * kPi);  // counter-clockwise (left) positive
      curv = turn / ((s[b] - s[a]) / 2);
      if (std::abs(curv) > kMaxCurvature) curv = kNaN;
    }
    if (!(speed >= 0 && speed <= kMaxSpeed)) speed = kNaN;
    out.time_s.push_back(fx[i].t_s - t0);
    out.speed.push_back(speed);
    out.curvature.push_back(curv);
  }
  return out;
}

}  // namespace gaia::data
