// Signals people have besides a CSV: GPS tracks (NMEA, GPX) and KITTI raw drives (OXTS), read into episodes.
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>

#include "gaia/core/fs.h"
#include "gaia/data/episode.h"
#include "gaia/data/gps.h"
#include "gaia/data/ingest.h"
#include "gaia/data/kitti.h"
#include "test_util.h"

using namespace gaia;
using namespace gaia::data;
using test::error_of;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kLat0 = 48.1, kLon0 = 11.5;  // somewhere in Munich
constexpr double kR = 6371000.0;

struct Pose {
  double t, lat, lon, speed;
};

// 40 s at 10 m/s, 1 Hz: 10 s straight east, 20 s on a circle of radius 100 m (left when `left`), then straight.
std::vector<Pose> drive(bool left) {
  std::vector<Pose> out;
  double x = 0, y = 0, heading = 0;  // metres east / north, radians counter-clockwise from east
  const double v = 10, dt = 0.1;
  for (int k = 0; k <= 400; ++k) {
    const double t = k * dt;
    if (k % 10 == 0)
      out.push_back({t, kLat0 + y / kR * 180 / kPi, kLon0 + x / (kR * std::cos(kLat0 * kPi / 180)) * 180 / kPi, v});
    const double curv = t >= 10 && t < 30 ? (left ? 0.01 : -0.01) : 0.0;
    heading += curv * v * dt;
    x += v * dt * std::cos(heading);
    y += v * dt * std::sin(heading);
  }
  return out;
}

std::string nmea_angle(double deg, bool lat) {
  const char hemi = lat ? (deg >= 0 ? 'N' : 'S') : (deg >= 0 ? 'E' : 'W');
  deg = std::abs(deg);
  const int d = int(deg);
  return fmt::format(lat ? "{:02d}{:08.5f},{}" : "{:03d}{:08.5f},{}", d, (deg - d) * 60, hemi);
}

std::string sentence(const std::string& body) {
  unsigned sum = 0;
  for (char c : body) sum ^= static_cast<unsigned char>(c);
  return fmt::format("${}*{:02X}\r\n", body, sum);
}

// RMC (with date and speed) and GGA sentences, 12:00:00 UTC on 2024-05-01 onwards, one bad checksum among them.
std::string nmea(const std::vector<Pose>& poses, bool with_rmc) {
  std::string out = "# logger v1\n";
  for (const auto& p : poses) {
    const int s = int(p.t);
    const std::string hms = fmt::format("12{:02d}{:02d}.00", s / 60, s % 60);
    if (with_rmc)
      out += sentence(fmt::format("GPRMC,{},A,{},{},{:.3f},90.0,010524,,,A", hms, nmea_angle(p.lat, true),
                                  nmea_angle(p.lon, false), p.speed / (1852.0 / 3600.0)));
    out += sentence(fmt::format("GPGGA,{},{},{},1,08,0.9,520.0,M,47.0,M,,", hms, nmea_angle(p.lat, true),
                                nmea_angle(p.lon, false)));
  }
  out += "$GPRMC,120100.00,A,4806.000,N,01130.000,E,5.0,0,010524,,,A*00\r\n";  // bad checksum: skipped
  return out;
}

std::string gpx(const std::vector<Pose>& poses) {
  std::string out = R"(<?xml version="1.0"?><gpx version="1.1" xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>)";
  for (const auto& p : poses) {
    const int s = int(p.t);
    // Local time two hours ahead of UTC: the same instants as the NMEA log.
    out += fmt::format(R"(<trkpt lat="{:.7f}" lon="{:.7f}"><time>2024-05-01T14:{:02d}:{:02d}+02:00</time></trkpt>)",
                       p.lat, p.lon, s / 60, s % 60);
  }
  return out + "</trkseg></trk></gpx>\n";
}

}  // namespace

TEST(Gps, NmeaAndGpxGiveSpeedAndSignedCurvature) {
  test::TempDir dir;
  for (bool left : {true, false}) {
    const auto poses = drive(left);
    write_file_atomic(dir / "t.nmea", nmea(poses, true));
    write_file_atomic(dir / "t.gpx", gpx(poses));
    const GpsTrack n = read_gps_track(dir / "t.nmea"), g = read_gps_track(dir / "t.gpx");
    ASSERT_EQ(n.fixes.size(), poses.size());
    ASSERT_EQ(g.fixes.size(), poses.size());
    EXPECT_EQ(n.skipped_lines, 1);
    EXPECT_DOUBLE_EQ(n.fixes[0].t_s, g.fixes[0].t_s);  // the same UTC instant from both
    EXPECT_NEAR(n.fixes[0].t_s, 1714564800.0, 1e-6);   // 2024-05-01 12:00:00 UTC
    for (const GpsTrack* t : {&n, &g}) {
      const Signals s = track_signals(*t, t->fixes[0].t_s);
      const double want = left ? 0.01 : -0.01;
      for (double at : {14.0, 20.0, 26.0}) {
        EXPECT_NEAR(s.curvature_at(at), want, 0.0015) << "t = " << at << (t == &n ? " nmea" : " gpx");
        EXPECT_NEAR(s.speed_at(at), 10.0, 0.3) << at;
      }
      for (double at : {4.0, 36.0}) EXPECT_NEAR(s.curvature_at(at), 0.0, 0.0008) << at;
    }
  }
}

TEST(Gps, GgaAloneAndBadTracks) {
  test::TempDir dir;
  const auto poses = drive(true);
  write_file_atomic(dir / "gga.log", nmea(poses, false));  // no RMC: positions only, speed from the path
  const GpsTrack t = read_gps_track(dir / "gga.log");
  EXPECT_EQ(t.fixes.size(), poses.size());
  EXPECT_TRUE(std::isnan(t.fixes[3].speed));
  const Signals s = track_signals(t, t.fixes[0].t_s + 5);  // video starts 5 s into the track
  EXPECT_NEAR(s.time_s.front(), -5, 1e-9);
  EXPECT_NEAR(s.speed_at(15), 10.0, 0.3);
  EXPECT_NEAR(s.curvature_at(15), 0.01, 0.0015);  // track time 20 s

  write_file_atomic(dir / "empty.nmea", "$GPGGA,120000.00,,,,,0,00,,,M,,M,,*66\n");
  auto e = error_of([&] { read_gps_track(dir / "empty.nmea"); });
  EXPECT_NE(e.find("empty.nmea"), std::string::npos) << e;
  EXPECT_NE(e.find("usable GPS fix"), std::string::npos) << e;
  write_file_atomic(dir / "bad.gpx", "<gpx><trk><trkpt lat=");
  e = error_of([&] { read_gps_track(dir / "bad.gpx"); });
  EXPECT_NE(e.find("bad.gpx: not a GPX file"), std::string::npos) << e;
  EXPECT_NE(error_of([&] { read_gps_track(dir / "none.gpx"); }).find("none.gpx"), std::string::npos);
}

TEST(Gps, IngestAlignsTheTrackAndRefusesOneThatMissesTheVideo) {
  test::TempDir dir;
  fs::create_directories(dir / "frames");
  for (int i = 0; i < 50; ++i)  // 5 s at 10 Hz
    cv::imwrite((dir / "frames" / fmt::format("{:03d}.png", i)).string(), cv::Mat(24, 32, CV_8UC3, cv::Scalar(i, 90, 30)));
  write_file_atomic(dir / "t.nmea", nmea(drive(true), true));
  IngestOptions o;
  o.height = 24;
  o.width = 32;
  o.fps = 10;
  o.gps = dir / "t.nmea";
  o.gps_offset = 12;  // the video starts 12 s into the track, inside the turn
  o.id = "a";
  o.drop_repeats = false;  // flat frames one grey level apart: every one would read as a repeat
  const auto r = ingest_video(dir / "frames", dir / "ds", o);
  EXPECT_EQ(r.meta.signals_source, "gps");
  EXPECT_EQ(r.frames_with_speed, 50);
  Episode ep(dir / "ds" / "episodes" / "a");
  EXPECT_NEAR(ep.curvature(20), 0.01, 0.0015);
  EXPECT_NEAR(ep.speed(20), 10, 0.3);
  EXPECT_EQ(Episode(dir / "ds" / "episodes" / "a").meta().signals_source, "gps");

  o.gps_offset = 1000;  // far past the track's end
  o.id = "b";
  auto e = error_of([&] { ingest_video(dir / "frames", dir / "ds", o); });
  EXPECT_NE(e.find("t.nmea: gives none of the 50 frames"), std::string::npos) << e;
  EXPECT_FALSE(fs::exists(dir / "ds" / "episodes" / "b"));
  o.signals = dir / "sig.csv";
  EXPECT_NE(error_of([&] { ingest_video(dir / "frames", dir / "ds", o); }).find("give one source"), std::string::npos);

  // One dataset, one frame size.
  IngestOptions big = o;
  big.signals.clear();
  big.gps_offset = 0;
  big.height = 48;
  big.width = 64;
  big.id = "c";
  e = error_of([&] { ingest_video(dir / "frames", dir / "ds", big); });
  EXPECT_NE(e.find("its episodes are 24x32, this config ingests at 48x64"), std::string::npos) << e;
}

namespace {

// A KITTI raw drive in the real layout: DATE/DRIVE/{image_02/data, image_02/timestamps.txt, oxts/...} and
// DATE/calib_cam_to_cam.txt, with `n` frames at 10 Hz, speed 8 m/s and yaw rate 0.08 rad/s.
fs::path kitti_drive(const fs::path& root, int n, bool with_oxts = true) {
  const fs::path date = root / "2011_09_26", d = date / "2011_09_26_drive_0001_sync";
  fs::create_directories(d / "image_02" / "data");
  std::string ts;
  for (int i = 0; i < n; ++i) {
    cv::imwrite((d / "image_02" / "data" / fmt::format("{:010d}.png", i)).string(),
                cv::Mat(30, 100, CV_8UC3, cv::Scalar(10 * i, 50, 200)));
    ts += fmt::format("2011-09-26 13:02:{:012.9f}\n", 25.0 + 0.1 * i + (i % 2) * 0.003);  // jitter as in KITTI
  }
  write_file_atomic(d / "image_02" / "timestamps.txt", ts);
  write_file_atomic(date / "calib_cam_to_cam.txt",
                    "S_rect_02: 1.242000e+03 3.750000e+02\n"
                    "P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 "
                    "1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03\n");
  if (!with_oxts) return d;
  fs::create_directories(d / "oxts" / "data");
  std::string names;
  for (const char* f : {"lat", "lon", "alt", "roll", "pitch", "yaw", "vn", "ve", "vf", "vl", "vu", "ax", "ay", "az",
                        "af", "al", "au", "wx", "wy", "wz", "wf", "wl", "wu", "pos_accuracy", "vel_accuracy",
                        "navstat", "numsats", "posmode", "velmode", "orimode"})
    names += std::string(f) + ": a field\n";
  write_file_atomic(d / "oxts" / "dataformat.txt", names);
  std::string ots;
  for (int i = 0; i < n; ++i) {
    std::vector<double> v(30, 0.0);
    v[0] = 49.0 + 1e-5 * i;
    v[1] = 8.4;
    v[8] = i < n - 2 ? 8.0 : 0.2;  // the car stops for the last two frames
    v[22] = 0.08;
    write_file_atomic(d / "oxts" / "data" / fmt::format("{:010d}.txt", i), fmt::format("{}\n", fmt::join(v, " ")));
    ots += fmt::format("2011-09-26 13:02:{:012.9f}\n", 25.0 + 0.1 * i + 0.002);
  }
  write_file_atomic(d / "oxts" / "timestamps.txt", ots);
  return d;
}

}  // namespace

TEST(Kitti, RawDriveGivesOxtsSpeedCurvatureAndLocation) {
  test::TempDir dir;
  const fs::path d = kitti_drive(dir.path, 12);
  EXPECT_TRUE(is_kitti_drive(d));
  EXPECT_FALSE(is_kitti_drive(dir.path));
  const KittiDrive k = read_kitti_drive(d);
  EXPECT_NEAR(k.fps, 10.0, 0.5);
  EXPECT_NEAR(k.focal_px, 721.5377, 1e-3);
  EXPECT_EQ(k.image_width, 1242);
  ASSERT_EQ(k.oxts.time_s.size(), 12u);
  EXPECT_EQ(k.oxts.time_s[1], k.image_time_s[1]);  // synced: record i belongs to image i
  EXPECT_NEAR(k.oxts.curvature[3], 0.01, 1e-12);  // 0.08 rad/s / 8 m/s
  EXPECT_TRUE(std::isnan(k.oxts.curvature[11]));  // 0.2 m/s: too slow to tell a bend
  EXPECT_NEAR(k.latitude, 49.0, 1e-12);

  IngestOptions o;
  o.height = 24;
  o.width = 64;
  const auto r = ingest_kitti(d, dir / "ds", o);
  EXPECT_EQ(r.meta.id, "2011_09_26_drive_0001_sync");
  EXPECT_EQ(r.meta.signals_source, "kitti-oxts");
  EXPECT_NEAR(r.meta.latitude, 49.0, 1e-12);
  Episode ep(dir / "ds" / "episodes" / r.meta.id);
  EXPECT_EQ(ep.size(), 12);
  EXPECT_NEAR(ep.time_s(1), 0.103, 1e-6);  // the images' own timestamps
  EXPECT_NEAR(ep.speed(5), 8.0, 1e-4);
  EXPECT_NEAR(ep.curvature(5), 0.01, 1e-4);

  o.fps = 25;
  EXPECT_NE(error_of([&] { ingest_kitti(d, dir / "ds2", o); }).find("from its timestamps"), std::string::npos);
}

TEST(Kitti, BadDrivesAreOneLine) {
  test::TempDir dir;
  const fs::path d = kitti_drive(dir.path, 5, false);
  IngestOptions o;
  o.height = 24;
  o.width = 64;
  auto e = error_of([&] { ingest_kitti(d, dir / "ds", o); });
  EXPECT_NE(e.find("no oxts/ folder"), std::string::npos) << e;
  EXPECT_FALSE(fs::exists(dir / "ds" / "episodes"));
  write_file_atomic(d / "image_02" / "timestamps.txt", "2011-09-26 13:02:25.0\n");
  e = error_of([&] { read_kitti_drive(d); });
  EXPECT_NE(e.find("1 timestamps for 5 files, and 0000000001.png is not a frame number within them"),
            std::string::npos) << e;
  write_file_atomic(d / "image_02" / "timestamps.txt", std::string(5, '\n') + "yesterday\n");
  e = error_of([&] { read_kitti_drive(d); });
  EXPECT_NE(e.find("not a KITTI timestamp"), std::string::npos) << e;
}

TEST(Kitti, RealDriveFromSharedData) {
  const fs::path real = test::real_data_dir();
  const fs::path d = real / "kitti-raw-0002-color-10f" / "2011_09_26" / "2011_09_26_drive_0002_sync";
  if (real.empty() || !fs::exists(d)) GTEST_SKIP() << "shared KITTI raw drive not found";
  const KittiDrive k = read_kitti_drive(d);
  EXPECT_NEAR(k.fps, 9.70, 0.02);  // "10 Hz": its frames are 0.1031 s apart
  ASSERT_EQ(k.oxts.speed.size(), 10u);
  EXPECT_NEAR(k.oxts.speed[0], 8.6225, 1e-3);  // SOURCES.md: about 8.8 m/s
  EXPECT_NEAR(k.latitude, 49.0145, 1e-3);
  EXPECT_NEAR(k.focal_px, 721.5377, 1e-3);
  test::TempDir dir;
  IngestOptions o;
  const auto r = ingest_kitti(d, dir / "ds", o);
  EXPECT_EQ(r.frames_with_speed, 10);
  Episode ep(dir / "ds" / "episodes" / r.meta.id);
  EXPECT_EQ(ep.frame_bgr(0).rows, 72);
  for (int i = 0; i < 10; ++i) EXPECT_LT(std::abs(ep.curvature(i)), 0.02) << i;  // a residential street, near straight
}
