// Episode store, signals CSV, ingestion (synthetic and real clips) and clip sampling by timestamps.
#include <cmath>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "gaia/core/error.h"
#include "gaia/data/clip_sampler.h"
#include "gaia/data/episode.h"
#include "gaia/data/ingest.h"
#include "gaia/data/signals.h"
#include "gaia/data/video_io.h"
#include "test_util.h"

using namespace gaia;
using test::error_of;
using namespace gaia::data;

namespace {

cv::Mat pattern(int h, int w, int k) {
  cv::Mat m(h, w, CV_8UC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) m.at<cv::Vec3b>(y, x) = cv::Vec3b(uchar(x * 3 + k), uchar(y * 5), uchar(k * 20));
  return m;
}

// A small MJPG/MP4 clip with a moving bar, `n` frames at `fps`.
fs::path make_video(const fs::path& dir, int n, double fps, int w = 160, int h = 120) {
  fs::path p = dir / "clip.avi";
  cv::VideoWriter vw(p.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), fps, cv::Size(w, h));
  EXPECT_TRUE(vw.isOpened());
  for (int i = 0; i < n; ++i) {
    cv::Mat f(h, w, CV_8UC3, cv::Scalar(40, 80, 120));
    cv::rectangle(f, cv::Rect((i * 7) % w, 0, 10, h), cv::Scalar(255, 255, 255), cv::FILLED);
    vw.write(f);
  }
  return p;
}


}  // namespace

TEST(EpisodeStore, RoundTripAllCodecsWithMissingSignals) {
  test::TempDir dir;
  for (std::string codec : {"raw", "png", "jpg"}) {
    EpisodeMeta m;
    m.id = "ep_" + codec;
    m.height = 24;
    m.width = 40;
    m.frame_codec = codec;
    m.weather = "rain";
    m.latitude = 51.5;
    m.longitude = -0.12;
    EpisodeWriter w(dir.path, m);
    for (int i = 0; i < 5; ++i) {
      FrameRecord r;
      r.bgr = pattern(24, 40, i);
      r.time_s = i * 0.04;
      if (i != 2) { r.speed = 10.0f + i; r.curvature = 0.01f * i; }
      r.caption = i == 3 ? "slowing, \"quoted\"" : "";
      w.append(r);
    }
    w.commit();
  }
  Dataset ds(dir.path);
  ASSERT_EQ(ds.size(), 3u);
  for (size_t e = 0; e < ds.size(); ++e) {
    Episode ep = ds.episode(e);
    ASSERT_EQ(ep.size(), 5);
    EXPECT_EQ(ep.meta().weather, "rain");
    EXPECT_DOUBLE_EQ(ep.meta().latitude, 51.5);
    EXPECT_TRUE(std::isnan(ep.speed(2)));  // missing stays missing, never zero
    EXPECT_TRUE(std::isnan(ep.curvature(2)));
    EXPECT_FLOAT_EQ(ep.speed(4), 14.0f);
    EXPECT_EQ(ep.caption(3), "slowing, \"quoted\"");
    EXPECT_DOUBLE_EQ(ep.time_s(4), 0.16);
    // random access in any order
    for (int i : {4, 0, 3}) {
      cv::Mat f = ep.frame_bgr(i), want = pattern(24, 40, i);
      double err = cv::norm(f, want, cv::NORM_INF);
      if (ep.meta().frame_codec == "jpg") EXPECT_LT(cv::norm(f, want, cv::NORM_L1) / f.total() / 3, 3.0);
      else EXPECT_EQ(err, 0) << ep.meta().frame_codec;
    }
  }
  // An existing episode is not overwritten silently.
  EpisodeMeta dup;
  dup.id = "ep_raw";
  dup.height = 24;
  dup.width = 40;
  EXPECT_NE(error_of([&] { EpisodeWriter w(dir.path, dup); }).find("already exists"), std::string::npos);
}

TEST(EpisodeStore, AbandonedWriterLeavesNoEpisodeAndCorruptionIsReported) {
  test::TempDir dir;
  {
    EpisodeMeta m;
    m.id = "half";
    m.height = 8;
    m.width = 8;
    EpisodeWriter w(dir.path, m);
    FrameRecord r;
    r.bgr = pattern(8, 8, 0);
    w.append(r);
    // destroyed without commit(): e.g. an exception mid-ingest
  }
  Dataset ds(dir.path);
  EXPECT_EQ(ds.size(), 0u);
  EXPECT_TRUE(fs::is_empty(dir / "episodes"));

  EpisodeMeta m;
  m.id = "ok";
  m.height = 8;
  m.width = 8;
  EpisodeWriter w(dir.path, m);
  FrameRecord r;
  r.bgr = pattern(8, 8, 0);
  w.append(r);
  r.time_s = 0.04;
  w.append(r);
  FrameRecord wrong;
  wrong.bgr = pattern(9, 8, 0);
  wrong.time_s = 1;
  EXPECT_NE(error_of([&] { w.append(wrong); }).find("expected 8x8"), std::string::npos);
  w.commit();
  fs::resize_file(dir / "episodes" / "ok" / "frames.bin", 100);
  std::string e = error_of([&] { Episode ep(dir / "episodes" / "ok"); });
  EXPECT_NE(e.find("frames.bin"), std::string::npos) << e;
  EXPECT_NE(error_of([&] { Dataset d(dir / "nothing"); }).find("no such dataset"), std::string::npos);
}

TEST(Signals, InterpolationAndMissingValues) {
  test::TempDir dir;
  write_file_atomic(dir / "s.csv", "time_s,speed,curvature,caption\n0,10,0.0,start\n1,20,,\"left bend, rain\"\n2,30,0.02,\n");
  Signals s = read_signals_csv(dir / "s.csv");
  EXPECT_DOUBLE_EQ(s.speed_at(0.5), 15.0);
  EXPECT_DOUBLE_EQ(s.speed_at(1.5), 25.0);
  // empty cell: missing, neither read as 0 nor interpolated across (README: empty cells stay NaN)
  EXPECT_TRUE(std::isnan(s.curvature_at(1.0)));
  EXPECT_TRUE(std::isnan(s.curvature_at(0.5)));
  EXPECT_TRUE(std::isnan(s.curvature_at(1.5)));
  EXPECT_DOUBLE_EQ(s.curvature_at(2.0), 0.02);
  EXPECT_TRUE(std::isnan(s.speed_at(-0.1)));     // outside the recorded span: missing
  EXPECT_TRUE(std::isnan(s.speed_at(2.5)));
  EXPECT_EQ(s.caption_at(1.2), "left bend, rain");
  EXPECT_EQ(s.caption_at(0.3), "start");

  write_file_atomic(dir / "cols.csv", "time,speed,curvature\n0,1,2\n");
  EXPECT_NE(error_of([&] { read_signals_csv(dir / "cols.csv"); }).find("cols.csv:1"), std::string::npos);
  write_file_atomic(dir / "nan.csv", "time_s,speed,curvature\n0,1,0.2\n1,nan,0.2\n");
  std::string e = error_of([&] { read_signals_csv(dir / "nan.csv"); });
  EXPECT_NE(e.find("nan.csv:3"), std::string::npos) << e;
  EXPECT_NE(e.find("speed"), std::string::npos) << e;
  write_file_atomic(dir / "short.csv", "time_s,speed,curvature\n0,1\n");
  EXPECT_NE(error_of([&] { read_signals_csv(dir / "short.csv"); }).find("short.csv:2: expected 3 columns"), std::string::npos);
}

TEST(Ingest, VideoWithSignalsResizesAndKeepsTimestamps) {
  test::TempDir dir;
  fs::path video = make_video(dir.path, 20, 25.0);
  write_file_atomic(dir / "sig.csv", "time_s,speed,curvature\n0.0,5,0.01\n0.4,9,0.03\n");
  IngestOptions o;
  o.height = 36;
  o.width = 64;
  o.signals = dir / "sig.csv";
  o.meta = {{"weather", "fog"}, {"latitude", "51.5"}, {"longitude", "-0.1"}, {"driver", "a"}};
  EpisodeMeta m = ingest_video(video, dir / "ds", o).meta;
  EXPECT_EQ(m.num_frames, 20);
  Episode ep(dir / "ds" / "episodes" / "clip");
  EXPECT_EQ(ep.meta().weather, "fog");
  EXPECT_EQ(ep.meta().extra.at("driver"), "a");
  EXPECT_NEAR(ep.meta().fps, 25.0, 1e-6);
  EXPECT_EQ(ep.frame_bgr(0).rows, 36);
  EXPECT_EQ(ep.frame_bgr(0).cols, 64);
  for (int i = 0; i < 20; ++i) EXPECT_NEAR(ep.time_s(i), i / 25.0, 1e-3) << i;
  EXPECT_NEAR(ep.speed(5), 7.0, 1e-3);  // t = 0.2 s: halfway
  EXPECT_NEAR(ep.curvature(5), 0.02, 1e-4);
  EXPECT_TRUE(std::isnan(ep.speed(15)));  // t = 0.6 s: after the last signal sample -> missing

  EXPECT_NE(error_of([&] { ingest_video(dir / "nope.mp4", dir / "ds2", o); }).find("nope.mp4"), std::string::npos);
  write_file_atomic(dir / "junk.mp4", "this is not a video");
  std::string e = error_of([&] { ingest_video(dir / "junk.mp4", dir / "ds2", o); });
  EXPECT_NE(e.find("junk.mp4"), std::string::npos) << e;
  EXPECT_FALSE(fs::exists(dir / "ds2" / "episodes" / "junk"));
  o.meta = {{"latitude", "north"}};
  EXPECT_NE(error_of([&] { ingest_video(video, dir / "ds3", o); }).find("latitude"), std::string::npos);
}

TEST(Ingest, ResizeCenterCropKeepsAspect) {
  cv::Mat wide(720, 1280, CV_8UC3, cv::Scalar(0, 0, 0));
  cv::rectangle(wide, cv::Rect(0, 0, 100, 720), cv::Scalar(255, 255, 255), cv::FILLED);  // left edge: cropped away?
  cv::Mat out = resize_center_crop(wide, 72, 128);  // 16:9 -> 16:9, nothing cropped
  EXPECT_EQ(out.size(), cv::Size(128, 72));
  EXPECT_GT(out.at<cv::Vec3b>(36, 2)[0], 200);
  cv::Mat sq = resize_center_crop(wide, 64, 64);    // square: the sides are cropped
  EXPECT_LT(sq.at<cv::Vec3b>(32, 0)[0], 10);
}

TEST(Ingest, RealClipsFromSharedData) {
  fs::path real = test::real_data_dir();
  if (real.empty() || !fs::exists(real / "highway-sunny-720p25.mp4")) GTEST_SKIP() << "shared real clips not found";
  test::TempDir dir;
  IngestOptions o;
  o.max_frames = 30;
  EpisodeMeta m = ingest_video(real / "highway-sunny-720p25.mp4", dir / "ds", o).meta;
  EXPECT_EQ(m.num_frames, 30);
  EXPECT_NEAR(m.fps, 25.0, 0.01);
  Episode ep(dir / "ds" / "episodes" / m.id);
  for (int i = 1; i < 30; ++i) EXPECT_NEAR(ep.time_s(i) - ep.time_s(i - 1), 0.04, 2e-3);
  cv::Scalar mean = cv::mean(ep.frame_bgr(10));
  EXPECT_GT(mean[0] + mean[1] + mean[2], 60);  // a real, non-black picture
  // The whole clip: its MP4 holds 116 packets but presents 100 frames (an edit list cuts the first 0.64 s), which
  // is not a truncation.
  IngestOptions whole;
  whole.id = "whole";
  const auto w = ingest_video(real / "highway-sunny-720p25.mp4", dir / "ds", whole);
  EXPECT_EQ(w.meta.num_frames, 100);
  EXPECT_EQ(w.container_frames, 100);
  EXPECT_TRUE(w.warnings.empty());

  // 29.97 fps MPEG-4: timestamps follow the container's rate.
  EpisodeMeta n = ingest_video(real / "night-rural-1080p30.mp4", dir / "ds", [&] { auto p = o; p.max_frames = 31; return p; }()).meta;
  Episode night(dir / "ds" / "episodes" / n.id);
  EXPECT_NEAR(night.time_s(30) - night.time_s(0), 30 / 29.97, 0.01);
  // KITTI: greyscale PNG directory at 10 Hz.
  IngestOptions k = o;
  k.fps = 10;
  k.max_frames = 12;
  EpisodeMeta km = ingest_video(real / "kitti-residential-gray-10hz", dir / "ds", k).meta;
  Episode kitti(dir / "ds" / "episodes" / km.id);
  EXPECT_EQ(kitti.size(), 12);
  EXPECT_NEAR(kitti.time_s(11), 1.1, 1e-9);
}

TEST(ClipSampler, RatesByTimestamps) {
  auto times = [](double fps, int n) {
    std::vector<double> t(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) t[static_cast<size_t>(i)] = i / fps;
    return t;
  };
  // 25 Hz -> 6.25 Hz: every 4th frame (paper §2.3)
  EXPECT_EQ(clip_indices(times(25, 100), 0, 5, 6.25), (std::vector<int64_t>{0, 4, 8, 12, 16}));
  // 30 fps: nearest frames to k * 0.16 s = 0, 4.8, 9.6, 14.4, 19.2 frames
  EXPECT_EQ(clip_indices(times(30, 100), 0, 5, 6.25), (std::vector<int64_t>{0, 5, 10, 14, 19}));
  // 20 fps: 0, 3.2, 6.4, 9.6, 12.8
  EXPECT_EQ(clip_indices(times(20, 100), 0, 5, 6.25), (std::vector<int64_t>{0, 3, 6, 10, 13}));
  // 25 Hz -> 12.5 Hz and 25 Hz (decoder rates)
  EXPECT_EQ(clip_indices(times(25, 100), 0.4, 3, 12.5), (std::vector<int64_t>{10, 12, 14}));
  EXPECT_EQ(clip_indices(times(25, 100), 0, 3, 25), (std::vector<int64_t>{0, 1, 2}));
  // A clip that runs past the end is refused.
  EXPECT_TRUE(clip_indices(times(25, 10), 0, 5, 6.25).empty());
  // The achieved spacing is close to 1/rate for any source rate.
  for (double fps : {20.0, 24.0, 25.0, 29.97, 30.0, 60.0}) {
    auto t = times(fps, 400);
    auto idx = clip_indices(t, 0.1, 26, 6.25);
    ASSERT_EQ(idx.size(), 26u) << fps;
    for (size_t k = 0; k < idx.size(); ++k) EXPECT_LE(std::abs(t[static_cast<size_t>(idx[k])] - (0.1 + k / 6.25)), 0.5 / fps + 1e-9);
  }
}

TEST(ClipSampler, SpreadClipsCoverEveryEpisodeAwayFromTheStart) {
  test::TempDir dir;
  test::synth_dataset(dir / "ds", 3, 2.0, 0, 16, 32);  // 50 frames at 25 Hz
  test::synth_dataset(dir / "ds", 1, 0.2, 3, 16, 32);  // 5 frames: too short for a 9-frame clip
  Dataset ds(dir / "ds");
  ASSERT_EQ(ds.size(), 4u);
  // One clip per episode, each a fraction (i + 0.5) / 4 of the way through its 50 - 8 possible starts; the short
  // episode is skipped.
  auto c = spread_clips(ds, {0, 1, 2, 3}, 9, 25.0, 4);
  ASSERT_EQ(c.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(c[i].episode, i);
    ASSERT_EQ(c[i].frames.size(), 9u);
    for (size_t k = 1; k < 9; ++k) EXPECT_EQ(c[i].frames[k], c[i].frames[k - 1] + 1);
    EXPECT_NEAR(double(c[i].frames[0]), (i + 0.5) / 4 * 41, 1.0) << i;
  }
  // More clips than episodes: two per episode, at different places.
  auto d = spread_clips(ds, {0, 1, 2}, 9, 25.0, 6);
  ASSERT_EQ(d.size(), 6u);
  for (size_t i = 0; i < 6; ++i) EXPECT_EQ(d[i].episode, i / 2) << i;
  for (size_t i = 0; i < 6; i += 2) EXPECT_LT(d[i].frames[0], d[i + 1].frames[0]) << i;
  EXPECT_TRUE(spread_clips(ds, {}, 9, 25.0, 3).empty());
}
