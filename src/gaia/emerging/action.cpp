#include "gaia/emerging/action.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <fmt/ranges.h>

#include <opencv2/imgproc.hpp>

#include "gaia/core/error.h"
#include "gaia/data/motion.h"
#include "gaia/eval/metrics.h"
#include "gaia/eval/svg_plot.h"
#include "gaia/synth/synth.h"
#include "gaia/tokenizer/io.h"
#include "gaia/world/batch.h"
#include "gaia/world/rollout.h"

namespace gaia::emerging {

std::vector<Command> action_commands(const std::string& set) {
  if (set == "default")
    return {{"straight", -1, 0.0, 0, false},        {"left", -1, 0.008, 0, false},
            {"right", -1, -0.008, 0, false},        {"strong-left", -1, 0.03, 0, true},
            {"strong-right", -1, -0.03, 0, true},   {"drift-right", -1, -0.002, -0.002, true},
            {"slow", 3.0, 0.0, 0, false},           {"fast", 13.0, 0.0, 0, false}};
  if (set == "sweep") {  // 1/km; beyond 12 (99% of the lane keeper's frames) counts as out of distribution
    std::vector<Command> c;
    for (int k : {-40, -30, -20, -14, -8, 8, 20, 30})
      c.push_back({fmt::format("{}-{}", k < 0 ? "right" : "left", std::abs(k)), -1, k / 1000.0, 0, std::abs(k) > 12});
    return c;
  }
  fail("unknown command set '{}' ({})", set, fmt::join(kCommandSets, ", "));
}

namespace {

constexpr double kSteerThreshold = 0.002;  // 1/m: below this a command or read-back counts as straight

struct Readback {
  std::vector<double> speed, curvature;  // per rollout, mean over its probe windows
  std::vector<double> pair_cmd, pair_read;  // per read-back window of the probe (a frame pair for K = 2): curvature
};

Readback read_rows(Models& m, const std::vector<std::vector<cv::Mat>>& frames, int64_t from) {
  Readback r;
  for (const auto& row : frames) {
    auto y = read_dynamics(m, std::vector<cv::Mat>(row.begin() + from, row.end()));  // [F, 2]
    r.speed.push_back(y.select(1, 0).mean().item<double>());
    r.curvature.push_back(y.select(1, 1).mean().item<double>());
    for (int64_t j = 0; j < y.size(0); ++j) r.pair_read.push_back(y[j][1].item<double>());
  }
  return r;
}

// A steering command this strong (1/m) or more is one the read-backs must get the side of (strong-left / -right).
constexpr double kStrongSteer = 0.02;

// The generated video's own visual odometry (data/motion.h), a read-back any driving video model's output can be
// given: the median yaw rate (rad/s, + = left) of each row's frames from `from` on, NaN where it finds no motion.
// At the tokenizer's frame size the road plane's scale is coarse, so only the yaw rate (no scale needed) is used.
// The estimator's windows and tolerances are in pixels, set for recorded footage (hundreds of pixels wide): the
// tokenizer's frames are enlarged first, or its tracking window spans a sixth of the frame.
constexpr int kEgoUpsample = 2;
std::vector<double> ego_motion_yaw_rates(const std::vector<std::vector<cv::Mat>>& rows, int64_t from, double fps) {
  std::vector<double> out;
  for (const auto& row : rows) {
    data::CameraIntrinsics cam;
    cam.width = row.at(size_t(from)).cols * kEgoUpsample;
    cam.height = row.at(size_t(from)).rows * kEgoUpsample;
    data::MotionEstimator est(cam, data::MotionOptions{});
    for (size_t k = size_t(from); k < row.size(); ++k) {
      cv::Mat f;
      cv::resize(row[k], f, cv::Size(), kEgoUpsample, kEgoUpsample, cv::INTER_CUBIC);
      est.add(f, double(k - size_t(from)) / fps);
    }
    std::vector<double> w;
    for (double y : est.finish().yaw_rate)
      if (std::isfinite(y)) w.push_back(y);
    std::sort(w.begin(), w.end());
    out.push_back(w.empty() ? std::nan("") : w[w.size() / 2]);
  }
  return out;
}

double sign_accuracy(const std::vector<double>& cmd, const std::vector<double>& read) {
  int n = 0, ok = 0;
  for (size_t i = 0; i < cmd.size(); ++i) {
    if (std::abs(cmd[i]) < kSteerThreshold) continue;
    ++n;
    ok += (cmd[i] > 0) == (read[i] > 0);
  }
  return n ? double(ok) / n : std::nan("");
}

nlohmann::json agreement(const std::vector<double>& cmd_speed, const std::vector<double>& cmd_curv,
                         const Readback& r, const std::vector<size_t>& rows) {
  std::vector<double> cs, cc, rs, rc;
  for (size_t i : rows) {
    cs.push_back(cmd_speed[i]);
    cc.push_back(cmd_curv[i]);
    rs.push_back(r.speed[i]);
    rc.push_back(r.curvature[i]);
  }
  return {{"curvature_spearman", eval::spearman(cc, rc)},
          {"speed_spearman", eval::spearman(cs, rs)},
          {"steering_sign_accuracy", sign_accuracy(cc, rc)},
          {"rollouts", rows.size()}};
}

double psnr_mean(const std::vector<cv::Mat>& a, const std::vector<cv::Mat>& b) {
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += eval::psnr(a[i], b[i]);
  return s / double(a.size());
}

// Does the world model know what a commanded turn looks like? Cross-entropy (nats per image token) of the
// replay's codes after the prompt, teacher-forced, under each of the given action sequences [R, P + F, 2]:
// -> [actions.size()][R]. A model that follows its actions scores the replay better under the command that made it
// than under the counter-command; a gap in sampling shows when it does and its rollouts still do not turn.
std::vector<std::vector<double>> replay_nats(Models& m, const torch::Tensor& prompt, const std::vector<torch::Tensor>& replay,
                                             const std::vector<torch::Tensor>& actions) {
  torch::NoGradGuard ng;
  m.world->eval();
  const int64_t R = prompt.size(0), batch = 16;
  auto tokens = torch::cat({prompt, torch::stack(replay)}, 1);  // [R, P + F, n]
  // Within the model's context: the last T steps, scoring the replay's frames among them (each after >= 1 frame).
  const int64_t S = std::min(tokens.size(1), m.world->layout.T), drop = tokens.size(1) - S;
  const int64_t F = std::min(replay.front().size(0), S - 1), P = S - F;
  tokens = tokens.narrow(1, drop, S);
  std::vector<std::vector<double>> out;
  for (const auto& a : actions) {
    std::vector<double> nats;
    for (int64_t r0 = 0; r0 < R; r0 += batch) {
      const int64_t b = std::min(batch, R - r0);
      world::WorldBatch wb;
      wb.tokens = tokens.narrow(0, r0, b);
      wb.actions = a.narrow(0, r0, b).narrow(1, drop, S);
      auto logits = m.world->forward(wb.to(m.dev)).narrow(1, P, F);  // [b, F, n, K]
      auto target = wb.tokens.narrow(1, P, F).to(m.dev).unsqueeze(-1);
      auto nll = -torch::log_softmax(logits, -1).gather(-1, target).squeeze(-1).mean({1, 2}).cpu();  // [b]
      for (int64_t i = 0; i < b; ++i) nats.push_back(nll[i].item<double>());
    }
    out.push_back(nats);
  }
  return out;
}

}  // namespace

nlohmann::json action_control(Models& m, const world::TokenDataset& ds, const data::Dataset* raw,
                              const ActionEvalOptions& o, Output& out) {
  const int64_t P = o.prompt_frames, F = o.frames;
  if (P < 1 || F < 1) fail("action control needs at least one prompt frame and one generated frame");
  if (F + 1 < m.dynamics->frames)  // the read-back starts at the last prompt frame
    fail("action control: the dynamics probe reads {} consecutive frames, so --frames must be at least {} (got {})",
         m.dynamics->frames, m.dynamics->frames - 1, F);
  const auto cmds = action_commands(o.commands);
  const int64_t C = int64_t(cmds.size()), R = int64_t(o.prompts) * C;
  // With EPISODES, only drives it holds can be replayed: a mirror image (gaia tokenize --mirror) has no drive there.
  std::set<std::string> replayable;
  if (raw) replayable.insert(raw->ids().begin(), raw->ids().end());
  auto pr = held_out_prompts(ds, o.prompts, P, P + F + 1, m.info.config.run.seed, o.footage,
                             [&](size_t e) { return !raw || replayable.count(ds.ids()[e]) > 0; });
  if (raw)
    for (size_t e : pr.episodes)
      if (!ds.meta(e).is_procedural())
        fail("{}: action control's counterfactual replay needs procedural prompts, and held-out episode {} is recorded "
             "footage (give --prompt-footage procedural, or leave out EPISODES)", ds.path().string(), ds.ids()[e]);

  // Row r = prompt r / C under command r % C. The command takes over from the last prompt step's action (the one
  // that leads into the first generated frame), so all F generated frames follow it.
  world::RolloutPrompt cond;
  cond.tokens = pr.tokens.repeat_interleave(C, 0);                         // [R, P, n]
  cond.actions = torch::full({R, P + F, 2}, std::nan(""));
  cond.actions.narrow(1, 0, P).copy_(pr.actions.repeat_interleave(C, 0));
  std::vector<double> cmd_speed(static_cast<size_t>(R)), cmd_curv(static_cast<size_t>(R));
  std::vector<double> kept_speed(static_cast<size_t>(R));  // m/s the steering commands hold: the prompt's, >= 3
  std::vector<std::vector<synth::ActionStep>> per_frame(static_cast<size_t>(R));  // commanded (m/s, 1/m) per generated frame
  for (int64_t r = 0; r < R; ++r) {
    const auto& c = cmds[size_t(r % C)];
    double v0 = pr.actions[r / C][P - 1][0].item<double>() * world::kSpeedScale;
    if (!std::isfinite(v0)) v0 = 8.0;
    kept_speed[size_t(r)] = std::max(v0, 3.0);
    double ss = 0, sc = 0;
    for (int64_t j = 0; j < F; ++j) {
      synth::ActionStep a{c.speed >= 0 ? c.speed : kept_speed[size_t(r)], c.curvature + c.drift * double(j + 1)};
      per_frame[size_t(r)].push_back(a);
      for (int64_t k : {P - 1 + j, j == F - 1 ? P + j : P - 1 + j}) {
        cond.actions[r][k][0] = a.speed / world::kSpeedScale;
        cond.actions[r][k][1] = a.curvature / world::kCurvatureScale;
      }
      ss += a.speed;
      sc += a.curvature;
    }
    cmd_speed[size_t(r)] = ss / double(F);
    cmd_curv[size_t(r)] = sc / double(F);
  }
  world::RolloutPrompt null_actions = cond;  // the baseline: null action tokens from the last prompt step on,
  null_actions.actions = cond.actions.clone();  // guided towards the prompt's own actions against null ones
  null_actions.actions.narrow(1, P - 1, F + 1).fill_(std::nan(""));  // (a struct copy shares the tensors' storage)
  // The counter-command: turn the other way at the speed the steering commands keep (guidance's negative by
  // default, and what the replay is scored against).
  const auto counter = world::counter_actions(cond.actions, P - 1, torch::tensor(kept_speed));
  if (o.mirror_negative) cond.negative_actions = counter;

  world::RolloutOptions ro;
  ro.frames = int(F);
  ro.futures = int(R);
  ro.sampling = o.sampling;
  ro.precision = m.precision;
  ro.guidance.scale = o.guidance_scale;  // the baseline is guided too: towards the prompt's own actions
  ro.seed = o.seed;
  auto with = world::rollout(m.world, cond, ro);
  auto without = world::rollout(m.world, null_actions, ro);
  auto fw = decode(m, with.tokens), fo = decode(m, without.tokens);
  auto rw = read_rows(m, fw, P - 1), rn = read_rows(m, fo, P - 1);

  std::vector<size_t> all, in_dist, ood, steer;
  for (int64_t r = 0; r < R; ++r) {
    all.push_back(size_t(r));
    (cmds[size_t(r % C)].out_of_distribution ? ood : in_dist).push_back(size_t(r));
  }
  nlohmann::json j;
  j["rollouts"] = R;
  j["prompt_frames"] = P;
  j["generated_frames"] = F;
  j["guidance_scale"] = o.guidance_scale;
  j["negative_actions"] = o.mirror_negative ? "mirror" : "null";
  j["commands"] = o.commands;
  j["generated_frames_per_second"] = double(R * F) / with.seconds;
  j["conditioned"] = agreement(cmd_speed, cmd_curv, rw, all);
  j["conditioned_in_distribution"] = agreement(cmd_speed, cmd_curv, rw, in_dist);
  j["conditioned_out_of_distribution"] = agreement(cmd_speed, cmd_curv, rw, ood);
  j["without_actions"] = agreement(cmd_speed, cmd_curv, rn, all);
  // Per window of the probe's K frames (K - 1 steps): the mean of the curvatures commanded over its steps.
  std::vector<double> pair_cmd;
  const size_t steps = size_t(m.dynamics->frames - 1);
  for (int64_t r = 0; r < R; ++r) {
    const auto& a = per_frame[size_t(r)];
    for (size_t w = 0; w + steps <= a.size(); ++w) {
      double c = 0;
      for (size_t k = w; k < w + steps; ++k) c += a[k].curvature / double(steps);
      pair_cmd.push_back(c);
    }
  }
  j["conditioned"]["steering_sign_accuracy_per_frame"] = sign_accuracy(pair_cmd, rw.pair_read);  // per probe window
  j["probe_frames"] = m.dynamics->frames;

  // Strongly steered rollouts, read two ways: the dynamics probe and the generated video's own ego-motion.
  const double fps = ds.rate_hz() > 0 ? ds.rate_hz() : 6.25;
  const auto yaw = ego_motion_yaw_rates(fw, P - 1, fps);
  std::vector<double> strong_cmd, strong_probe, strong_ego;
  int ego_read = 0;
  for (int64_t r = 0; r < R; ++r)
    if (std::abs(cmd_curv[size_t(r)]) >= kStrongSteer) {
      strong_cmd.push_back(cmd_curv[size_t(r)]);
      strong_probe.push_back(rw.curvature[size_t(r)]);
      ego_read += std::isfinite(yaw[size_t(r)]);
      strong_ego.push_back(std::isfinite(yaw[size_t(r)]) ? yaw[size_t(r)] : -cmd_curv[size_t(r)]);  // unread = wrong
    }
  std::vector<double> all_yaw_cmd, all_yaw;
  for (int64_t r = 0; r < R; ++r)
    if (std::isfinite(yaw[size_t(r)])) {
      all_yaw_cmd.push_back(cmd_curv[size_t(r)]);
      all_yaw.push_back(yaw[size_t(r)]);
    }
  j["strong_steering"] = {{"min_curvature", kStrongSteer},
                          {"rollouts", strong_cmd.size()},
                          {"probe_sign_accuracy", sign_accuracy(strong_cmd, strong_probe)},
                          {"ego_motion_sign_accuracy", sign_accuracy(strong_cmd, strong_ego)},
                          {"ego_motion_read", strong_cmd.empty() ? 0.0 : double(ego_read) / double(strong_cmd.size())}};
  j["ego_motion"] = {{"rollouts_read", all_yaw.size()},
                     {"curvature_yaw_rate_spearman", all_yaw.size() > 2 ? eval::spearman(all_yaw_cmd, all_yaw) : std::nan("")},
                     {"yaw_rate_by_rollout", yaw}};

  // Counterfactual replay of the procedural world under the same commands: ground truth for every rollout.
  std::vector<std::vector<cv::Mat>> truth(static_cast<size_t>(R));
  Readback truth_read, truth_coded_read;  // the probe on the ground truth (as rendered / through the tokenizer)
  std::vector<std::vector<double>> truth_nats;  // [3][R]: the replay's codes under the command / counter-command / none
  if (raw) {
    const fs::path cf = out.dir / "counterfactual";
    for (int64_t r = 0; r < R; ++r) {
      const auto& id = ds.ids()[pr.episodes[size_t(r / C)]];
      auto it = std::find(raw->ids().begin(), raw->ids().end(), id);
      if (it == raw->ids().end())
        fail("{}: episode {} of the token dataset is not in this dataset (EPISODES must be the tokens' source)",
             raw->root().string(), id);
      data::Episode src = raw->episode(size_t(it - raw->ids().begin()));
      // Native frames per token step of this drive (a dataset of recorded clips beside it has other rates).
      const int stride = int(std::lround(src.meta().fps / (ds.rate_hz() > 0 ? ds.rate_hz() : 6.25)));
      const int64_t from = (pr.starts[size_t(r / C)] + P - 1) * stride;
      std::vector<synth::ActionStep> native;
      for (const auto& a : per_frame[size_t(r)])
        for (int s = 0; s < stride; ++s) native.push_back(a);
      native.push_back(per_frame[size_t(r)].back());
      auto meta = synth::replay(src, from, native, cf, fmt::format("{}-r{:03d}", id, r), true);
      data::Episode rep(cf / "episodes" / meta.id);
      for (int64_t k = 0; k <= F; ++k) truth[size_t(r)].push_back(rep.frame_bgr(k * stride));  // steps P-1 .. P+F-1
    }
    fs::remove_all(cf);  // frames on disk were only a means; the numbers and videos are what stays
    truth_read = read_rows(m, truth, 0);
    j["counterfactual_probe"] = agreement(cmd_speed, cmd_curv, truth_read, all);  // the probe on ground truth: the ceiling
    // The same ground truth through the tokenizer (encode, decode): what the probe reads of a perfect world model,
    // since every rollout reaches the probe through the tokenizer's decoder.
    std::vector<std::vector<cv::Mat>> truth_coded;
    std::vector<torch::Tensor> truth_codes;  // [F, n] per rollout: the replay's generated frames as codes
    for (const auto& row : truth) {
      auto codes = tokenizer::encode_frames(m.tok, row, m.dev);  // [F + 1, h, w]
      truth_codes.push_back(codes.narrow(0, 1, F).reshape({F, -1}).cpu());
      truth_coded.push_back(decode(m, codes.reshape({1, codes.size(0), -1}))[0]);
    }
    truth_coded_read = read_rows(m, truth_coded, 0);
    j["counterfactual_probe_tokenized"] = agreement(cmd_speed, cmd_curv, truth_coded_read, all);
    truth_nats = replay_nats(m, pr.tokens.repeat_interleave(C, 0), truth_codes,
                             {cond.actions, counter, null_actions.actions});
    double pw = 0, pn = 0;
    std::vector<torch::Tensor> fg, ft, fnull;
    for (int64_t r = 0; r < R; ++r) {
      std::vector<cv::Mat> g(fw[size_t(r)].begin() + P, fw[size_t(r)].end()), z(fo[size_t(r)].begin() + P, fo[size_t(r)].end());
      std::vector<cv::Mat> t(truth[size_t(r)].begin() + 1, truth[size_t(r)].end());
      pw += psnr_mean(g, t) / double(R);
      pn += psnr_mean(z, t) / double(R);
      torch::Tensor a, b, c;
      read_scene(m, g, &a);
      read_scene(m, t, &b);
      read_scene(m, z, &c);
      fg.push_back(a);
      ft.push_back(b);
      fnull.push_back(c);
    }
    j["counterfactual"] = {{"psnr_db", pw}, {"psnr_db_without_actions", pn},
                           {"fd_probe", probe::frechet_distance(torch::cat(fg), torch::cat(ft))},
                           {"fd_probe_without_actions", probe::frechet_distance(torch::cat(fnull), torch::cat(ft))}};
  }

  // Per command: what was asked and what came back (conditioned, without actions, ground truth).
  std::vector<std::string> names;
  eval::Series s_cmd{"commanded", {}, ""}, s_with{"world model", {}, ""}, s_null{"no action conditioning", {}, ""},
      s_truth{"counterfactual ground truth", {}, ""};
  nlohmann::json per = nlohmann::json::object();
  const size_t W = rw.pair_read.size() / size_t(R);  // probe windows per rollout (the same for every rollout)
  for (int64_t c = 0; c < C; ++c) {
    double a = 0, b = 0, t = 0, cs = 0, rs = 0;
    std::vector<double> by_window(W, 0.0);  // when in the rollout the turn is made (or given up)
    std::vector<double> by_rollout, commanded;  // which prompts turn the wrong way
    for (int i = 0; i < o.prompts; ++i) {
      const size_t r = size_t(i * C + c);
      by_rollout.push_back(rw.curvature[r]);
      commanded.push_back(cmd_curv[r]);
      for (size_t k = 0; k < W; ++k) by_window[k] += rw.pair_read[r * W + k] / o.prompts;
      a += rw.curvature[r] / o.prompts;
      b += rn.curvature[r] / o.prompts;
      cs += cmd_speed[r] / o.prompts;
      rs += rw.speed[r] / o.prompts;
    }
    double tc = 0, gap = 0, prefer = 0, gain_null = 0;
    if (raw)
      for (int i = 0; i < o.prompts; ++i) {
        const size_t r = size_t(i * C + c);
        t += truth_read.curvature[r] / o.prompts;
        tc += truth_coded_read.curvature[r] / o.prompts;
        gap += (truth_nats[1][r] - truth_nats[0][r]) / o.prompts;
        prefer += (truth_nats[0][r] < truth_nats[1][r]) / double(o.prompts);
        gain_null += (truth_nats[2][r] - truth_nats[0][r]) / o.prompts;
      }
    names.push_back(cmds[size_t(c)].name);
    s_cmd.y.push_back(cmd_curv[size_t(c)] * 1000);
    s_with.y.push_back(a * 1000);
    s_null.y.push_back(b * 1000);
    s_truth.y.push_back(t * 1000);
    per[cmds[size_t(c)].name] = {{"commanded_curvature", cmd_curv[size_t(c)]}, {"read_curvature", a},
                                 {"read_curvature_by_window", by_window}, {"read_curvature_by_rollout", by_rollout},
                                 {"read_curvature_without_actions", b}, {"commanded_speed", cs}, {"read_speed", rs},
                                 {"out_of_distribution", cmds[size_t(c)].out_of_distribution}};
    if (std::abs(cmd_curv[size_t(c)]) >= kSteerThreshold)  // its share of the steering sign accuracy
      per[cmds[size_t(c)].name]["steering_sign_accuracy"] = sign_accuracy(commanded, by_rollout);
    if (raw) {
      auto& row = per[cmds[size_t(c)].name];
      row["read_curvature_counterfactual"] = t;
      row["read_curvature_counterfactual_tokenized"] = tc;
      // Teacher-forced: how much better the replay scores under its command than under the counter-command / none.
      row["replay_nats_gain_over_counter_command"] = gap;
      row["replay_prefers_command"] = prefer;
      row["replay_nats_gain_over_no_action"] = gain_null;
    }
  }
  j["per_command"] = per;
  std::vector<eval::Series> series{s_cmd, s_with, s_null};
  if (raw) series.push_back(s_truth);
  out.text("plots/action_curvature.svg",
           eval::svg_bars("curvature read back by the dynamics probe (1/km) per command", names, series, 760, 320));

  // Videos of the first prompt: every steering command side by side, and its counterfactual ground truth.
  std::vector<std::vector<cv::Mat>> gen_rows, truth_rows;
  std::vector<std::string> labels;
  for (int64_t c = 0; c < std::min<int64_t>(C, 6); ++c) {
    gen_rows.push_back(fw[size_t(c)]);
    labels.push_back(cmds[size_t(c)].name);
    if (raw) {
      std::vector<cv::Mat> t(fw[size_t(c)].begin(), fw[size_t(c)].begin() + P - 1);
      t.insert(t.end(), truth[size_t(c)].begin(), truth[size_t(c)].end());
      truth_rows.push_back(t);
    }
  }
  out.gif("videos/action_generated.gif", tile(gen_rows, labels), fps / 2);
  nlohmann::json videos = nlohmann::json::array();
  videos.push_back({{"caption", "one held-out prompt, then each command (world model, decoded by the tokenizer)"},
                    {"items", {{{"label", "generated"}, {"path", "videos/action_generated.gif"}}}}});
  if (raw) {
    out.gif("videos/action_counterfactual.gif", tile(truth_rows, labels), fps / 2);
    videos.push_back({{"caption", "the procedural world replayed under the same commands (ground truth)"},
                      {"items", {{{"label", "counterfactual"}, {"path", "videos/action_counterfactual.gif"}}}}});
  }
  out.sections.push_back(
      {{"title", "Action control"},
       {"text", fmt::format("{} held-out prompts x {} commands ({} prompt frames, {} generated at {} Hz). The dynamics "
                            "probe reads the ego's speed and curvature back from each window of {} consecutive decoded "
                            "frames. strong-left / strong-right / drift-right are outside the recorded driving.",
                            o.prompts, C, P, F, fps, m.dynamics->frames)},
       {"videos", videos},
       {"plots", {{{"caption", "commanded vs read-back curvature"}, {"path", "plots/action_curvature.svg"}}}},
       {"metrics", j}});
  return j;
}

}  // namespace gaia::emerging
