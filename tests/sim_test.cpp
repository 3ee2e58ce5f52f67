// Closed-loop sessions (sim/session.h): a session stepped with a fixed action sequence gives the tokens of a
// rollout with that sequence and seed (guided against the counter-command, past the sliding window); a fork
// continues exactly as its parent would and apart from it; reset() replays; bad input is one clear error. The
// JSON protocol (sim/hub.h) in process.
#include <atomic>
#include <mutex>
#include <thread>
#include <tuple>

#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/sim/hub.h"
#include "gaia/sim/session.h"
#include "gaia/world/batch.h"
#include "gaia/world/rollout.h"
#include "test_util.h"

using namespace gaia;

namespace {

constexpr int64_t kSimN = 6, kSimK = 32;

struct Fixture {
  world::WorldInfo info;
  world::WorldModel model{nullptr};
  Fixture() {
    info.config = test::config("tiny.yaml");
    info.config.world.guidance_scale = 3;
    info.config.world.top_k = 8;
    info.grid_h = 2;
    info.grid_w = 3;
    info.K = kSimK;
    torch::manual_seed(12);
    model = world::WorldModel(info.config.world, kSimN, kSimK);
    model->eval();
  }
};

}  // namespace

TEST(SimSession, SteppedWithFixedActionsItGivesTheRolloutsTokens) {
  Fixture f;
  {  // sharpened: a random model's actions barely move its distributions, and the two counter-commands must differ
    torch::NoGradGuard ng;
    for (auto& q : f.model->parameters()) q.mul_(3.0);
  }
  const int64_t T = f.model->layout.T, P = 2, F = T + 3;  // past the window: the history is re-encoded
  torch::manual_seed(3);
  auto prompt = torch::randint(0, kSimK, {P, kSimN}, torch::kLong);
  auto prompt_actions = torch::tensor({{7.0f, 0.001f}, {7.5f, 0.002f}});
  std::vector<sim::Action> commands;
  for (int64_t k = 0; k < F; ++k) commands.push_back({6.0 + 0.2 * double(k), k % 3 == 0 ? 0.01 : -0.005});

  // As gaia generate builds it: normalised actions for every step, the counter-command from step P on.
  world::RolloutPrompt p;
  p.tokens = prompt;
  auto acts = torch::empty({P + F, 2});
  for (int64_t k = 0; k < P + F; ++k) {
    const double v = k < P ? prompt_actions[k][0].item<double>() : commands[size_t(k - P)].speed;
    const double c = k < P ? prompt_actions[k][1].item<double>() : commands[size_t(k - P)].curvature;
    acts[k][0] = v / world::kSpeedScale;
    acts[k][1] = c / world::kCurvatureScale;
  }
  p.actions = acts;
  torch::Tensor mirrored;  // the "mirror" rollout: "turn" must give other frames, or the test tells nothing
  for (const bool turn_only : {false, true}) {
  SCOPED_TRACE(turn_only ? "turn: the counter-command at the command's own speed" : "mirror");
  // "turn" mirrors the curvature at each command's own speed; "mirror" at the prompt's last speed.
  p.negative_actions = turn_only ? world::counter_actions(acts, P) : world::counter_actions(acts, P, torch::tensor(7.5));
  world::RolloutOptions o;
  o.frames = int(F);
  o.seed = 9;
  o.sampling.top_k = 8;
  o.sampling.temperature = f.info.config.world.temperature;
  o.sampling.guide_actions_within_top_k = f.info.config.world.guide_actions_within_top_k;
  o.guidance.scale = 3;
  auto expected = world::rollout(f.model, p, o).tokens[0];  // [P + F, n]
  if (turn_only) EXPECT_FALSE(torch::equal(expected, mirrored));
  else mirrored = expected;

  sim::SessionSettings s;
  s.seed = 9;
  s.negative_keeps_speed = turn_only;
  sim::SimSession session(f.model, f.info, s);
  session.start(prompt, prompt_actions);
  EXPECT_EQ(session.steps(), P);
  for (int64_t k = 0; k < F; ++k) {
    auto tok = session.step(commands[size_t(k)]);
    ASSERT_EQ(tok.sizes(), torch::IntArrayRef({kSimN}));
    EXPECT_TRUE(torch::equal(tok, expected[P + k])) << "step " << k;
  }
  EXPECT_TRUE(torch::equal(session.tokens(), expected));
  }
}

TEST(SimSession, AForkContinuesAsItsParentAndApartFromIt) {
  Fixture f;
  sim::SessionSettings s;
  s.seed = 4;
  s.sampling = "sample";
  sim::SimSession a(f.model, f.info, s);
  torch::manual_seed(5);
  a.start(torch::randint(0, kSimK, {2, kSimN}, torch::kLong), {}, "rain");
  for (int i = 0; i < 3; ++i) a.step({8, 0});
  auto b = a.fork();
  // The same commands: the same frames, past the window, whichever steps first.
  std::vector<torch::Tensor> from_b;
  for (int i = 0; i < 6; ++i) from_b.push_back(b.step({8, 0.01}));
  for (int i = 0; i < 6; ++i) EXPECT_TRUE(torch::equal(a.step({8, 0.01}), from_b[size_t(i)])) << i;
  // Other commands on the fork leave the parent's history as it was.
  auto c = a.fork();
  for (int i = 0; i < 3; ++i) c.step({2, -0.02}, "night");
  EXPECT_EQ(c.text(), "night");
  EXPECT_EQ(a.text(), "rain");
  EXPECT_EQ(a.steps(), 11);
  EXPECT_EQ(c.steps(), 14);
  EXPECT_TRUE(torch::equal(c.tokens().narrow(0, 0, 11), a.tokens()));
  // reset(): back to the prompt, the same random stream.
  auto first = a.tokens().narrow(0, 2, 3).clone();
  a.reset();
  EXPECT_EQ(a.steps(), 2);
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(torch::equal(a.step({8, 0}), first[i])) << i;
}

TEST(SimSession, BadInputIsOneClearError) {
  Fixture f;
  sim::SimSession s(f.model, f.info, {});
  EXPECT_NE(test::error_of([&] { s.step({8, 0}); }).find("after start()"), std::string::npos);
  EXPECT_NE(test::error_of([&] { s.start(torch::full({2, kSimN}, kSimK, torch::kLong)); }).find("[0, K = 32)"),
            std::string::npos);
  EXPECT_NE(test::error_of([&] { s.start(torch::zeros({2, kSimN + 1}, torch::kLong)); }).find("n = 6"),
            std::string::npos);
  const int64_t T = f.model->layout.T;
  EXPECT_NE(test::error_of([&] { s.start(torch::zeros({T, kSimN}, torch::kLong)); }).find("at most"), std::string::npos);
  EXPECT_NE(test::error_of([&] { s.start(torch::zeros({2, kSimN}, torch::kLong), torch::zeros({3, 2})); })
                .find("prompt actions"),
            std::string::npos);
  s.start(torch::zeros({1, kSimN}, torch::kLong));
  EXPECT_NE(test::error_of([&] { s.step({std::nan(""), 0.7}); }).find("curvature"), std::string::npos);
  EXPECT_NE(test::error_of([&] { s.step({-1, 0}); }).find("speed"), std::string::npos);
  EXPECT_NE(test::error_of([&] { s.step({INFINITY, 0}); }).find("finite"), std::string::npos);
  EXPECT_EQ(s.steps(), 1);  // nothing was stepped by the refused actions
  EXPECT_NE(test::error_of([&] { sim::SessionSettings bad; bad.window_stride = 0; sim::SimSession x(f.model, f.info, bad); })
                .find("window stride"),
            std::string::npos);
}

namespace {

nlohmann::json raw_prompt(int64_t frames) {
  nlohmann::json rows = nlohmann::json::array();
  for (int64_t k = 0; k < frames; ++k) rows.push_back(std::vector<int64_t>(kSimN, (3 * k) % kSimK));
  return {{"tokens", rows}, {"actions", nlohmann::json::array({{7.0, 0.001}, {7.5, nullptr}})}};
}

}  // namespace

// The JSON protocol in process: create / step / fork / reset / close / status, the same tokens as a session, and
// every bad request a 4xx with one line that leaves the hub serving.
TEST(SimHub, SessionsAreCreatedSteppedForkedAndClosedAndBadRequestsAreAnswered) {
  Fixture f;
  sim::SessionHub hub(f.model, f.info, {2, 0, 600}, {}, [](const torch::Tensor& t, const std::string& format) {
    return nlohmann::json::array({format, t.sum().item<int64_t>()});
  });
  auto r = hub.handle("create", {{"prompt", raw_prompt(2)}, {"seed", 9}, {"text", "rain"}});
  ASSERT_EQ(r.status, 200) << r.body.dump();
  const auto id = r.body["session"].get<int64_t>();
  EXPECT_EQ(r.body["steps"], 2);
  // The same as a session made directly.
  sim::SessionSettings s;
  s.seed = 9;
  sim::SimSession direct(f.model, f.info, s);
  direct.start(torch::stack({torch::full({kSimN}, 0, torch::kLong), torch::full({kSimN}, 3, torch::kLong)}),
               torch::tensor({{7.0f, 0.001f}, {7.5f, NAN}}), "rain");
  for (int k = 0; k < 3; ++k) {
    const nlohmann::json frame = k == 2 ? nlohmann::json("jpeg") : nlohmann::json(true);
    r = hub.handle("step", {{"session", id}, {"speed", 8}, {"curvature", 0.01}, {"frame", frame}});
    ASSERT_EQ(r.status, 200) << r.body.dump();
    auto expected = direct.step({8, 0.01});
    EXPECT_EQ(r.body["tokens"].get<std::vector<int64_t>>(),
              std::vector<int64_t>(expected.data_ptr<int64_t>(), expected.data_ptr<int64_t>() + kSimN));
    // the app's encoder, called on the frame's tokens in the format asked (true: PNG)
    EXPECT_EQ(r.body["frame"], nlohmann::json::array({k == 2 ? "jpeg" : "png", expected.sum().item<int64_t>()}));
    EXPECT_EQ(r.body["step"], 2 + k);
  }
  r = hub.handle("fork", {{"session", id}});
  ASSERT_EQ(r.status, 200) << r.body.dump();
  const auto fork = r.body["session"].get<int64_t>();
  EXPECT_EQ(r.body["steps"], 5);
  // The hub is full (2 sessions): a third is refused, not queued.
  r = hub.handle("create", nlohmann::json::object());
  EXPECT_EQ(r.status, 429);
  EXPECT_NE(r.body["error"].get<std::string>().find("close one"), std::string::npos);

  const std::vector<std::tuple<std::string, nlohmann::json, int, std::string>> bad = {
      {"step", {{"session", id}, {"speed", 101}}, 400, "'speed' must be in [0, 100]"},
      {"step", {{"session", id}, {"speed", "fast"}}, 400, "'speed' must be a number"},
      {"step", {{"session", id}, {"steer", 1}}, 400, "unknown field 'steer'"},
      {"step", {{"session", 99}}, 404, "no session 99"},
      {"step", {{"speed", 8}}, 400, "'session'"},
      {"fly", nlohmann::json::object(), 404, "unknown request 'fly'"},
      {"step", {{"session", id}, {"frame", "gif"}}, 400, "'frame' must be true, false, \"png\" or \"jpeg\""},
      {"create", {{"prompt", {{"tokens", {{1, 2}}}}}}, 400, "'prompt.tokens[0]' must be a list of 6 ids"},
      {"create", {{"prompt", {{"episode", "a"}}}}, 400, "no token dataset"},
      {"create", {{"guidance", -1}}, 400, "'guidance' must be in [0, 100]"},
  };
  for (const auto& [op, req, status, words] : bad) {
    r = hub.handle(op, req);
    EXPECT_EQ(r.status, status) << op << " " << req.dump() << ": " << r.body.dump();
    EXPECT_NE(r.body["error"].get<std::string>().find(words), std::string::npos) << r.body.dump();
  }
  // Nothing above stepped a session; the fork then goes on as the parent would.
  r = hub.handle("step", {{"session", fork}, {"speed", 8}, {"curvature", 0.01}});
  auto expected = direct.step({8, 0.01});
  EXPECT_EQ(r.body["step"], 5);
  EXPECT_EQ(r.body["tokens"].get<std::vector<int64_t>>(),
            std::vector<int64_t>(expected.data_ptr<int64_t>(), expected.data_ptr<int64_t>() + kSimN));
  EXPECT_EQ(hub.handle("reset", {{"session", id}}).body["steps"], 2);
  EXPECT_EQ(hub.handle("close", {{"session", fork}}).status, 200);
  EXPECT_EQ(hub.handle("step", {{"session", fork}}).status, 404);
  EXPECT_EQ(hub.sessions(), 1u);
  EXPECT_EQ(hub.handle("status", nlohmann::json::object()).body["sessions"].size(), 1u);
}

// A session answers one request at a time: while one waits in it (a slow frame encoder), another to the same
// session is refused at once with max_queue 0, and one to another session is answered.
// Continuous driving: "command" sets a session's standing action (and a text that applies once), "drive" steps
// with it, giving the tokens "step" gives with the same action; bad commands are 4xx and change nothing.
TEST(SimHub, DriveStepsWithTheStandingCommand) {
  Fixture f;
  sim::SessionHub hub(f.model, f.info, {4, 0, 600}, {});
  const auto a = hub.handle("create", {{"prompt", raw_prompt(2)}, {"seed", 3}}).body["session"].get<int64_t>();
  const auto b = hub.handle("create", {{"prompt", raw_prompt(2)}, {"seed", 3}}).body["session"].get<int64_t>();
  auto r = hub.handle("command", {{"session", a}, {"speed", 6}, {"curvature", -0.02}, {"text", "fog"}});
  ASSERT_EQ(r.status, 200) << r.body.dump();
  EXPECT_EQ(r.body["command"]["curvature"], -0.02);
  for (int k = 0; k < 3; ++k) {
    auto d = hub.handle("drive", {{"session", a}});
    nlohmann::json step{{"session", b}, {"speed", 6}, {"curvature", -0.02}};
    if (k == 0) step["text"] = "fog";
    auto s = hub.handle("step", step);
    ASSERT_EQ(d.status, 200) << d.body.dump();
    EXPECT_EQ(d.body["tokens"], s.body["tokens"]) << "step " << k;
    EXPECT_EQ(d.body["text"], "fog");
    EXPECT_EQ(d.body["command"]["speed"], 6.0);
  }
  const std::vector<std::tuple<std::string, nlohmann::json, int, std::string>> bad = {
      {"command", {{"session", a}, {"curvature", 0.9}}, 400, "'curvature' must be in [-0.5, 0.5]"},
      {"command", {{"session", a}, {"speed", nullptr}, {"yaw", 1}}, 400, "unknown field 'yaw'"},
      {"command", {{"session", 77}, {"speed", 1}}, 404, "no session 77"},
      {"drive", {{"session", a}, {"speed", 3}}, 400, "unknown field 'speed'"},
  };
  for (const auto& [op, req, status, words] : bad) {
    r = hub.handle(op, req);
    EXPECT_EQ(r.status, status) << op << " " << req.dump() << ": " << r.body.dump();
    EXPECT_NE(r.body["error"].get<std::string>().find(words), std::string::npos) << r.body.dump();
  }
  EXPECT_EQ(hub.handle("drive", {{"session", a}}).body["command"]["curvature"], -0.02);  // unchanged by the refusals
}

TEST(SimHub, ABusySessionRefusesRatherThanPilesUp) {
  Fixture f;
  std::mutex gate;
  gate.lock();
  std::atomic<bool> inside{false};
  sim::SessionHub hub(f.model, f.info, {4, 0, 600}, {}, [&](const torch::Tensor&, const std::string&) {
    inside = true;
    std::lock_guard<std::mutex> wait(gate);
    return nlohmann::json(nullptr);
  });
  const auto a = hub.handle("create", nlohmann::json::object()).body["session"].get<int64_t>();
  const auto b = hub.handle("create", nlohmann::json::object()).body["session"].get<int64_t>();
  sim::HubReply slow;
  std::thread t([&] { slow = hub.handle("step", {{"session", a}, {"frame", true}}); });
  while (!inside) std::this_thread::yield();
  auto r = hub.handle("step", {{"session", a}});
  EXPECT_EQ(r.status, 429);
  EXPECT_NE(r.body["error"].get<std::string>().find("busy"), std::string::npos);
  EXPECT_EQ(hub.handle("step", {{"session", b}}).status, 200);
  gate.unlock();
  t.join();
  EXPECT_EQ(slow.status, 200);
  EXPECT_EQ(hub.handle("step", {{"session", a}}).status, 200);
}

// The read-back (the dynamics probe in the app) sees each step's last `frames` frames, once there are that many.
TEST(SimHub, EachStepReadsBackItsLastFrames) {
  Fixture f;
  sim::ReadBack rb;
  rb.frames = 3;
  rb.read = [](const torch::Tensor& recent) {
    return nlohmann::json({{"frames", recent.size(0)}, {"sum", recent.sum().item<int64_t>()}});
  };
  sim::SessionHub hub(f.model, f.info, {}, {}, {}, rb);
  auto id = hub.handle("create", {{"prompt", raw_prompt(2)}}).body["session"];
  auto r = hub.handle("step", {{"session", id}, {"speed", 5}});
  ASSERT_EQ(r.status, 200) << r.body.dump();
  ASSERT_TRUE(r.body.contains("read_back")) << r.body.dump();  // 2 prompt frames + this one
  auto tokens = r.body["tokens"].get<std::vector<int64_t>>();
  int64_t sum = 0;
  for (auto t : tokens) sum += t;
  sum += kSimN * 3;  // the prompt's frames: all 0, then all 3
  EXPECT_EQ(r.body["read_back"]["frames"], 3);
  EXPECT_EQ(r.body["read_back"]["sum"], sum);
  sim::SessionHub early(f.model, f.info, {}, {}, {}, rb);
  id = early.handle("create", nlohmann::json::object()).body["session"];
  EXPECT_FALSE(early.handle("step", {{"session", id}}).body.contains("read_back"));  // one frame so far
}

// fork(plans): one copy per plan, stepped along it as one batch (or one by one). With one plan the copy's frames are
// fork() + step()'s (the same random stream, past the window); with several (argmax, so that no draw depends on the
// batch) each copy is what a fork stepped alone along its plan gives; the parent is unchanged and the copies go on
// stepping.
TEST(SimSession, ForkAlongPlansStepsTheCopiesAsOneBatch) {
  Fixture f;
  const int64_t T = f.model->layout.T;
  for (const std::string sampling : {"top-k", "argmax"}) {
    SCOPED_TRACE(sampling);
    sim::SessionSettings s;
    s.seed = 6;
    s.sampling = sampling;
    sim::SimSession a(f.model, f.info, s);
    torch::manual_seed(8);
    a.start(torch::randint(0, kSimK, {2, kSimN}, torch::kLong), torch::tensor({{7.0f, 0.0f}, {7.0f, 0.001f}}), "rain");
    a.step({8, 0.01});
    const auto before = a.tokens().clone();
    std::vector<std::vector<sim::Action>> plans;
    const size_t branches = sampling == "argmax" ? 3 : 1;
    for (size_t b = 0; b < branches; ++b) {
      plans.emplace_back();
      for (int64_t k = 0; k < T + 2; ++k)  // past the window
        plans.back().push_back({6.0 + double(b), (b % 2 ? -0.01 : 0.02) * double(k % 3)});
    }
    auto copies = a.fork(plans, std::string("night"), sim::SimSession::Branching::Batched);
    ASSERT_EQ(copies.size(), branches);
    auto one_by_one = a.fork(plans, std::string("night"), sim::SimSession::Branching::OneByOne);
    EXPECT_TRUE(torch::equal(a.tokens(), before));  // the parent is as it was
    EXPECT_EQ(a.text(), "rain");
    for (size_t b = 0; b < branches; ++b) {
      auto alone = a.fork();
      for (const auto& act : plans[b]) alone.step(act, std::string("night"));
      EXPECT_EQ(copies[b].steps(), a.steps() + T + 2);
      EXPECT_EQ(copies[b].text(), "night");
      EXPECT_TRUE(torch::equal(copies[b].tokens(), alone.tokens())) << "plan " << b;
      EXPECT_TRUE(torch::equal(one_by_one[b].tokens(), alone.tokens())) << "plan " << b;
      // The copy is a session of its own from here on.
      EXPECT_TRUE(torch::equal(copies[b].step({5, 0}), alone.step({5, 0}))) << "plan " << b;
    }
  }
  sim::SimSession a(f.model, f.info, {});
  a.start(torch::zeros({1, kSimN}, torch::kLong));
  using Plans = std::vector<std::vector<sim::Action>>;
  EXPECT_NE(test::error_of([&] { a.fork(Plans{}); }).find("at least one plan"), std::string::npos);
  EXPECT_NE(test::error_of([&] { a.fork(Plans{{{8, 0}}, {{8, 0}, {8, 0}}}); }).find("same number of steps"),
            std::string::npos);
  EXPECT_NE(test::error_of([&] { a.fork(Plans{{{8, 0.9}}}); }).find("curvature"), std::string::npos);
  EXPECT_EQ(a.steps(), 1);
}

// The protocol's fork with "plans": each branch's frames (tokens, the last frame, in order), as sessions of their own
// unless "open" is false; a batch that would not fit is a 429 that opens none, a bad plan a 400.
TEST(SimHub, ForkWithPlansAnswersEachBranch) {
  Fixture f;
  sim::SessionHub hub(f.model, f.info, {3, 0, 600}, {}, [](const torch::Tensor& t, const std::string& format) {
    return nlohmann::json::array({format, t.sum().item<int64_t>()});
  });
  auto r = hub.handle("create", {{"prompt", raw_prompt(2)}, {"seed", 2}, {"sampling", "argmax"}});
  ASSERT_EQ(r.status, 200) << r.body.dump();
  const auto id = r.body["session"].get<int64_t>();
  const nlohmann::json plans = {{{8, 0.02}, {8, 0.02}, {8, 0.02}}, {{5, -0.02}, {5, nullptr}, {5, -0.02}}};
  r = hub.handle("fork", {{"session", id}, {"plans", plans}, {"frame", "jpeg"}, {"open", false}});
  ASSERT_EQ(r.status, 200) << r.body.dump();
  ASSERT_EQ(r.body["branches"].size(), 2u);
  EXPECT_EQ(hub.sessions(), 1u);  // none opened
  const auto closed_first = r.body["branches"][0];
  r = hub.handle("fork", {{"session", id}, {"plans", plans}, {"frame", true}});
  ASSERT_EQ(r.status, 200) << r.body.dump();
  EXPECT_EQ(hub.sessions(), 3u);
  EXPECT_EQ(r.body["forked_from"], id);
  for (size_t b = 0; b < 2; ++b) {
    const auto& one = r.body["branches"][b];
    ASSERT_EQ(one["tokens"].size(), 3u);
    EXPECT_EQ(one["steps"], 5);
    auto mine = one["session"].get<int64_t>();
    auto next = hub.handle("step", {{"session", mine}, {"speed", 8}});
    ASSERT_EQ(next.status, 200) << next.body.dump();
    EXPECT_EQ(next.body["step"], 5);
    const auto last = one["tokens"][2].get<std::vector<int64_t>>();
    int64_t sum = 0;
    for (auto x : last) sum += x;
    EXPECT_EQ(one["frame"], nlohmann::json::array({"png", sum}));
  }
  EXPECT_EQ(r.body["branches"][0]["tokens"], closed_first["tokens"]);  // open or not, the same batch
  const auto opened = r.body;
  // The parent, unchanged by the forks, stepped along plan 1 itself (argmax: the same frames as its branch).
  for (size_t k = 0; k < 3; ++k) {
    const auto& a = plans[1][k];
    nlohmann::json step{{"session", id}, {"speed", a[0]}};
    if (!a[1].is_null()) step["curvature"] = a[1];
    auto one = hub.handle("step", step);
    ASSERT_EQ(one.status, 200) << one.body.dump();
    EXPECT_EQ(one.body["tokens"], opened["branches"][1]["tokens"][k]) << k;
  }
  const std::vector<std::tuple<nlohmann::json, int, std::string>> bad = {
      {{{"session", id}, {"plans", plans}}, 429, "close some first"},  // 3 open, 2 more
      {{{"session", id}, {"plans", nlohmann::json::array()}, {"open", false}}, 400, "1 to 16 plans"},
      {{{"session", id}, {"plans", {{{8, 0.9}}}}, {"open", false}}, 400, "'plans[0][0]': curvature"},
      {{{"session", id}, {"plans", {{{8, "x"}}}}, {"open", false}}, 400, "'plans[0][0][1]' must be a number"},
      {{{"session", id}, {"plans", {{{8, 0}}, {{8, 0}, {8, 0}}}}, {"open", false}}, 400, "same number of steps"},
      {{{"session", 42}, {"plans", {{{8, 0}}}}, {"open", false}}, 404, "no session 42"},
      {{{"session", id}, {"plans", {{{8, 0}}}}, {"depth", 2}}, 400, "unknown field 'depth'"},
  };
  for (const auto& [req, status, words] : bad) {
    r = hub.handle("fork", req);
    EXPECT_EQ(r.status, status) << req.dump() << ": " << r.body.dump();
    EXPECT_NE(r.body["error"].get<std::string>().find(words), std::string::npos) << r.body.dump();
  }
  EXPECT_EQ(hub.sessions(), 3u);
}
