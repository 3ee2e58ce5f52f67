// The scaling-law study (§6): the power-law fit f(x) = c + (x/a)^b and its prediction band, the family's size rule,
// and a whole study at tiny size (runs, the prediction written before the largest trains, resuming, the plot).
#include <cmath>
#include <random>

#include "gaia/config.h"
#include "gaia/core/json_file.h"
#include "gaia/eval/scaling_fit.h"
#include "gaia/sizing/sizing.h"
#include "gaia/world/scaling.h"
#include "test_util.h"
#include "token_fixture.h"

using namespace gaia;
using namespace gaia::test::token_fixture;

TEST(ScalingFit, RecoversAKnownLawAndPredictsBeyondIt) {
  const eval::PowerLaw truth{2.0, 1e6, -0.3, 0};
  std::vector<double> x, y;
  for (double e = 6; e <= 9.01; e += 0.5) {
    x.push_back(std::pow(10.0, e));
    y.push_back(truth(x.back()));
  }
  const auto f = eval::fit_power_law(x, y);
  EXPECT_NEAR(f.c, 2.0, 2e-3);
  EXPECT_NEAR(f.b, -0.3, 2e-3);
  EXPECT_NEAR(f(1e11) / truth(1e11), 1.0, 1e-3);  // two decades beyond the runs
  EXPECT_LT(f.sse, 1e-8);

  // With noise, the band holds the truth and widens with the distance it predicts over.
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0, 0.01);
  std::vector<double> noisy = y;
  for (auto& v : noisy) v += noise(rng);
  const auto g = eval::fit_power_law(x, noisy);
  const auto near = eval::prediction_band(x, noisy, g, 1e9 * 3), far = eval::prediction_band(x, noisy, g, 1e12);
  EXPECT_LT(near.lo, near.hi);
  EXPECT_LE(near.lo, truth(3e9) + 0.02);
  EXPECT_GE(near.hi, truth(3e9) - 0.02);
  EXPECT_GT(far.hi - far.lo, near.hi - near.lo);
}

TEST(ScalingFit, RefusesWhatNoFallingLawFits) {
  EXPECT_NE(test::error_of([] { eval::fit_power_law({1, 2}, {3, 2}); }).find("at least 3 runs"), std::string::npos);
  EXPECT_NE(test::error_of([] { eval::fit_power_law({1, 10, 100}, {2, 3, 4}); }).find("do not fall"), std::string::npos);
  EXPECT_NE(test::error_of([] { eval::fit_power_law({1, 0, 100}, {4, 3, 2}); }).find("run 1 has compute 0"),
            std::string::npos);
}

TEST(Scaling, FamilyFollowsTheConfigsRule) {
  Config c = test::config("default.yaml");
  const auto runs = world::scaling_family(c, 6, 144);
  ASSERT_EQ(runs.size(), 6u);
  const double per_step = double(c.world.batch_size) * c.world.context_steps * (c.world.text_tokens + 144 + 2);
  for (size_t i = 0; i < runs.size(); ++i) {
    const auto& r = runs[i];
    EXPECT_EQ(r.d_model % c.world.scaling_head_dim, 0);
    EXPECT_EQ(r.n_heads * c.world.scaling_head_dim, r.d_model);
    EXPECT_EQ(r.n_layers, std::max(1, int(std::lround(double(r.d_model) / c.world.scaling_width_per_layer))));
    Config m = world::scaling_config(c, r);
    EXPECT_EQ(r.params, sizing::world_params(m).non_embedding);
    EXPECT_EQ(r.steps, int(std::ceil(c.world.scaling_tokens_per_param * double(r.params) / per_step)));
    EXPECT_DOUBLE_EQ(r.flops, 6.0 * double(r.params) * per_step * r.steps);
    EXPECT_LE(m.world.warmup_steps, std::max(1, r.steps / 10));
    if (i > 0) {
      EXPECT_GT(r.d_model, runs[i - 1].d_model);
      EXPECT_GT(r.flops, runs[i - 1].flops);
    }
  }
  EXPECT_LT(runs.front().params, 20000);    // from a few thousand ...
  EXPECT_GT(runs.back().params, 300000);    // ... to some hundred thousand at six sizes
  EXPECT_NE(test::error_of([&] { world::scaling_family(c, 3, 144); }).find("too few"), std::string::npos);
}

// A whole study at tiny size: every run trains and records its outcome, the prediction is written before the
// largest trains and kept when the study runs again (which trains nothing), and the plot and summary are written.
TEST(Scaling, StudyPredictsTheLargestBeforeTrainingItAndResumes) {
  test::TempDir dir;
  const fs::path root = dir / "tokens";
  write_header(root);
  for (int e = 0; e < 10; ++e) write_episode(root, EpisodeSpec{fmt::format("e{}", e), 24, "clear", 3 * e});
  Config c = test::config("tiny.yaml");
  c.run.device = "cpu";
  c.world.scaling_width = 8;
  c.world.scaling_head_dim = 8;
  c.world.scaling_width_per_layer = 16;
  c.world.scaling_tokens_per_param = 3;
  world::ScalingOptions o;
  o.tokens = root;
  o.out = dir / "study";
  o.sizes = 4;
  std::vector<std::string> started;
  auto r = world::run_scaling(c, o, [&](size_t, const world::ScalingRun& run) { started.push_back(run.name); });
  ASSERT_EQ(r.runs.size(), 4u);
  EXPECT_EQ(started.size(), 4u);
  for (auto& run : r.runs) {
    EXPECT_TRUE(run.done);
    EXPECT_TRUE(std::isfinite(run.loss) && run.loss > 0) << run.name;
    EXPECT_TRUE(fs::exists(o.out / "runs" / run.name / "run.json")) << run.name;
  }
  const auto pred = read_json(o.out / "prediction.json");
  EXPECT_EQ(pred["run"], r.runs.back().name);
  EXPECT_DOUBLE_EQ(pred["predicted"].get<double>(), r.predicted);
  EXPECT_LE(r.band.lo, r.predicted + 1e-12);
  EXPECT_GE(r.band.hi, r.predicted - 1e-12);
  EXPECT_NEAR(r.relative_error, (r.runs.back().loss - r.predicted) / r.runs.back().loss, 1e-12);
  // The prediction came from the runs before the largest: refitting them gives it again.
  std::vector<double> x, y;
  for (size_t i = 0; i + 1 < r.runs.size(); ++i) {
    x.push_back(r.runs[i].flops);
    y.push_back(r.runs[i].loss);
  }
  EXPECT_NEAR(eval::fit_power_law(x, y)(r.runs.back().flops), r.predicted, 1e-9);
  const std::string svg = read_file(o.out / "scaling.svg");
  EXPECT_NE(svg.find("<circle"), std::string::npos);
  EXPECT_NE(svg.find("largest: prediction"), std::string::npos);
  EXPECT_EQ(read_json(o.out / "scaling.json")["largest"]["outcome"].get<double>(), r.runs.back().loss);

  started.clear();
  auto again = world::run_scaling(c, o, [&](size_t, const world::ScalingRun& run) { started.push_back(run.name); });
  EXPECT_EQ(again.runs.back().loss, r.runs.back().loss);  // recorded, not retrained
  EXPECT_EQ(again.predicted, r.predicted);
  // Another rule into the same directory is refused, naming the record.
  c.world.scaling_tokens_per_param = 6;
  EXPECT_NE(test::error_of([&] { world::run_scaling(c, o); }).find("run.json: records another run"), std::string::npos);
}
