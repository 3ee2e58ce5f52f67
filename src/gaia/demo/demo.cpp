#include "gaia/demo/demo.h"

#include <chrono>
#include <cmath>
#include <map>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <opencv2/imgproc.hpp>

#include "gaia/emerging/common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/data/episode.h"
#include "gaia/data/gif.h"
#include "gaia/data/video_io.h"
#include "gaia/decoder/pipeline.h"
#include "gaia/probe/probe.h"
#include "gaia/report/report.h"
#include "gaia/synth/synth.h"
#include "gaia/tokenizer/io.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/batch.h"
#include "gaia/world/prompt_text.h"
#include "gaia/world/rollout.h"

namespace gaia::demo {

namespace {

using Rows = std::vector<std::vector<cv::Mat>>;

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Frames of one rollout row through the tokenizer decoder, with the prompt frames outlined.
std::vector<cv::Mat> outlined(const std::vector<cv::Mat>& frames, int64_t P) {
  std::vector<cv::Mat> out;
  for (size_t k = 0; k < frames.size(); ++k) {
    cv::Mat f = frames[k].clone();
    if (int64_t(k) < P) cv::rectangle(f, {0, 0}, {f.cols - 1, f.rows - 1}, {255, 255, 255}, 1);
    out.push_back(f);
  }
  return out;
}

// The video prompt: a drive in the procedural world that no model has seen (another seed), or a video file.
struct VideoPrompt {
  std::string name;
  std::vector<cv::Mat> frames, continuation;  // continuation: what really came next (a video file)
  torch::Tensor actions;                      // [P, 2] normalised, NaN where unknown
  double speed = 8.0;                         // m/s the steering commands hold (the prompt's last, or 8)
  std::unique_ptr<data::Episode> episode;     // the procedural drive, for its counterfactual replay
};

VideoPrompt video_prompt(const DemoOptions& o, emerging::Models& m, const fs::path& out, int stride) {
  const auto& wc = m.info.config;
  const int64_t P = o.prompt_frames, F = o.frames;
  VideoPrompt vp;
  vp.actions = torch::full({P, 2}, std::nan(""));
  if (!o.video.empty()) {
    auto frames = data::read_frames_at_rate(o.video, wc.data.world_fps, P + F, m.tok->height, m.tok->width);
    if (int64_t(frames.size()) < P)
      fail("{}: {} frames at {} Hz, the prompt needs {}", o.video, frames.size(), wc.data.world_fps, P);
    vp.frames.assign(frames.begin(), frames.begin() + P);
    vp.continuation = frames;
    vp.name = fs::path(o.video).filename().string();
    return vp;
  }
  synth::SynthOptions so;
  so.height = m.tok->height;
  so.width = m.tok->width;
  so.fps = wc.data.native_fps;
  so.seconds = double((P + F + 1) * stride) / so.fps + 0.5;
  so.seed = 20261123;
  so.weather = "clear";
  so.time_of_day = "day";
  so.scene = "straight";
  so.overwrite = true;
  const fs::path ds_dir = out / "prompt";
  auto meta = synth::write_episode(ds_dir, so, 0);
  vp.episode = std::make_unique<data::Episode>(ds_dir / "episodes" / meta.id);
  for (int64_t k = 0; k < P; ++k) {
    vp.frames.push_back(vp.episode->frame_bgr(k * stride));
    vp.actions[k][0] = vp.episode->speed(k * stride) / world::kSpeedScale;
    vp.actions[k][1] = vp.episode->curvature(k * stride) / world::kCurvatureScale;
  }
  vp.speed = std::max(4.0, double(vp.episode->speed((P - 1) * stride)));
  vp.name = meta.id + ", \"" + vp.episode->caption(0) + "\"";
  return vp;
}

}  // namespace

const std::vector<TextPrompt>& demo_text_prompts() {
  // One weather and one lighting prompt, as the paper's text-conditioned figure shows (§5).
  static const std::vector<TextPrompt> v{{"night", 1, "night"}, {"heavy rain", 0, "rain"}};
  return v;
}

DemoResult run_demo(const DemoOptions& o, const fs::path& out, const std::function<void(const std::string&)>& say) {
  const auto t_start = std::chrono::steady_clock::now();
  auto need = [&](const char* name) {
    fs::path p = o.models / name;
    if (!fs::exists(p))
      fail("{}: missing; the demo uses the shipped models (run from the repository root, pass --models DIR, or "
           "train them with `gaia demo --from-scratch`)", p.string());
    return p;
  };
  const auto dev = parse_device(o.device);
  const fs::path world_w = need("world.safetensors"), tok_w = need("tokenizer.safetensors");  // checked in order
  const fs::path dyn_w = need("probe-dynamics.safetensors"), scene_w = need("probe-scene.safetensors");
  auto m = emerging::load_models(world_w, tok_w, dyn_w, scene_w, dev);
  const fs::path decoder_w = o.models / "decoder.safetensors";
  const auto& wc = m.info.config;
  const int64_t P = o.prompt_frames, F = o.frames;
  if (P < 1 || F < 1) fail("--prompt-frames and --frames must be >= 1");
  const double rate = wc.data.world_fps;
  const int stride = int(std::lround(wc.data.native_fps / rate));
  say(fmt::format("== gaia demo ==  world model {:.2f}M parameters, T = {} steps of {} tokens, tokenizer {}x{} -> {}x{}",
                  double(m.world->parameter_count()) / 1e6, wc.world.context_steps,
                  m.world->layout.length() / wc.world.context_steps, m.tok->height, m.tok->width, m.info.grid_h,
                  m.info.grid_w));

  // 1. The video prompt.
  VideoPrompt vp = video_prompt(o, m, out, stride);
  auto prompt = tokenizer::encode_frames(m.tok, vp.frames, dev).reshape({P, -1}).to(torch::kCPU).to(torch::kLong);
  say(fmt::format("prompt: {}, {} frames at {} Hz", vp.name, P, rate));

  // 2. Three futures (no actions after the prompt), then steer left / right in a second batch: only the
  // steering is guided (towards the commands, away from the mirrored commands).
  const std::vector<std::pair<std::string, double>> steer = {{"steer left", 0.01}, {"steer right", -0.01}};
  const int futures = 3;
  auto with_prompt = [&](int64_t rows) {
    world::RolloutPrompt rp;
    rp.tokens = prompt.unsqueeze(0).repeat({rows, 1, 1});
    rp.actions = torch::full({rows, P + F, 2}, std::nan(""));
    rp.actions.narrow(1, 0, P).copy_(vp.actions.unsqueeze(0).expand({rows, P, 2}));
    return rp;
  };
  world::RolloutPrompt sp = with_prompt(int64_t(steer.size()));
  for (size_t s = 0; s < steer.size(); ++s) {
    auto a = sp.actions[int64_t(s)].narrow(0, P - 1, F + 1);
    a.select(1, 0).fill_(vp.speed / world::kSpeedScale);
    a.select(1, 1).fill_(steer[s].second / world::kCurvatureScale);
  }
  sp.negative_actions = world::counter_actions(sp.actions, P - 1);  // left contrasted with right (rollout.h)
  world::RolloutOptions ro;
  ro.frames = int(F);
  ro.futures = futures;
  ro.sampling.top_k = wc.world.top_k;
  ro.sampling.temperature = wc.world.temperature;
  ro.sampling.guide_actions_within_top_k = wc.world.guide_actions_within_top_k;
  ro.seed = o.seed;
  ro.precision = o.precision;
  ProgressBar bar(4 * F, "rollouts");
  int64_t done = 0;
  auto step = [&](int k, int) { bar.update(done + k); };
  auto r1 = world::rollout(m.world, with_prompt(futures), ro, step);
  done += F;
  world::RolloutOptions so = ro;
  so.futures = int(steer.size());
  so.guidance.scale = o.action_guidance;
  auto rs = world::rollout(m.world, sp, so, step);
  done += F;

  // 3. Text alone (§5): no video prompt, the text prompt at every step and constant guidance on every frame.
  const auto& texts = demo_text_prompts();
  const int64_t M = wc.world.text_tokens, Tn = int64_t(texts.size());
  world::RolloutPrompt tp;
  std::vector<std::string> words;
  for (auto& t : texts) words.push_back(t.prompt);
  world::set_future_texts(tp, m.text_encoder(), words, F, M);
  world::RolloutOptions to = ro;
  to.futures = int(Tn);
  to.guidance.scale = o.text_guidance;
  to.guidance.total_frames = int(F);
  auto r2 = world::rollout(m.world, tp, to, step);
  done += F;

  // 4. An unconditional scene, from nothing.
  world::RolloutOptions uo = ro;
  uo.futures = 1;
  auto r3 = world::rollout(m.world, world::RolloutPrompt{}, uo, step);
  bar.finish();

  // 5. Ground truth for the steering: the prompt's world replayed under the same commands (procedural prompts).
  std::vector<std::vector<cv::Mat>> truth;
  for (size_t s = 0; vp.episode && s < steer.size(); ++s) {
    std::vector<synth::ActionStep> acts(size_t((F + 1) * stride), {vp.speed, steer[s].second});
    auto rm = synth::replay(*vp.episode, (P - 1) * stride, acts, out / "counterfactual",
                            fmt::format("{}-cf{}", vp.episode->meta().id, s), true);
    data::Episode rep(out / "counterfactual" / "episodes" / rm.id);
    std::vector<cv::Mat> t(vp.frames.begin(), vp.frames.end() - 1);
    for (int64_t k = 0; k <= F; ++k) t.push_back(rep.frame_bgr(k * stride));
    truth.push_back(t);
  }

  // 6. Decoding: the tokenizer's decoder for every rollout, the video decoder for the first future.
  auto f1 = emerging::decode(m, r1.tokens), fsteer = emerging::decode(m, rs.tokens), f2 = emerging::decode(m, r2.tokens),
       f3 = emerging::decode(m, r3.tokens);
  auto video = [&](const std::string& rel, const std::vector<cv::Mat>& frames, double fps) {
    fs::create_directories((out / rel).parent_path());
    data::write_gif(out / rel, frames, fps);
    data::write_video(fs::path(out / rel).replace_extension(".mp4"), frames, fps);
  };
  const double show = rate / 2;  // 6.25 Hz frames shown at half speed: short clips are easier to follow
  video("videos/futures.gif",
        emerging::tile(Rows{outlined(f1[0], P), outlined(f1[1], P), outlined(f1[2], P)}, {"future 1", "future 2", "future 3"}),
        show);
  video("videos/prompt.gif", emerging::tile(Rows{outlined(vp.frames, P)}, {"prompt"}), show);
  video("videos/steer_generated.gif",
        emerging::tile(Rows{outlined(fsteer[0], P), outlined(fsteer[1], P)}, {"left (model)", "right (model)"}), show);
  if (!truth.empty())
    video("videos/steer_truth.gif",
          emerging::tile(Rows{outlined(truth[0], P), outlined(truth[1], P)}, {"left (replay)", "right (replay)"}), show);
  if (!vp.continuation.empty()) video("videos/real.gif", emerging::tile(Rows{outlined(vp.continuation, P)}, {"real"}), show);
  std::vector<std::string> text_labels;
  for (const auto& t : texts) text_labels.push_back("\"" + t.prompt + "\"");
  video("videos/text.gif", emerging::tile(Rows(f2.begin(), f2.end()), text_labels), show);
  video("videos/unconditional.gif", emerging::tile(Rows{f3[0]}, {"unconditional"}), show);

  // Probe read-back of what the demo asked for.
  auto read_curv = [&](const std::vector<cv::Mat>& f) {  // NaN (null in the JSON) when too short for the probe
    if (int64_t(f.size()) - (P - 1) < m.dynamics->frames) return std::nan("");
    return emerging::read_dynamics(m, std::vector<cv::Mat>(f.begin() + P - 1, f.end())).select(1, 1).mean().item<double>();
  };
  nlohmann::json readback = {{"steer_left_curvature_per_km", 1000 * read_curv(fsteer[0])},
                             {"steer_right_curvature_per_km", 1000 * read_curv(fsteer[1])},
                             {"steer_guidance_scale", o.action_guidance},
                             {"commanded_left_per_km", 10.0},
                             {"commanded_right_per_km", -10.0},
                             {"text_guidance_scale", o.text_guidance}};
  std::vector<std::string> text_lines;
  for (size_t i = 0; i < texts.size(); ++i) {
    const auto& t = texts[i];
    const auto& names = t.attribute == 0 ? probe::weather_classes() : probe::time_classes();
    auto cls = emerging::read_scene(m, f2[i]).select(1, t.attribute).cpu();  // [F] class ids
    std::map<std::string, int> read;
    for (int64_t k = 0; k < cls.size(0); ++k) ++read[names[size_t(cls[k].item<int64_t>())]];
    const int hits = read.count(t.read_as) ? read[t.read_as] : 0;
    readback["text"][t.prompt] = {{"read_as", read}, {"frames", cls.size(0)}, {"share_as_prompted", double(hits) / double(cls.size(0))}};
    text_lines.push_back(fmt::format("\"{}\": {} of {} frames read as {}", t.prompt, hits, cls.size(0), t.read_as));
  }

  nlohmann::json dec_items = nlohmann::json::array();
  double dec_seconds = 0;
  if (fs::exists(decoder_w)) {
    const auto t0 = std::chrono::steady_clock::now();
    auto ids = r1.tokens.narrow(0, 0, 1).view({1, P + F, m.info.grid_h, m.info.grid_w});
    auto coarse = decoder::coarse_frames(m.tok, ids, dev);
    std::unique_ptr<ProgressBar> dbar;
    auto v = decoder::diffusion_decode(m.tok, decoder_w, ids, coarse, o.ddim_steps, rate, o.fps, o.seed, dev,
                                       [&](int k, int total) {
                                         if (!dbar) dbar = std::make_unique<ProgressBar>(total, "video decoder", true, k);
                                         dbar->update(k);
                                       },
                                       {}, o.precision);
    if (dbar) dbar->finish();
    dec_seconds = seconds_since(t0);
    video("videos/future1_video_decoder.gif", decoder::side_by_side(v), o.fps / 2);
    dec_items.push_back({{"label", fmt::format("video decoder, {} DDIM steps, {} Hz", o.ddim_steps, o.fps)},
                         {"path", "videos/future1_video_decoder.gif"}});
  } else {
    say(fmt::format("note: {} missing: the video diffusion decoder is skipped (tokenizer decoder only)", decoder_w.string()));
  }
  dec_items.push_back({{"label", "tokenizer decoder, 6.25 Hz"}, {"path", "videos/futures.gif"}});

  const std::string& cmdline = o.command_line;
  nlohmann::json futures_items = {{{"label", "prompt"}, {"path", "videos/prompt.gif"}},
                                  {{"label", "futures"}, {"path", "videos/futures.gif"}}};
  if (!vp.continuation.empty()) futures_items.push_back({{"label", "real"}, {"path", "videos/real.gif"}});
  nlohmann::json steer_items = {{{"label", "generated"}, {"path", "videos/steer_generated.gif"}}};
  if (!truth.empty()) steer_items.push_back({{"label", "ground truth"}, {"path", "videos/steer_truth.gif"}});
  nlohmann::json steer_metrics = readback;  // the steering part of the read-back
  steer_metrics.erase("text");
  steer_metrics.erase("text_guidance_scale");
  nlohmann::json sections = nlohmann::json::array();
  sections.push_back({{"title", "Video prompt and three futures"},
                      {"text", fmt::format("A {}-frame prompt from a drive the models never saw (outlined), then {} "
                                           "frames at {} Hz sampled with top-k = {}, shown at half speed.",
                                           P, F, rate, wc.world.top_k)},
                      {"videos", {{{"caption", vp.continuation.empty() ? "prompt | three futures"
                                                                      : "prompt | three futures | what really happened"},
                                   {"items", futures_items}}}},
                      {"commands", {cmdline}}});
  sections.push_back({{"title", "Steering"},
                      {"text", fmt::format("The same prompt with the actions commanded: curvature +0.01 (left) and "
                                           "-0.01 1/m (right), the speed held, with classifier-free guidance s = {} "
                                           "on the actions against the mirrored command. Beside it the procedural "
                                           "world replayed under the same commands: the counterfactual ground truth.",
                                           o.action_guidance)},
                      {"videos", {{{"caption", truth.empty() ? "world model" : "world model | counterfactual replay"},
                                   {"items", steer_items}}}},
                      {"metrics", steer_metrics},
                      {"commands", {cmdline}}});
  nlohmann::json text_metrics = nlohmann::json::object();
  for (const auto& t : texts) text_metrics[t.prompt + " read as " + t.read_as] = readback["text"][t.prompt]["share_as_prompted"];
  text_metrics["text_guidance_scale"] = o.text_guidance;
  sections.push_back({{"title", "Text prompts"},
                      {"text", fmt::format("Scenes generated from a text prompt alone (no video prompt, no actions), "
                                           "the prompt at every step and classifier-free guidance s = {} on every "
                                           "frame. The scene probe reads every decoded frame back: {}.",
                                           o.text_guidance, fmt::join(text_lines, "; "))},
                      {"videos", {{{"caption", fmt::format("{}", fmt::join(text_labels, " | "))},
                                   {"items", {{{"label", "text"}, {"path", "videos/text.gif"}}}}}}},
                      {"metrics", text_metrics},
                      {"commands", {cmdline}}});
  sections.push_back({{"title", "Unconditional scene"},
                      {"text", "Generated from nothing: no prompt, no actions, no text."},
                      {"videos", {{{"caption", "unconditional"},
                                   {"items", {{{"label", "scene"}, {"path", "videos/unconditional.gif"}}}}}}}});
  sections.push_back({{"title", "Decoders"},
                      {"text", fmt::format("The first future through the video diffusion decoder ({:.0f} s on this "
                                           "machine) and through the tokenizer's frame-by-frame decoder.",
                                           dec_seconds)},
                      {"videos", {{{"caption", "video decoder | tokenizer decoder"}, {"items", dec_items}}}}});
  DemoResult res;
  res.seconds = seconds_since(t_start);
  nlohmann::json manifest = {
      {"title", "gaia demo"},
      {"subtitle", fmt::format("shipped models from {}; {:.0f} s on this machine", o.models.string(), res.seconds)},
      {"sections", sections}};
  write_file_atomic(out / "report.json", manifest.dump(2) + "\n");
  res.report = out / "report.html";
  report::write_report(out, res.report);
  res.readback = readback;
  return res;
}

}  // namespace gaia::demo
