// gaia synth / gaia synth replay through the binary: determinism across thread counts, replay files,
// and clear errors.
#include "gaia/data/episode.h"
#include "gaia/data/geofence.h"
#include "test_util.h"

using namespace gaia;

TEST(SynthCli, DeterministicWhateverTheThreadCount) {
  test::TempDir dir;
  auto a = test::run_gaia("synth --episodes 2 --seconds 1 --seed 9 --threads 1 --out '" + (dir / "a").string() + "'");
  auto b = test::run_gaia("synth --episodes 2 --seconds 1 --seed 9 --threads 2 --out '" + (dir / "b").string() + "'");
  ASSERT_EQ(a.status, 0) << a.output;
  ASSERT_EQ(b.status, 0) << b.output;
  data::Dataset da(dir / "a"), db(dir / "b");
  ASSERT_EQ(da.ids(), db.ids());
  for (auto& id : da.ids())
    for (auto f : {"frames.bin", "speed.npy", "curvature.npy", "captions.jsonl", "labels.jsonl"})
      EXPECT_EQ(read_file(dir / "a" / "episodes" / id / f), read_file(dir / "b" / "episodes" / id / f)) << id << f;
}

TEST(SynthCli, ReplayWritesAnEpisodeAndRejectsBadActions) {
  test::TempDir dir;
  ASSERT_EQ(test::run_gaia("synth --episodes 1 --seconds 2 --size 48x96 --out '" + (dir / "ds").string() + "'").status, 0);
  data::Dataset ds(dir / "ds");
  fs::path ep = dir / "ds" / "episodes" / ds.ids()[0];
  std::string csv = "speed,curvature\n";
  for (int i = 0; i < 10; ++i) csv += "8.0,0.03\n";
  write_file_atomic(dir / "left.csv", csv);
  auto r = test::run_gaia("synth replay '" + ep.string() + "' --from 20 --actions '" + (dir / "left.csv").string() +
                          "' --out '" + (dir / "cf").string() + "'");
  ASSERT_EQ(r.status, 0) << r.output;
  data::Dataset cf(dir / "cf");
  ASSERT_EQ(cf.size(), 1u);
  EXPECT_EQ(cf.episode(0).size(), 10);
  EXPECT_FLOAT_EQ(cf.episode(0).curvature(3), 0.03f);
  write_file_atomic(dir / "bad.csv", "speed,curvature\n8.0,nan\n");
  auto e = test::run_gaia("synth replay '" + ep.string() + "' --actions '" + (dir / "bad.csv").string() + "' --out '" +
                          (dir / "cf2").string() + "'");
  EXPECT_NE(e.status, 0);
  EXPECT_NE(e.output.find("bad.csv:2"), std::string::npos) << e.output;
  EXPECT_FALSE(fs::exists(dir / "cf2" / "episodes") && !fs::is_empty(dir / "cf2" / "episodes"));
  auto s = test::run_gaia("synth --size 72by128 --out '" + (dir / "x").string() + "'");
  EXPECT_NE(s.status, 0);
  EXPECT_NE(s.output.find("--size"), std::string::npos) << s.output;
  auto w = test::run_gaia("synth --weather hail --out '" + (dir / "x").string() + "'");
  EXPECT_NE(w.status, 0);
  EXPECT_NE(w.output.find("hail"), std::string::npos) << w.output;
}

// gaia synth counterfactuals replays the training split only: no held-out drive (what gaia eval prompts with) is
// ever shown to the world model under another command. Bad flags are one clear line.
TEST(SynthCli, CounterfactualsReplayOnlyTheTrainingDrives) {
  test::TempDir dir;
  ASSERT_EQ(test::run_gaia("synth --episodes 12 --seconds 1.2 --size 32x64 --seed 3 --out '" + (dir / "ds").string() + "'").status, 0);
  data::Dataset ds(dir / "ds");
  const data::Split split = data::load_or_default_split(ds, 0.1, 3);
  ASSERT_FALSE(split.held_out().empty());
  auto r = test::run_gaia("synth counterfactuals '" + (dir / "ds").string() + "' --per-episode 2 --lead 0.4 --hold 0.4 " +
                          "--seed 3 --out '" + (dir / "cf").string() + "'");
  ASSERT_EQ(r.status, 0) << r.output;
  data::Dataset cf(dir / "cf");
  EXPECT_EQ(cf.size(), split.train.size() * 2);
  for (size_t e = 0; e < cf.size(); ++e) {
    const std::string src = cf.meta(e).extra.at("replay_of");
    EXPECT_NE(std::find(split.train.begin(), split.train.end(), src), split.train.end()) << src;
  }
  // --without-meta leaves out drives by a metadata key (here the wandering drives of a second run into the source).
  ASSERT_EQ(test::run_gaia("synth --episodes 3 --first 12 --seconds 1.2 --size 32x64 --seed 3 --wander 1 --out '" +
                           (dir / "ds").string() + "'").status, 0);
  auto lk = test::run_gaia("synth counterfactuals '" + (dir / "ds").string() + "' --per-episode 1 --lead 0.4 --hold 0.4 " +
                           "--seed 3 --without-meta synth_wander --out '" + (dir / "cf-lk").string() + "'");
  ASSERT_EQ(lk.status, 0) << lk.output;
  data::Dataset cf_lk(dir / "cf-lk");
  EXPECT_EQ(cf_lk.size(), split.train.size());
  for (size_t e = 0; e < cf_lk.size(); ++e) EXPECT_FALSE(cf_lk.meta(e).extra.count("synth_wander"));
  auto same_dir = test::run_gaia("synth counterfactuals '" + (dir / "ds").string() + "' --out '" + (dir / "ds").string() + "'");
  EXPECT_NE(same_dir.status, 0);
  EXPECT_NE(same_dir.output.find("--out must not be the source"), std::string::npos) << same_dir.output;
  auto bad = test::run_gaia("synth counterfactuals '" + (dir / "ds").string() + "' --hold 0 --out '" + (dir / "cf5").string() + "'");
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("hold"), std::string::npos) << bad.output;
}
