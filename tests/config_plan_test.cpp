// Config registry (YAML, --set, unknown keys) and `gaia plan` against the paper's figures.
#include "gaia/core/config.h"
#include "gaia/core/error.h"
#include "gaia/plan/plan.h"
#include "test_util.h"

using namespace gaia;

namespace {
Config load(const std::string& name) { return Config::load(test::source_dir() / "configs" / name); }
}  // namespace

TEST(Config, DefaultYamlEqualsBuiltInDefaults) {
  Config builtin;
  Config file = load("default.yaml");
  EXPECT_EQ(file.to_yaml(), builtin.to_yaml());
}

TEST(Config, AllShippedConfigsLoadAndRoundTrip) {
  for (auto name : {"tiny.yaml", "default.yaml", "paper.yaml"}) {
    Config c = load(name);
    Config again;
    again.apply_yaml(c.to_yaml(), "dump");
    EXPECT_EQ(again.to_yaml(), c.to_yaml()) << name;
  }
}

TEST(Config, UnknownKeysAndBadValuesNameTheKey) {
  test::TempDir dir;
  write_file_atomic(dir / "bad.yaml", "name: x\nworld:\n  d_model: 64\n  n_layayers: 2\n");
  try {
    Config::load(dir / "bad.yaml");
    FAIL() << "unknown key accepted";
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_NE(m.find("bad.yaml:4"), std::string::npos) << m;
    EXPECT_NE(m.find("world.n_layayers"), std::string::npos) << m;
  }
  write_file_atomic(dir / "type.yaml", "world:\n  d_model: lots\n");
  try {
    Config::load(dir / "type.yaml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("world.d_model"), std::string::npos) << e.what();
  }
  Config c;
  EXPECT_THROW(c.set("world.nope=3"), Error);
  EXPECT_THROW(c.set("world.d_model"), Error);
  c.set("world.d_model=512");
  EXPECT_EQ(c.world.d_model, 512);
  c.set("tokenizer.channel_mult=[1, 2, 4, 4]");
  EXPECT_EQ(c.tokenizer.channel_mult, (std::vector<int>{1, 2, 4, 4}));
  c.set("tokenizer.downsample=3");
  EXPECT_THROW(c.validate(), Error);
  Config k;
  k.set("world.guide_actions_within_top_k=false");
  EXPECT_FALSE(k.world.guide_actions_within_top_k);
  EXPECT_THROW(k.set("world.guide_actions_within_top_k=maybe"), Error);
  k.set("world.top_k=0");
  EXPECT_NE(test::error_of([&] { k.validate(); }).find("world.top_k"), std::string::npos);
  Config r;
  r.set("world.p_action_replay=0.9");
  EXPECT_NO_THROW(r.validate());
  r.set("world.p_action_replay=1.5");
  EXPECT_NE(test::error_of([&] { r.validate(); }).find("world.p_action_replay"), std::string::npos);
}

TEST(Plan, PaperConfigMatchesThePaper) {
  Config c = load("paper.yaml");
  plan::Plan p = plan::make_plan(c);
  EXPECT_EQ(p.image_tokens, 576);             // §4.1: 18 x 32
  EXPECT_EQ(c.step_tokens(), 610);            // §2.1: m + n + l = 610
  EXPECT_EQ(p.sequence_length, 15860);        // §4.2: 26 x 610
  EXPECT_NEAR(p.bit_compression, 470, 5);     // §4.1: ~470
  EXPECT_NEAR(p.world.total / 1e9, 6.5, 0.1);  // §4.2: 6.5B
  EXPECT_NEAR(p.tokenizer.total / 1e9, 0.3, 0.05);  // §4.1: 0.3B
  EXPECT_NEAR(p.decoder.total / 1e9, 2.6, 0.15);    // §4.3: 2.6B
  EXPECT_DOUBLE_EQ(p.world_flops_per_token, 6.0 * p.world.non_embedding);  // §6: C = 6N
}

TEST(Plan, WorldModelCountFollowsTheGptFormula) {
  Config c = load("tiny.yaml");
  const int64_t d = c.world.d_model, L = c.world.n_layers;
  EXPECT_EQ(plan::world_params(c).non_embedding, L * (12 * d * d + 13 * d) + 2 * d);
  c.world.n_layers *= 2;
  EXPECT_EQ(plan::world_params(c).non_embedding, 2 * L * (12 * d * d + 13 * d) + 2 * d);
  // Tiny is ~0.1M parameters as DESIGN.md promises; default is a few million.
  EXPECT_LT(plan::world_params(load("tiny.yaml")).total, 200000);
  int64_t def = plan::world_params(load("default.yaml")).total;
  EXPECT_GT(def, 1000000);
  EXPECT_LT(def, 20000000);
}

TEST(Plan, CliPrintsPaperFigures) {
  auto r = test::run_gaia("plan '" + (test::source_dir() / "configs" / "paper.yaml").string() + "'");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("15860"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("6.52B"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("472.6"), std::string::npos) << r.output;
}
