#include "gaia/data/kitti.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <sstream>

#include <opencv2/core.hpp>

#include "gaia/core/civil_time.h"
#include "gaia/core/error.h"
#include "gaia/core/numbers.h"

namespace gaia::data {

namespace {

const char* const kCameras[] = {"image_02", "image_03", "image_00", "image_01"};

// The non-blank lines, without trailing spaces or carriage returns.
std::vector<std::string> lines_of(const fs::path& f) {
  std::vector<std::string> out;
  for (std::string l : read_lines(f)) {
    while (!l.empty() && (l.back() == '\r' || l.back() == ' ')) l.pop_back();
    if (!l.empty()) out.push_back(std::move(l));
  }
  return out;
}

std::vector<double> timestamps(const fs::path& f) {
  if (!fs::exists(f)) fail("{}: missing (KITTI raw keeps one timestamp a frame there)", f.string());
  std::vector<double> t;
  int line = 0;
  for (const auto& l : lines_of(f)) t.push_back(kitti_timestamp(l, fmt::format("{}:{}", f.string(), ++line)));
  return t;
}

// KITTI names frame i `%010d`: each file's timestamp is line i of timestamps.txt, so a drive cut to its first
// frames (or with frames removed) keeps the right times.
std::vector<double> times_of(const std::vector<fs::path>& files, const std::vector<double>& stamps,
                             const fs::path& stamp_file) {
  std::vector<double> out;
  if (files.size() == stamps.size()) return stamps;
  for (const auto& f : files) {
    const std::string stem = f.stem().string();
    size_t used = 0;
    unsigned long long i = 0;
    try {
      i = std::stoull(stem, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != stem.size() || stem.empty() || i >= stamps.size())
      fail("{}: {} timestamps for {} files, and {} is not a frame number within them", stamp_file.string(),
           stamps.size(), files.size(), f.filename().string());
    out.push_back(stamps[size_t(i)]);
  }
  return out;
}

std::vector<fs::path> files_in(const fs::path& dir, const std::string& ext) {
  std::vector<fs::path> out;
  if (fs::is_directory(dir))
    for (auto& e : fs::directory_iterator(dir))
      if (e.is_regular_file() && e.path().extension() == ext) out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

// Field positions by name from oxts/dataformat.txt ("vf:   forward velocity ..."), else KITTI's fixed order.
std::map<std::string, size_t> oxts_fields(const fs::path& oxts) {
  std::map<std::string, size_t> idx{{"lat", 0}, {"lon", 1}, {"vf", 8}, {"wu", 22}};
  const fs::path f = oxts / "dataformat.txt";
  if (!fs::exists(f)) return idx;
  size_t i = 0;
  std::map<std::string, size_t> named;
  for (const auto& l : lines_of(f)) {
    const auto colon = l.find(':');
    if (colon == std::string::npos) continue;
    named[l.substr(0, colon)] = i++;
  }
  for (auto& [k, v] : idx) {
    if (!named.count(k)) fail("{}: names no field '{}'", f.string(), k);
    v = named[k];
  }
  return idx;
}

// The rectified projection of camera N (P_rect_0N: fx 0 cx tx 0 fy cy ty 0 0 1 tz) and its size (S_rect_0N).
void read_calib(KittiDrive* d, const std::string& camera) {
  for (const fs::path& f : {d->dir / "calib_cam_to_cam.txt", d->dir.parent_path() / "calib_cam_to_cam.txt"}) {
    if (!fs::exists(f)) continue;
    const std::string n = camera.substr(camera.size() - 2);  // "02"
    std::vector<double> p, s;
    for (const auto& l : lines_of(f)) {
      auto values = [&](const std::string& key, std::vector<double>* out) {
        if (l.rfind(key + ":", 0) != 0) return;
        std::stringstream ss(l.substr(key.size() + 1));
        double x;
        while (ss >> x) out->push_back(x);
      };
      values("P_rect_" + n, &p);
      values("S_rect_" + n, &s);
    }
    if (p.size() != 12 || s.size() != 2 || !(p[0] > 0))
      fail("{}: no usable P_rect_{} / S_rect_{} (12 and 2 numbers)", f.string(), n, n);
    d->focal_px = p[0];
    d->cx = p[2];
    d->cy = p[6];
    d->image_width = int(s[0]);
    d->image_height = int(s[1]);
    return;
  }
}

}  // namespace

double kitti_timestamp(const std::string& s, const std::string& where) {
  int y, mo, d, h, mi, used = 0;
  if (std::sscanf(s.c_str(), "%4d-%2d-%2d %2d:%2d:%n", &y, &mo, &d, &h, &mi, &used) != 5 || used == 0)
    fail("{}: '{}' is not a KITTI timestamp (YYYY-MM-DD HH:MM:SS.fffffffff)", where, s);
  double sec = 0;
  char* end = nullptr;
  sec = std::strtod(s.c_str() + used, &end);
  if (*end != '\0' || !(sec >= 0 && sec < 61) || mo < 1 || mo > 12 || d < 1 || d > 31 || h > 23 || mi > 59)
    fail("{}: '{}' is not a KITTI timestamp (YYYY-MM-DD HH:MM:SS.fffffffff)", where, s);
  return utc_seconds(y, mo, d, h, mi, sec);
}

bool is_kitti_drive(const fs::path& dir) {
  if (!fs::is_directory(dir)) return false;
  for (const char* c : kCameras)
    if (fs::is_directory(dir / c / "data")) return true;
  return false;
}

KittiDrive read_kitti_drive(const fs::path& dir) {
  KittiDrive d;
  d.dir = dir;
  std::string camera;
  for (const char* c : kCameras)
    if (fs::is_directory(dir / c / "data")) {
      camera = c;
      break;
    }
  if (camera.empty()) fail("{}: not a KITTI raw drive (no image_02/data, image_03/data, image_00/data or image_01/data)", dir.string());
  d.images = dir / camera / "data";
  const auto images = files_in(d.images, ".png");
  if (images.empty()) fail("{}: no PNG frames", d.images.string());
  const auto it = times_of(images, timestamps(dir / camera / "timestamps.txt"), dir / camera / "timestamps.txt");
  for (double t : it) d.image_time_s.push_back(t - it[0]);
  if (it.size() > 1) {
    // The mean gap: KITTI's camera timestamps jitter by a few milliseconds frame to frame.
    const double g = (it.back() - it.front()) / double(it.size() - 1);
    if (!(g > 1e-3 && g < 10))
      fail("{}: frames {} s apart on average: not a video's timestamps", (dir / camera / "timestamps.txt").string(), g);
    d.fps = 1 / g;
  } else {
    d.fps = 10;  // KITTI raw's camera rate; one frame gives nothing to measure
  }
  read_calib(&d, camera);

  const fs::path oxts = dir / "oxts";
  if (!fs::is_directory(oxts / "data")) return d;
  const auto records = files_in(oxts / "data", ".txt");
  const auto ot = times_of(records, timestamps(oxts / "timestamps.txt"), oxts / "timestamps.txt");
  const auto idx = oxts_fields(oxts);
  for (size_t i = 0; i < records.size(); ++i) {
    std::stringstream ss(read_file(records[i]));
    std::vector<double> v;
    double x;
    while (ss >> x) v.push_back(x);
    if (!ss.eof() || v.size() <= std::max(idx.at("wu"), idx.at("vf")))
      fail("{}: not an OXTS record (want {}+ numbers, got {})", records[i].string(), idx.at("wu") + 1, v.size());
    const double vf = v[idx.at("vf")], wu = v[idx.at("wu")];
    if (!std::isfinite(vf) || !std::isfinite(wu)) fail("{}: vf or wu is not finite", records[i].string());
    if (i == 0) {
      d.latitude = v[idx.at("lat")];
      d.longitude = v[idx.at("lon")];
    }
    // A synced drive (the _sync downloads) has one record per image: it belongs to that image, whose timestamp
    // differs by milliseconds. Otherwise the records are placed by their own timestamps.
    const double t = records.size() == it.size() ? d.image_time_s[i] : ot[i] - it[0];
    if (!d.oxts.time_s.empty() && t <= d.oxts.time_s.back())
      fail("{}: timestamps must increase (record {})", (oxts / "timestamps.txt").string(), i);
    d.oxts.time_s.push_back(t);
    // Reversing is not modelled: speed stays >= 0, and a curvature needs a car that is moving.
    d.oxts.speed.push_back(vf >= 0 && vf <= kMaxSpeed ? vf : kNaN);
    const double k = vf >= kKittiMinSpeed ? wu / vf : kNaN;
    d.oxts.curvature.push_back(std::abs(k) <= kMaxCurvature ? k : kNaN);
  }
  if (!(std::abs(d.latitude) <= 90 && std::abs(d.longitude) <= 180))
    fail("{}: latitude/longitude {} / {} out of range", records[0].string(), d.latitude, d.longitude);
  return d;
}

Signals pose_signals(const fs::path& poses, double fps) {
  if (!(fps > 0)) fail("{}: poses need the frame rate (--fps)", poses.string());
  if (!fs::exists(poses)) fail("{}: no such poses file", poses.string());
  std::vector<cv::Matx34d> P;
  int line = 0;
  for (const auto& l : lines_of(poses)) {
    ++line;
    std::stringstream ss(l);
    cv::Matx34d m;
    int k = 0;
    double x;
    while (k < 12 && ss >> x) m.val[k++] = x;
    std::string rest;
    if (k != 12 || (ss >> rest) || !std::isfinite(cv::norm(m)))
      fail("{}:{}: a pose is 12 finite numbers (a 3x4 [R | c] row by row)", poses.string(), line);
    P.push_back(m);
  }
  if (P.size() < 2) fail("{}: needs two or more poses", poses.string());
  Signals s;
  for (size_t i = 0; i < P.size(); ++i) {
    const size_t a = i + 1 < P.size() ? i : i - 1, b = a + 1;  // the last frame repeats the step before it
    const cv::Matx33d Ra = P[a].get_minor<3, 3>(0, 0), Rb = P[b].get_minor<3, 3>(0, 0);
    const cv::Vec3d ca(P[a](0, 3), P[a](1, 3), P[a](2, 3)), cb(P[b](0, 3), P[b](1, 3), P[b](2, 3));
    const cv::Matx33d rel = Ra.t() * Rb;  // frame b's axes in frame a's
    const double dist = cv::norm(cb - ca), yaw = std::atan2(-rel(0, 2), rel(2, 2));  // its forward axis, turned left
    const double v = dist * fps;
    s.time_s.push_back(double(i) / fps);
    s.speed.push_back(v <= kMaxSpeed ? v : kNaN);
    const double k = v >= kKittiMinSpeed ? yaw / dist : kNaN;
    s.curvature.push_back(std::abs(k) <= kMaxCurvature ? k : kNaN);
  }
  return s;
}

}  // namespace gaia::data
