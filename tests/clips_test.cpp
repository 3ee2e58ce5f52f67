// A folder of real clips with a manifest: repeated frames found and dropped, the manifest's columns checked and
// turned into metadata and captions, held-out groups that cover every condition, `gaia ingest DIR --manifest`
// (resumable, one line per failed clip) and `gaia data motion` from the recording itself.
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "gaia/core/fs.h"
#include "gaia/data/episode.h"
#include "gaia/data/geofence.h"
#include "gaia/data/holdout.h"
#include "gaia/data/ingest.h"
#include "gaia/data/manifest.h"
#include "gaia/data/repeats.h"
#include "gaia/data/video_io.h"
#include "test_util.h"

using namespace gaia;
using namespace gaia::data;
using test::error_of;
using test::q;

namespace {

// A frame of a moving texture: every frame differs from the one before everywhere a block can see.
cv::Mat moving_frame(int i, int h = 120, int w = 160) {
  cv::Mat f(h, w, CV_8UC3, cv::Scalar(60, 90, 110));
  cv::RNG rng(7);
  for (int k = 0; k < 60; ++k) {
    const int x = (rng.uniform(0, w) + 6 * i) % w, y = rng.uniform(0, h);
    cv::circle(f, {x, y}, rng.uniform(3, 9), cv::Scalar(rng.uniform(0, 255), rng.uniform(0, 255), 255), cv::FILLED);
  }
  return f;
}

// `n` camera frames written `hold` times each into an MJPG AVI at `fps` (a container holding a slower camera).
fs::path write_clip(const fs::path& p, int n, int hold, double fps) {
  cv::VideoWriter vw(p.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), fps, cv::Size(160, 120));
  EXPECT_TRUE(vw.isOpened()) << p;
  for (int i = 0; i < n; ++i)
    for (int r = 0; r < hold; ++r) vw.write(moving_frame(i));
  return p;
}

}  // namespace

TEST(Repeats, FoundInHeldFramesAndNotInSlowMotion) {
  // A 20 Hz camera held five times (coding noise up to a few grey levels between the copies) ...
  std::vector<double> held{0, 0.3, 0.5, 2.7, 0.4, 25, 0.2, 0.9, 1.3, 0.1, 31, 0.0, 0.4, 2.0, 0.6, 28};
  auto r = find_repeats(held);
  for (size_t i = 1; i < held.size(); ++i) EXPECT_EQ(r[i], held[i] < 10) << i;
  // ... against a slow night drive whose frames all change a little, and a still scene (coding noise alone).
  std::vector<double> slow{0, 2.1, 3.2, 2.6, 4.0, 7.3, 6.0, 3.8, 6.1, 2.4, 3.0};
  for (bool b : find_repeats(slow)) EXPECT_FALSE(b);
  std::vector<double> still{0, 0.2, 0.3, 0.1, 0.2};
  auto s = find_repeats(still);
  EXPECT_FALSE(s[0]);  // the first frame is always kept
  for (size_t i = 1; i < s.size(); ++i) EXPECT_TRUE(s[i]);

  // The measure itself: nothing for a copy, a large change for a moved scene (coding noise on real footage:
  // Ingest.RepeatedFramesOfARealClip).
  const cv::Mat a = change_thumbnail(moving_frame(0)), b = change_thumbnail(moving_frame(1));
  EXPECT_EQ(frame_change(a, a), 0);
  EXPECT_GT(frame_change(a, b), 10);

  // The camera's rate from the kept frames' times: 25 Hz in a 30 fps container (every sixth frame a repeat),
  // and a stop whose still frames were dropped does not lower it.
  std::vector<double> t;
  for (int i = 0; i < 60; ++i)
    if (i % 6 != 5) t.push_back(i / 30.0);
  EXPECT_NEAR(kept_frame_rate(t), 25.0, 0.6);
  std::vector<double> stop{0, 0.05, 0.10, 0.15, 2.15, 2.20, 2.25};
  EXPECT_NEAR(kept_frame_rate(stop), 20.0, 1e-6);
  EXPECT_EQ(kept_frame_rate({1.0}), 0);
}

TEST(Manifest, ReadsColumnsAndRefusesUnknownValues) {
  test::TempDir d;
  const fs::path csv = d / "clips.csv";
  write_file_atomic(csv,
                    "file,fps,weather,time_of_day,road,source_repo,place,notes\n"
                    "a.mp4,20,clear,day,highway,owner/repo,\"Seattle, USA (downtown)\",\"held, twice\"\n"
                    "b.mp4,,Rain,night,city,owner/other,Berlin,\n");
  const Manifest m = read_manifest(csv, d.path);
  ASSERT_EQ(m.rows.size(), 2u);
  EXPECT_EQ(m.rows[0].id, "a");
  EXPECT_EQ(m.rows[0].path, d.path / "a.mp4");
  EXPECT_DOUBLE_EQ(m.rows[0].fps, 20);
  EXPECT_EQ(m.rows[0].get("place"), "Seattle, USA (downtown)");
  EXPECT_EQ(m.rows[0].get("notes"), "held, twice");
  EXPECT_EQ(m.rows[0].columns.count("fps"), 0u);  // a rate, not metadata
  EXPECT_EQ(m.rows[1].weather(), "rain");         // values are lower-cased
  EXPECT_EQ(m.rows[1].fps, 0);
  EXPECT_EQ(m.rows[1].columns.count("notes"), 0u);  // empty cells are no metadata
  // Captions share the procedural world's words for the conditions, and name the road.
  const std::string c = manifest_caption(m.rows[1], 3.0);
  EXPECT_NE(c.find("night"), std::string::npos) << c;
  EXPECT_NE(c.find("rain"), std::string::npos) << c;
  EXPECT_NE(c.find("in the city"), std::string::npos) << c;
  EXPECT_EQ(manifest_caption(m.rows[1], 3.5), c);  // the same second, the same words

  auto bad = [&](const std::string& body) {
    write_file_atomic(d / "bad.csv", body);
    return error_of([&] { read_manifest(d / "bad.csv", d.path); });
  };
  std::string e = bad("file,weather\na.mp4,clear\nb.mp4,sunny\n");
  EXPECT_NE(e.find("bad.csv:3"), std::string::npos) << e;
  EXPECT_NE(e.find("clip b.mp4"), std::string::npos) << e;
  EXPECT_NE(e.find("'weather' is 'sunny'"), std::string::npos) << e;
  e = bad("file,road\na.mp4,motorway\n");
  EXPECT_NE(e.find("'road' is 'motorway'"), std::string::npos) << e;
  e = bad("file,fps\na.mp4,fast\n");
  EXPECT_NE(e.find("'fps' is 'fast'"), std::string::npos) << e;
  e = bad("name,fps\na.mp4,20\n");
  EXPECT_NE(e.find("no 'file' column"), std::string::npos) << e;
  e = bad("file,fps\na.mp4,20,3\n");
  EXPECT_NE(e.find("3 cells where the header names 2"), std::string::npos) << e;
  e = bad("file\nx/a.mp4\ny/a.mp4\n");
  EXPECT_NE(e.find("'a' appears twice"), std::string::npos) << e;
  EXPECT_NE(error_of([&] { read_manifest(d / "none.csv", d.path); }).find("none.csv"), std::string::npos);
}

TEST(HoldOut, WholeGroupsCoverEveryConditionTheClipsAllow) {
  auto ep = [](const std::string& id, const std::string& src, const std::string& place, const std::string& time,
               const std::string& weather, const std::string& road, int64_t frames) {
    EpisodeMeta m;
    m.id = id;
    m.time_of_day = time;
    m.weather = weather;
    m.extra = {{"source_repo", src}, {"place", place}, {"road", road}};
    m.num_frames = frames;
    return m;
  };
  const std::vector<EpisodeMeta> eps = {
      ep("big-day", "big", "Seattle, USA (downtown)", "day", "clear", "city", 1000),
      ep("big-day2", "big", "Seattle, USA (freeway)", "day", "overcast", "highway", 900),  // the same place
      ep("big-night", "big", "unknown (North America)", "night", "clear", "highway", 1000),
      ep("big-rain", "big", "unknown (North America)", "day", "rain", "highway", 900),
      ep("berlin-night", "berlin", "Berlin, Germany", "night", "clear", "city", 600),
      ep("berlin-tunnel", "berlin", "Berlin, Germany", "night", "clear", "tunnel", 150),  // a tunnel: one group only
      ep("rainy", "wet", "mountains", "day", "rain", "rural", 1200),
      ep("small", "tiny", "Taiwan", "day", "overcast", "city", 100),
      ep("small2", "tiny", "Taiwan", "day", "clear", "rural", 100),
      ep("fog", "foggy", "", "day", "fog", "rural", 400)};
  const auto h = hold_out_groups(eps, {"source_repo", "place"}, {"weather", "time_of_day", "road"}, 0.15, 1);
  auto held = [&](const std::string& id) { return std::count(h.episodes.begin(), h.episodes.end(), id) > 0; };
  // Whole groups: the two Seattle clips go together, as do the two of one unknown place, and Berlin's.
  EXPECT_EQ(held("big-day"), held("big-day2"));
  EXPECT_EQ(held("big-night"), held("big-rain"));
  EXPECT_EQ(held("berlin-night"), held("berlin-tunnel"));
  // Berlin alone has a tunnel, and fog one group alone: both stay in training and are reported.
  EXPECT_FALSE(held("berlin-tunnel"));
  EXPECT_FALSE(held("fog"));
  EXPECT_NE(std::find(h.uncovered.begin(), h.uncovered.end(), "road=tunnel"), h.uncovered.end());
  EXPECT_NE(std::find(h.uncovered.begin(), h.uncovered.end(), "weather=fog"), h.uncovered.end());
  // Night (two groups hold it) and rain have a held-out group, and training keeps some of each.
  EXPECT_TRUE(held("big-night"));
  for (const std::string v : {"night", "rain", "day"}) {
    bool in_val = false, in_train = false;
    for (const auto& m : eps) (held(m.id) ? in_val : in_train) |= m.time_of_day == v || m.weather == v;
    EXPECT_TRUE(in_val && in_train) << v;
  }
  EXPECT_GE(double(h.frames), 0.15 * double(h.total_frames));
  EXPECT_EQ(h.total_frames, 6350);
  // The same seed picks the same groups.
  EXPECT_EQ(hold_out_groups(eps, {"source_repo", "place"}, {"weather", "time_of_day", "road"}, 0.15, 1).episodes,
            h.episodes);
  EXPECT_NE(error_of([&] { hold_out_groups({eps[0], eps[1]}, {"source_repo"}, {}, 0.1, 1); }).find("1 group"),
            std::string::npos);
}

// The manifest's clips in one command: repeats dropped (a 25 Hz camera held twice in a 50 fps container), metadata
// and captions from the columns, a missing clip and one too short for a training window each one line naming them,
// the others kept, a non-zero exit; a second run skips what is there. A bad column value stops before any clip.
TEST(IngestManifestCli, AFolderOfClipsResumableWithRepeatsDropped) {
  test::TempDir d;
  fs::create_directories(d / "clips");
  write_clip(d / "clips" / "held.avi", 60, 2, 50);  // 2.4 s of a 25 Hz camera in 120 frames at 50 fps
  write_clip(d / "clips" / "plain.avi", 40, 1, 20);
  write_clip(d / "clips" / "short.avi", 10, 1, 20);  // 0.5 s: shorter than one window of the tiny config
  write_file_atomic(d / "clips" / "clips.csv",
                    "file,fps,weather,time_of_day,road,source_repo,place\n"
                    "held.avi,50,rain,night,highway,a/one,\"Seattle, USA\"\n"
                    "plain.avi,,clear,day,city,b/two,Berlin\n"
                    "gone.avi,,clear,day,city,b/two,Berlin\n"
                    "short.avi,,fog,dusk,rural,c/three,\n");
  const std::string base = "ingest " + q(d / "clips") + " --manifest clips.csv --config " +
                           q(test::source_dir() / "configs" / "tiny.yaml") + " --out " + q(d / "ds");
  auto r = test::run_gaia(base);
  EXPECT_NE(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("clip gone.avi): column 'file'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("short.avi: its 10 frames span"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("2 of 4 clips failed (gone, short)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("held: dropped 60 of 120 frames that repeat the one before (50 fps container, 25 Hz "
                          "camera)"), std::string::npos) << r.output;
  Dataset ds(d / "ds");
  ASSERT_EQ(ds.size(), 2u);  // nothing of the failed clips
  EXPECT_FALSE(fs::exists(d / "ds" / "episodes" / "short"));
  Episode held(d / "ds" / "episodes" / "held");
  EXPECT_EQ(held.size(), 60);
  EXPECT_NEAR(held.meta().fps, 25, 0.1);
  for (int64_t i = 1; i < held.size(); ++i) EXPECT_NEAR(held.time_s(i) - held.time_s(i - 1), 0.04, 1e-3) << i;
  EXPECT_EQ(held.meta().weather, "rain");
  EXPECT_EQ(held.meta().time_of_day, "night");
  EXPECT_EQ(held.meta().extra.at("road"), "highway");
  EXPECT_EQ(held.meta().extra.at("source_repo"), "a/one");
  EXPECT_EQ(held.meta().extra.at("place"), "Seattle, USA");
  EXPECT_NE(held.caption(0).find("highway"), std::string::npos) << held.caption(0);
  Episode plain(d / "ds" / "episodes" / "plain");
  EXPECT_EQ(plain.size(), 40);  // nothing repeats
  EXPECT_NEAR(plain.meta().fps, 20, 1e-6);

  // Resumed: what is there is skipped; with the missing clip put right, the run ends well.
  write_clip(d / "clips" / "gone.avi", 40, 1, 20);
  r = test::run_gaia(base);
  EXPECT_NE(r.status, 0) << r.output;  // short.avi is still too short
  EXPECT_NE(r.output.find("ingested 1 clips, 2 already there, 1 failed"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(d / "ds" / "episodes" / "gone" / "episode.json"));

  // A value the manifest may not hold: one line naming the clip and the column, and nothing ingested.
  write_file_atomic(d / "clips" / "typo.csv", "file,weather\nplain.avi,sunny\n");
  r = test::run_gaia("ingest " + q(d / "clips") + " --manifest " + q(d / "clips" / "typo.csv") + " --out " +
                     q(d / "ds2"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("typo.csv:2 (clip plain.avi): column 'weather' is 'sunny'"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "ds2" / "episodes"));

  // Procedural drives beside the clips: --hold-out-by groups the recorded clips and holds the procedural drives out
  // exactly as the default split does (the drives the shipped models were validated on stay held out).
  r = test::run_gaia("synth --episodes 12 --seconds 1 --size 32x64 --seed 1 --threads 1 --out " + q(d / "ds"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("data split " + q(d / "ds") + " --hold-out-by source_repo,place --cover licence --seed 5");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("procedural drives: "), std::string::npos) << r.output;
  const Split split = read_split(d / "ds" / "split.json");
  const auto held_ids = split.held_out();
  Dataset mixed(d / "ds");
  int procedural_held = 0;
  std::vector<std::string> recorded_held;
  for (size_t e = 0; e < mixed.size(); ++e) {
    const auto& m = mixed.meta(e);
    const bool out = std::find(held_ids.begin(), held_ids.end(), m.id) != held_ids.end();
    if (m.is_procedural()) {
      EXPECT_EQ(out, held_out_at_random(m.id, kDefaultValFraction, 5)) << m.id;
      procedural_held += out;
    } else {
      if (out) recorded_held.push_back(m.id);
    }
  }
  // Nothing to cover: the smallest group up to 15% of the recorded frames (procedural ones, shorter, do not count).
  EXPECT_EQ(recorded_held, std::vector<std::string>{"held"}) << r.output;
  EXPECT_LT(procedural_held, 12);

  // gaia data motion goes back to the recording; without it, it refuses rather than estimate from 32x64 frames.
  fs::remove(d / "clips" / "plain.avi");
  r = test::run_gaia("data motion " + q(d / "ds") + " --episodes plain");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("plain: its recording"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("is not at hand"), std::string::npos) << r.output;
}

// A real clip whose container holds each camera frame five times: 1000 frames at 100 fps are a 20 Hz camera.
TEST(Ingest, RepeatedFramesOfARealClip) {
  const fs::path real = test::real_data_dir();
  const fs::path clip = real / "clips" / "day-highway-billzito.mp4";
  if (real.empty() || !fs::exists(clip)) GTEST_SKIP() << "shared real clips not found (../shared/data/real/clips)";
  test::TempDir d;
  IngestOptions o;
  const auto res = ingest_video(clip, d / "ds", o);
  EXPECT_EQ(res.frames_decoded, 1000);
  EXPECT_NEAR(double(res.meta.num_frames), 200, 6);
  EXPECT_NEAR(res.meta.fps, 20, 0.5);
  EXPECT_NEAR(res.container_fps, 100, 0.5);
}
