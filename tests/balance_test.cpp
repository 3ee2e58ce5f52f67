// Balanced sampling (paper §3): exponents 0, 0.5 and 1 give the empirical, square-root and uniform
// distributions, checked statistically by actually sampling; the geofenced split; mirror images and their split.
#include <cmath>
#include <random>

#include "gaia/core/error.h"
#include "gaia/data/balance.h"
#include "gaia/data/geofence.h"
#include "gaia/data/mirror.h"
#include "test_util.h"

using namespace gaia;
using namespace gaia::data;

namespace {

// A skewed weather distribution: 70% clear, 20% rain, 8% fog, 2% snow.
std::vector<FeatureRow> weather_rows() {
  std::vector<FeatureRow> rows;
  const std::pair<const char*, int> counts[] = {{"clear", 700}, {"rain", 200}, {"fog", 80}, {"snow", 20}};
  for (auto& [w, n] : counts)
    for (int i = 0; i < n; ++i) {
      FeatureRow r;
      r.cat["weather"] = w;
      rows.push_back(r);
    }
  return rows;
}

// Chi-square statistic of observed counts against expected probabilities.
double chi2(const std::map<std::string, double>& obs, const std::map<std::string, double>& p, double n) {
  double x = 0;
  for (auto& [k, pk] : p) {
    double e = pk * n, o = obs.count(k) ? obs.at(k) : 0;
    x += (o - e) * (o - e) / e;
  }
  return x;
}

}  // namespace

TEST(Balance, ExponentsGiveEmpiricalSqrtAndUniformDistributions) {
  auto rows = weather_rows();
  const std::map<std::string, double> emp{{"clear", 0.7}, {"rain", 0.2}, {"fog", 0.08}, {"snow", 0.02}};
  for (double ex : {0.0, 0.5, 1.0}) {
    Balancer b({"weather"}, ex, 10);
    b.fit(rows);
    std::map<std::string, double> expect;
    double z = 0;
    for (auto& [k, p] : emp) z += std::pow(p, 1 - ex);
    for (auto& [k, p] : emp) expect[k] = std::pow(p, 1 - ex) / z;  // p^(1 - exponent), normalised
    // The analytic sampled histogram matches the formula...
    auto h = b.histogram("weather", rows);
    for (size_t i = 0; i < h.bins.size(); ++i) EXPECT_NEAR(h.sampled[i], expect[h.bins[i]], 1e-9) << ex;
    // ...and so does actually sampling with keep(): chi-square with 3 dof below the 0.1% critical value.
    std::mt19937_64 rng(42);
    std::map<std::string, double> obs;
    double kept = 0;
    for (int pass = 0; pass < 200; ++pass)
      for (auto& r : rows)
        if (b.keep(r, rng)) { obs[r.cat["weather"]] += 1; kept += 1; }
    EXPECT_LT(chi2(obs, expect, kept), 16.27) << "exponent " << ex;
    if (ex == 0) {
      EXPECT_NEAR(b.acceptance_rate(rows), 1.0, 1e-12);  // no balancing: everything kept
    }
  }
}

TEST(Balance, JointWeightOverTwoIndependentFeatures) {
  // Independent features: the joint weight makes each marginal p^(1 - exponent).
  std::vector<FeatureRow> rows;
  std::mt19937_64 g(1);
  for (int i = 0; i < 4000; ++i) {
    FeatureRow r;
    r.cat["weather"] = (g() % 10) < 8 ? "clear" : "rain";  // 80/20
    r.num["speed"] = (g() % 10) < 6 ? 3.0 : 20.0;           // 60/40 in two bins
    rows.push_back(r);
  }
  Balancer b({"weather", "speed"}, 1.0, 2);
  b.fit(rows);
  auto hw = b.histogram("weather", rows), hs = b.histogram("speed", rows);
  for (double p : hw.sampled) EXPECT_NEAR(p, 0.5, 0.02);
  for (double p : hs.sampled) EXPECT_NEAR(p, 0.5, 0.02);
  EXPECT_THROW(Balancer({"colour"}, 0.5, 10), Error);
  EXPECT_THROW(Balancer({"weather"}, 1.5, 10), Error);
}

TEST(Balance, MissingValuesFormTheirOwnBin) {
  std::vector<FeatureRow> rows(10);
  for (int i = 0; i < 10; ++i) rows[static_cast<size_t>(i)].num["speed"] = i < 3 ? NAN : double(i);
  Balancer b({"speed"}, 0.5, 4);
  b.fit(rows);
  auto h = b.histogram("speed", rows);
  EXPECT_EQ(h.bins.back(), "missing");
  EXPECT_NEAR(h.empirical.back(), 0.3, 1e-12);
}

TEST(Geofence, StrictBoxesAreValidationOnly) {
  test::TempDir dir;
  auto add = [&](const std::string& id, double lat, double lon) {
    EpisodeMeta m;
    m.id = id;
    m.height = 4;
    m.width = 4;
    m.latitude = lat;
    m.longitude = lon;
    EpisodeWriter w(dir.path, m);
    FrameRecord r;
    r.bgr = cv::Mat(4, 4, CV_8UC3, cv::Scalar(0, 0, 0));
    w.append(r);
    w.commit();
  };
  for (int i = 0; i < 40; ++i) add("e" + std::to_string(i), 51.40 + 0.005 * i, -0.2 + 0.005 * i);
  add("noloc", NAN, NAN);
  Dataset ds(dir.path);
  GeoBox box = parse_geobox("51.45,-0.16,51.50,-0.10");
  Split s = geofence_split(ds, {box}, 0.0, 7);
  EXPECT_EQ(s.val_random.size(), 0u);
  for (auto& id : s.val_geofence) {
    EpisodeMeta m = Episode(dir / "episodes" / id).meta();
    EXPECT_TRUE(box.contains(m.latitude, m.longitude)) << id;
  }
  for (auto& id : s.train) {
    EpisodeMeta m = Episode(dir / "episodes" / id).meta();
    EXPECT_FALSE(m.has_location() && box.contains(m.latitude, m.longitude)) << id;
  }
  EXPECT_EQ(s.val_geofence.size() + s.train.size(), 41u);
  EXPECT_GE(s.val_geofence.size(), 9u);
  // Random hold-out is seeded, stable, and never takes a fenced episode into training.
  Split r1 = geofence_split(ds, {box}, 0.25, 7), r2 = geofence_split(ds, {box}, 0.25, 7);
  EXPECT_EQ(r1.val_random, r2.val_random);
  EXPECT_EQ(r1.val_geofence, s.val_geofence);
  EXPECT_GT(r1.val_random.size(), 0u);
  EXPECT_THROW(parse_geobox("1,2,3"), Error);
  EXPECT_THROW(parse_geobox("5,2,3,4"), Error);
}

// A few real drives beside many procedural ones: the "footage" feature at exponent 1 gives them half of the draws.
TEST(Balance, FootageWeighsRealDrivesAsMuchAsProceduralOnes) {
  EpisodeMeta real, synth;
  real.source = "highway.mp4";
  synth.source = "synth:seed=1,episode=3";
  EXPECT_FALSE(real.is_procedural());
  EXPECT_TRUE(synth.is_procedural());
  std::vector<FeatureRow> rows;
  for (int i = 0; i < 1000; ++i) rows.push_back(example_features(i < 30 ? real : synth, {8.f}, {0.f}));
  EXPECT_EQ(rows[0].cat.at("footage"), "real");
  EXPECT_EQ(rows[999].cat.at("footage"), "procedural");
  Balancer b({"footage"}, 1.0, 10);
  b.fit(rows);
  auto h = b.histogram("footage", rows);
  ASSERT_EQ(h.bins.size(), 2u);
  for (size_t i = 0; i < 2; ++i) EXPECT_NEAR(h.sampled[i], 0.5, 1e-9) << h.bins[i];
}

// Held out by name (--hold-out): the episode and what derives from it, whatever the geofence or the random draw says;
// the split file keeps the list, and one written before it existed reads as before.
TEST(Geofence, EpisodesHeldOutByNameTakeTheirMirrorImagesAlong) {
  std::vector<EpisodeMeta> eps;
  for (std::string id : {"a", "a-mirror", "b", "b-cf01", "c"}) {
    EpisodeMeta m;
    m.id = id;
    eps.push_back(m);
  }
  Split s = geofence_split(eps, {}, 0.0, 0, {"a", "b"});
  EXPECT_EQ(s.val_named, (std::vector<std::string>{"a", "a-mirror", "b", "b-cf01"}));
  EXPECT_EQ(s.train, std::vector<std::string>{"c"});
  EXPECT_EQ(s.held_out().size(), 4u);
  Split back = Split::from_json(s.to_json(), "test");
  EXPECT_EQ(back.val_named, s.val_named);
  Split old = Split::from_json(nlohmann::json{{"train", {"c"}}, {"val_geofence", nlohmann::json::array()}, {"val_random", {"a"}}}, "old");
  EXPECT_TRUE(old.val_named.empty());
  EXPECT_FALSE(geofence_split(eps, {}, 0, 0).to_json().contains("val_named"));
  const std::string e = test::error_of([&] { geofence_split(eps, {}, 0.0, 0, {"zz"}, "DS"); });
  EXPECT_NE(e.find("--hold-out zz: DS has no episode of that name"), std::string::npos) << e;
}

TEST(Mirror, SwapsSidesInWordsAndLabelsButNotIntensifiers) {
  EXPECT_EQ(mirror_words("approaching a left bend, changing lanes to the Right"),
            "approaching a right bend, changing lanes to the Left");
  EXPECT_EQ(mirror_words("right behind a bus, turn right ahead: LEFT"), "right behind a bus, turn left ahead: RIGHT");
  EXPECT_EQ(mirror_words("left_bend"), "right_bend");
  EXPECT_EQ(mirror_words("leftover rights, bright"), "leftover rights, bright");  // whole words only
  nlohmann::json l = {{"curvature", 0.01}, {"lane_offset_m", -0.5}, {"road_ahead", "right_bend"}, {"ego_lane", 1},
                      {"speed", 7.0}, {"weather", "rain"}};
  nlohmann::json m = mirror_labels(l);
  EXPECT_DOUBLE_EQ(m["curvature"].get<double>(), -0.01);
  EXPECT_DOUBLE_EQ(m["lane_offset_m"].get<double>(), 0.5);
  EXPECT_EQ(m["road_ahead"], "left_bend");
  EXPECT_EQ(m["ego_lane"], 1);
  EXPECT_DOUBLE_EQ(m["speed"].get<double>(), 7.0);
  EXPECT_EQ(m["weather"], "rain");
  EXPECT_EQ(mirror_labels(m), l);  // an involution
}

TEST(Mirror, MirrorImagesAndReplaysAreHeldOutWithTheirSource) {
  EXPECT_EQ(split_source_id("e7-cf03"), "e7");
  EXPECT_EQ(split_source_id("e7-cf03-mirror"), "e7");
  EXPECT_EQ(split_source_id("e7-mirror"), "e7");
  for (const char* id : {"e7", "e7-cf", "-cf03", "e7-cfx3", "e7-cf03x", "e7-cf03-mirror-mirror"})
    EXPECT_EQ(split_source_id(id), mirror_source_id(id)) << id;  // nothing else is taken for a replay
  EXPECT_EQ(mirrored_id("e7"), "e7-mirror");
  EXPECT_EQ(mirror_source_id("e7-mirror"), "e7");
  EXPECT_EQ(mirror_source_id("e7"), "e7");
  EXPECT_EQ(mirror_source_id("-mirror"), "-mirror");
  int held = 0;
  for (int i = 0; i < 200; ++i) {
    const std::string id = "synth-e" + std::to_string(i);
    const bool v = held_out_at_random(id, 0.2, 3);
    held += v;
    EXPECT_EQ(held_out_at_random(mirrored_id(id), 0.2, 3), v) << id;
    EXPECT_EQ(held_out_at_random(id + "-cf03", 0.2, 3), v) << id;  // counterfactual replays (synth/counterfactual.h)
    EXPECT_EQ(held_out_at_random(mirrored_id(id + "-cf11"), 0.2, 3), v) << id;
  }
  EXPECT_GT(held, 20);  // the hold-out is real, so agreement above is not trivial
  EXPECT_LT(held, 60);
}
