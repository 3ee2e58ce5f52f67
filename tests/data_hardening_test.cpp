// Hardening of the data side: strict signals CSV (finite, in range, plain decimal, closed quotes, missing stays
// missing), coverage of the clip by the CSV, truncated videos, --fps / --id checks and orphaned staging dirs.
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <regex>
#include <sstream>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "gaia/core/error.h"
#include "gaia/data/episode.h"
#include "gaia/data/ingest.h"
#include "gaia/data/signals.h"
#include "test_util.h"

using namespace gaia;
using test::q;
using namespace gaia::data;
using test::error_of;

namespace {

// `n` frames of a moving bar at 25 fps; MJPG in AVI, or MPEG-4 Part 2 in MP4 for a ".mp4" name. Empty when the
// encoder is missing.
fs::path make_video(const fs::path& dir, int n, const std::string& name = "clip.avi") {
  fs::path p = dir / name;
  const bool mp4 = p.extension() == ".mp4";
  int cc = mp4 ? cv::VideoWriter::fourcc('m', 'p', '4', 'v') : cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
  cv::VideoWriter vw(p.string(), cv::CAP_FFMPEG, cc, 25.0, cv::Size(160, 120));
  if (!vw.isOpened()) return {};  // no such encoder in this build
  cv::RNG rng(7);
  for (int i = 0; i < n; ++i) {
    cv::Mat f(120, 160, CV_8UC3);
    rng.fill(f, cv::RNG::UNIFORM, 0, 255);  // noise: every frame costs about the same number of bytes
    cv::rectangle(f, cv::Rect((i * 7) % 160, 0, 10, 120), cv::Scalar(255, 255, 255), cv::FILLED);
    vw.write(f);
  }
  return p;
}

// The error of reading a CSV with the header, one good row (line 2), then `row` (line 3).
std::string row_error(const test::TempDir& dir, const std::string& row) {
  write_file_atomic(dir / "s.csv", "time_s,speed,curvature\n0,1,0\n" + row + "\n");
  return error_of([&] { read_signals_csv(dir / "s.csv"); });
}

bool has(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }

// The app at small()'s frame size: a dataset holds one size.
const std::string kSmall = " --set data.height=24 --set data.width=32";

IngestOptions small() {
  IngestOptions o;
  o.height = 24;
  o.width = 32;
  return o;
}


// The lines of the app's output that it says itself ("gaia: error: ...", "gaia: warning: ..."); the rest is
// progress (a line per 10% when stderr is not a terminal).
std::vector<std::string> said(const std::string& output) {
  std::vector<std::string> out;
  std::istringstream in(output);
  for (std::string line; std::getline(in, line);)
    if (line.rfind("gaia: ", 0) == 0) out.push_back(line);
  return out;
}

// Failed, with exactly one error line naming `what`, and nothing after it.
void expect_one_error(const test::RunResult& r, const std::string& what) {
  EXPECT_NE(r.status, 0) << r.output;
  auto lines = said(r.output);
  ASSERT_EQ(lines.size(), 1u) << r.output;
  EXPECT_EQ(lines[0].rfind("gaia: error: ", 0), 0u) << r.output;
  EXPECT_TRUE(has(lines[0], what)) << r.output;
  EXPECT_EQ(r.output.substr(r.output.size() - lines[0].size() - 1), lines[0] + "\n") << r.output;
}

}  // namespace

TEST(DataHardening, SignalsRejectNonFiniteValuesNamingLineAndColumn) {
  test::TempDir dir;
  for (auto [row, col] : {std::pair{"1,inf,0", "speed"}, {"1,-inf,0", "speed"}, {"1,nan,0", "speed"},
                          {"1,2,Infinity", "curvature"}, {"1,2,NaN", "curvature"}, {"inf,2,0", "time_s"},
                          {"1e400,2,0", "time_s"}, {"1,1e400,0", "speed"}, {"1,2,-1e999", "curvature"}}) {
    std::string e = row_error(dir, row);
    EXPECT_TRUE(has(e, "s.csv:3: column " + std::string(col))) << row << " -> " << e;
  }
  // 1e39 is a finite double but overflows the float32 the episode stores (it used to surface as inf much later).
  std::string e = row_error(dir, "1,1e39,0");
  EXPECT_TRUE(has(e, "s.csv:3: column speed")) << e;
  EXPECT_TRUE(has(e, "[0, 100]")) << e;
}

TEST(DataHardening, SignalsEnforcePhysicalRanges) {
  test::TempDir dir;
  for (auto row : {"1,-5,0", "1,1e30,0", "1,100.5,0"}) {
    std::string e = row_error(dir, row);
    EXPECT_TRUE(has(e, "s.csv:3: column speed")) << row << " -> " << e;
    EXPECT_TRUE(has(e, "[0, 100] m/s")) << e;
  }
  for (auto row : {"1,2,5", "1,2,-1.5", "1,2,1e39"}) {
    std::string e = row_error(dir, row);
    EXPECT_TRUE(has(e, "s.csv:3: column curvature")) << row << " -> " << e;
    EXPECT_TRUE(has(e, "[-1, 1] 1/m")) << e;
  }
  for (auto row : {"0,2,0", "-1,2,0"}) {  // times must strictly increase
    std::string e = row_error(dir, row);
    EXPECT_TRUE(has(e, "s.csv:3: column time_s")) << row << " -> " << e;
  }
  // The bounds themselves are allowed.
  write_file_atomic(dir / "ok.csv", "time_s,speed,curvature\n-2,0,-1\n0,100,1\n");
  Signals s = read_signals_csv(dir / "ok.csv");
  EXPECT_DOUBLE_EQ(s.speed_at(-1), 50);
  EXPECT_DOUBLE_EQ(s.curvature_at(-1), 0);
}

TEST(DataHardening, SignalsNumbersArePlainDecimal) {
  test::TempDir dir;
  for (auto [row, col] : {std::pair{"1,0x10,0", "speed"}, {"1,2,0x0", "curvature"}, {"0x1,2,0", "time_s"},
                          {"1,1.2.3,0", "speed"}, {"1,12abc,0", "speed"}, {"1,e5,0", "speed"}, {"1,.,0", "speed"},
                          {"1,1e,0", "speed"}, {"1,+,0", "speed"}, {"1,1 2,0", "speed"}, {"1,2,0.1f", "curvature"}}) {
    std::string e = row_error(dir, row);
    EXPECT_TRUE(has(e, "s.csv:3: column " + std::string(col))) << row << " -> " << e;
  }
  write_file_atomic(dir / "ok.csv", "time_s,speed,curvature\n+0,5.,-.5\n1E1, 3e-2 ,+2.5e-1\n");
  Signals s = read_signals_csv(dir / "ok.csv");
  ASSERT_EQ(s.time_s.size(), 2u);
  EXPECT_DOUBLE_EQ(s.time_s[1], 10);
  EXPECT_DOUBLE_EQ(s.speed[0], 5);
  EXPECT_DOUBLE_EQ(s.speed[1], 0.03);
  EXPECT_DOUBLE_EQ(s.curvature[0], -0.5);
  EXPECT_DOUBLE_EQ(s.curvature[1], 0.25);
}

TEST(DataHardening, SignalsUnterminatedQuoteIsAnError) {
  test::TempDir dir;
  write_file_atomic(dir / "q.csv", "time_s,speed,curvature,caption\n0,1,0,\"fine, quoted\"\n1,2,0,\"abc\n");
  std::string e = error_of([&] { read_signals_csv(dir / "q.csv"); });
  EXPECT_TRUE(has(e, "q.csv:3: unterminated quote")) << e;
  write_file_atomic(dir / "h.csv", "time_s,speed,curvature,\"caption\n0,1,0,x\n");
  e = error_of([&] { read_signals_csv(dir / "h.csv"); });
  EXPECT_TRUE(has(e, "h.csv:1: unterminated quote")) << e;
  write_file_atomic(dir / "ok.csv", "time_s,speed,curvature,caption\n0,1,0,\"say \"\"hi\"\", go\"\n");
  EXPECT_EQ(read_signals_csv(dir / "ok.csv").caption_at(0), "say \"hi\", go");
}

TEST(DataHardening, SignalsMissingCellsStayMissingNeverInterpolatedAcross) {
  test::TempDir dir;
  write_file_atomic(dir / "m.csv", "time_s,speed,curvature\n0,10,0.1\n1,,0.2\n2,30,\n3,40,0.4\n4,,0.5\n");
  Signals s = read_signals_csv(dir / "m.csv");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // speed: row 1 missing -> (0, 2) missing; row 4 missing -> (3, 4] missing.
  const std::vector<std::pair<double, double>> speed = {{0, 10},    {0.5, nan}, {1, nan},  {1.5, nan}, {2, 30},
                                                        {2.5, 35},  {3, 40},    {3.5, nan}, {4, nan}};
  for (auto [t, want] : speed) {
    if (std::isnan(want)) EXPECT_TRUE(std::isnan(s.speed_at(t))) << t << " -> " << s.speed_at(t);
    else EXPECT_DOUBLE_EQ(s.speed_at(t), want) << t;
  }
  // curvature: row 2 missing -> (1, 3) missing.
  const std::vector<std::pair<double, double>> curv = {{0.5, 0.15}, {1, 0.2},   {1.5, nan}, {2, nan},
                                                       {2.5, nan},  {3, 0.4},   {3.5, 0.45}, {4, 0.5}};
  for (auto [t, want] : curv) {
    if (std::isnan(want)) EXPECT_TRUE(std::isnan(s.curvature_at(t))) << t << " -> " << s.curvature_at(t);
    else EXPECT_NEAR(s.curvature_at(t), want, 1e-12) << t;
  }
}

TEST(DataHardeningCli, IngestGapsGiveNaNAtExactFramesAndLowCoverageWarns) {
  test::TempDir dir;
  fs::path video = make_video(dir.path, 20);
  ASSERT_FALSE(video.empty());
  // Frames are at i / 25 s. Row 0.21 has no speed: frames strictly between 0.09 and 0.39 s (3..9) get none.
  write_file_atomic(dir / "sig.csv", "time_s,speed,curvature\n-0.01,5,0\n0.09,6,0.1\n0.21,,0.2\n0.39,9,0.3\n0.61,11,0.4\n");
  IngestOptions o = small();
  o.signals = dir / "sig.csv";
  IngestResult r = ingest_video(video, dir / "ds", o);
  ASSERT_EQ(r.meta.num_frames, 20);
  Episode ep(dir / "ds" / "episodes" / "clip");
  for (int i = 0; i < 20; ++i) {
    const double t = ep.time_s(i);
    ASSERT_NEAR(t, i / 25.0, 1e-3) << i;
    if (i <= 2) EXPECT_NEAR(ep.speed(i), 5 + (t + 0.01) / 0.1, 1e-4) << i;
    else if (i <= 9) EXPECT_TRUE(std::isnan(ep.speed(i))) << i << " -> " << ep.speed(i);
    else if (i <= 15) EXPECT_NEAR(ep.speed(i), 9 + (t - 0.39) / 0.22 * 2, 1e-4) << i;
    else EXPECT_TRUE(std::isnan(ep.speed(i))) << i;  // after the last row
    EXPECT_EQ(std::isnan(ep.curvature(i)), i > 15) << i;  // the curvature column has no gap
  }
  EXPECT_EQ(r.frames_with_speed, 9);
  EXPECT_DOUBLE_EQ(r.signal_coverage, 0.45);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_TRUE(has(r.warnings[0], "sig.csv")) << r.warnings[0];
  EXPECT_TRUE(has(r.warnings[0], "45.0%")) << r.warnings[0];
  EXPECT_TRUE(has(r.warnings[0], "9 of 20")) << r.warnings[0];

  // Full coverage: no warning.
  write_file_atomic(dir / "full.csv", "time_s,speed,curvature\n0,5,0\n1,6,0\n");
  o.signals = dir / "full.csv";
  o.id = "full";
  IngestResult f = ingest_video(video, dir / "ds", o);
  EXPECT_EQ(f.frames_with_speed, 20);
  EXPECT_TRUE(f.warnings.empty());

  // The app prints the warning as one "gaia: warning:" line and still succeeds.
  auto run = test::run_gaia("ingest " + q(video) + kSmall + " --signals " + q(dir / "sig.csv") + " --id cli --out " +
                            q(dir / "ds"));
  EXPECT_EQ(run.status, 0) << run.output;
  auto lines = said(run.output);
  ASSERT_EQ(lines.size(), 1u) << run.output;
  EXPECT_EQ(lines[0].rfind("gaia: warning: " + (dir / "sig.csv").string() + ": covers only 45.0% of the frames", 0), 0u)
      << run.output;
}

TEST(DataHardening, IngestFailsWhenSignalsCoverNoFrame) {
  test::TempDir dir;
  fs::path video = make_video(dir.path, 10);
  ASSERT_FALSE(video.empty());
  write_file_atomic(dir / "late.csv", "time_s,speed,curvature\n100,5,0\n200,6,0\n");
  IngestOptions o = small();
  o.signals = dir / "late.csv";
  std::string e = error_of([&] { ingest_video(video, dir / "ds", o); });
  EXPECT_TRUE(has(e, "late.csv")) << e;
  EXPECT_TRUE(has(e, "clip.avi")) << e;
  EXPECT_FALSE(has(e, "\n")) << e;
  EXPECT_FALSE(fs::exists(dir / "ds" / "episodes" / "clip"));
  EXPECT_TRUE(fs::is_empty(dir / "ds" / "episodes"));  // no staging leftovers either
}

TEST(DataHardeningCli, IngestRejectsBadFpsAndUnsafeIds) {
  test::TempDir dir;
  fs::path video = make_video(dir.path, 6);
  ASSERT_FALSE(video.empty());
  for (double fps : {-5.0, 1e9, 1000.5, std::numeric_limits<double>::quiet_NaN()}) {
    IngestOptions o = small();
    o.fps = fps;
    std::string e = error_of([&] { ingest_video(video, dir / "ds", o); });
    EXPECT_TRUE(has(e, "--fps")) << fps << " -> " << e;
    EXPECT_TRUE(has(e, "(0, 1000]")) << fps << " -> " << e;
  }
  for (std::string id : {"..", ".", ".hidden", ".tmp-x-1-0", "a/b", "../escape", "a b"}) {
    IngestOptions o = small();
    o.id = id;
    std::string e = error_of([&] { ingest_video(video, dir / "ds", o); });
    EXPECT_TRUE(has(e, "episode id '" + id + "'")) << id << " -> " << e;
  }
  EXPECT_FALSE(fs::exists(dir / "escape"));
  // A stated rate must agree with the one the video states (frame times come from its timestamps).
  IngestOptions o = small();
  o.id = "a.b-c_1";
  o.fps = 30;
  std::string e = error_of([&] { ingest_video(video, dir / "ds", o); });
  EXPECT_TRUE(has(e, "--fps 30 does not match the 25 fps")) << e;
  EXPECT_TRUE(has(e, "clip.avi")) << e;
  EXPECT_FALSE(fs::exists(dir / "ds" / "episodes" / "a.b-c_1"));
  o.fps = 25;
  EXPECT_EQ(ingest_video(video, dir / "ds", o).meta.fps, 25);

  // The app: one error line naming --fps and the range, for 0 too (the library's "not given").
  for (std::string v : {"0", "=-5", "1e9", "nan"}) {
    auto r = test::run_gaia("ingest " + q(video) + " --fps" + (v[0] == '=' ? v : " " + v) + " --out " + q(dir / "ds2"));
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << v << ": " << r.output;
    expect_one_error(r, "--fps");
    EXPECT_TRUE(has(r.output, "(0, 1000]")) << v << ": " << r.output;
  }
  expect_one_error(test::run_gaia("ingest " + q(video) + " --id .. --out " + q(dir / "ds2")), "episode id '..'");
  EXPECT_FALSE(fs::exists(dir / "ds2" / "episode.json"));
}

TEST(DataHardening, WriterRemovesStagingDirsOfDeadProcessesOnly) {
  test::TempDir dir;
  pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) ::_exit(0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);  // reaped: the pid no longer exists
  fs::path episodes = dir / "episodes";
  fs::path dead = episodes / fmt::format(".tmp-old-ep-{}-3", child);
  fs::path live = episodes / fmt::format(".tmp-busy-{}-0", ::getpid());
  fs::path odd = episodes / ".tmp-not-a-pid";
  for (auto& d : {dead, live, odd}) {
    fs::create_directories(d);
    write_file_atomic(d / "frames.bin", "x");
  }
  EpisodeMeta m;
  m.id = "new";
  m.height = 8;
  m.width = 8;
  EpisodeWriter w(dir.path, m);
  FrameRecord f;
  f.bgr = cv::Mat(8, 8, CV_8UC3, cv::Scalar(1, 2, 3));
  w.append(f);
  w.commit();
  EXPECT_FALSE(fs::exists(dead));
  EXPECT_TRUE(fs::exists(live / "frames.bin"));
  EXPECT_TRUE(fs::exists(odd / "frames.bin"));
  EXPECT_TRUE(fs::exists(episodes / "new" / "episode.json"));
}

TEST(DataHardeningCli, TruncatedVideoFailsUnlessAllowPartial) {
  test::TempDir dir;
  fs::path video = make_video(dir.path, 100);
  ASSERT_FALSE(video.empty());
  {
    cv::VideoCapture cap(video.string(), cv::CAP_FFMPEG);
    ASSERT_TRUE(cap.isOpened());
    ASSERT_NEAR(cap.get(cv::CAP_PROP_FRAME_COUNT), 100, 2);
  }
  // The whole file passes.
  IngestOptions o = small();
  o.id = "whole";
  EXPECT_EQ(ingest_video(video, dir / "ds", o).meta.num_frames, 100);

  fs::resize_file(video, fs::file_size(video) / 2);
  {
    cv::VideoCapture cap(video.string(), cv::CAP_FFMPEG);
    if (!cap.isOpened() || cap.get(cv::CAP_PROP_FRAME_COUNT) <= 0)
      GTEST_SKIP() << "this FFmpeg states no frame count for a truncated AVI";
  }
  o.id = "half";
  std::string e = error_of([&] { ingest_video(video, dir / "ds", o); });
  std::smatch m;
  ASSERT_TRUE(std::regex_search(e, m, std::regex("clip\\.avi: decoded ([0-9]+) of 100 frames: the file is truncated or "
                                                 "damaged; --allow-partial keeps the ([0-9]+)$")))
      << e;
  const int kept = std::stoi(m[1].str());
  EXPECT_EQ(std::stoi(m[2].str()), kept);
  EXPECT_GT(kept, 20);
  EXPECT_LT(kept, 80);
  EXPECT_FALSE(fs::exists(dir / "ds" / "episodes" / "half"));

  o.allow_partial = true;
  IngestResult r = ingest_video(video, dir / "ds", o);
  EXPECT_EQ(r.meta.num_frames, kept);
  EXPECT_EQ(r.container_frames, 100);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_TRUE(has(r.warnings[0], fmt::format("decoded {} of 100 frames", kept))) << r.warnings[0];

  // Stopping at --max-frames is not truncation.
  IngestOptions few = small();
  few.id = "few";
  few.max_frames = 10;
  IngestResult fr = ingest_video(video, dir / "ds", few);
  EXPECT_EQ(fr.meta.num_frames, 10);
  EXPECT_TRUE(fr.warnings.empty());

  // The app: one error line without the flag; with it, the episode and one warning line.
  auto bad = test::run_gaia("ingest " + q(video) + kSmall + " --id cli --out " + q(dir / "ds"));
  expect_one_error(bad, fmt::format("{}: decoded {} of 100 frames", video.string(), kept));
  EXPECT_TRUE(has(bad.output, "--allow-partial keeps the")) << bad.output;
  auto ok = test::run_gaia("ingest " + q(video) + kSmall + " --id cli --allow-partial --out " + q(dir / "ds"));
  EXPECT_EQ(ok.status, 0) << ok.output;
  auto lines = said(ok.output);
  ASSERT_EQ(lines.size(), 1u) << ok.output;
  EXPECT_EQ(lines[0].rfind(fmt::format("gaia: warning: {}: decoded {} of 100 frames", video.string(), kept), 0), 0u)
      << ok.output;
  EXPECT_TRUE(fs::exists(dir / "ds" / "episodes" / "cli" / "episode.json"));
}

TEST(DataHardeningCli, TruncatedMp4IsOneClearError) {
  test::TempDir dir;
  fs::path video = make_video(dir.path, 100, "clip.mp4");
  if (video.empty() || fs::file_size(video) == 0) GTEST_SKIP() << "no MPEG-4 encoder in this OpenCV/FFmpeg";
  fs::resize_file(video, fs::file_size(video) / 2);
  // Either it cannot be opened (the index is at the end) or it opens and decodes short: both one line naming it.
  auto r = test::run_gaia("ingest " + q(video) + " --out " + q(dir / "ds"));
  expect_one_error(r, "clip.mp4");
  EXPECT_TRUE(has(r.output, "truncated")) << r.output;
  EXPECT_FALSE(fs::exists(dir / "ds" / "episodes" / "clip"));
}
