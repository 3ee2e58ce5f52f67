// gaia generate: roll out futures with the world model (§2.3, §5.1) from a video prompt (token dataset episode or a
// video file), or from nothing, steered by actions and text, with classifier-free guidance and schedules.
#include <cstdio>

#include <nlohmann/json.hpp>

#include "common.h"
#include "episode_prompt.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/torch/precision.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/generate.h"
#include "gaia/world/io.h"
#include "gaia/world/prompt_text.h"
#include "gaia/world/rollout.h"
#include "gaia/world/token_dataset.h"
#include "gaia/world/token_file.h"
#ifndef GAIA_NO_VIDEO
#include <opencv2/imgproc.hpp>

#include "gaia/data/video_io.h"
#include "gaia/emerging/common.h"
#include "gaia/synth/synth.h"
#include "gaia/tokenizer/io.h"
#endif

namespace gaia::app {

namespace {

struct GenerateFlags {
  std::string world, tokenizer, tokens, episode, video, actions_csv, steer = "none", text, negative,
      action_negative = "mirror", t5, text_emb, negative_emb;
  std::string sampling, token_schedule = "constant", frame_schedule = "constant";
  int start = 0, prompt_frames = -1, frames = 8, futures = 1, top_k = -1, plateau = 0, window_stride = 1;
  double speed = -1, top_p = 0.9, temperature = -1, guidance = 0;
  TokenFormatFlags format;  // TOKENS from another tokenizer
};

}  // namespace

void register_generate(CLI::App& app) {
  auto* cmd = app.add_subcommand("generate", "roll out futures with the world model (video/action/text prompts)");
  auto flags = std::make_shared<SharedFlags>();
  auto g = std::make_shared<GenerateFlags>();
  auto* tokens_opt = cmd->add_option("TOKENS", g->tokens, "video prompt from this token dataset or token file (with "
                                     "--episode; none: no video prompt)");
  add_token_format_flags(cmd, &g->format);
  add_weights_flag(cmd, Weights::World, &g->world)->required();
  add_weights_flag(cmd, Weights::Tokenizer, &g->tokenizer, "decodes a preview video, tokenizes --video");
  auto old_tokens = add_old_spelling(cmd, "--tokens", "the positional TOKENS");
  cmd->add_option("--episode", g->episode, "episode id or index in TOKENS");
  cmd->add_option("--start", g->start, "first prompt step in the episode");
  cmd->add_option("--video", g->video, "video prompt from a video file (needs --tokenizer)")
      ->excludes(tokens_opt)
      ->excludes(old_tokens->option);
  cmd->add_option("--prompt-frames", g->prompt_frames, "prompt frames (default: context - 1, at most 4)");
  cmd->add_option("--frames", g->frames, "frames to generate (sliding window beyond the context)")
      ->check(number_in({1, 1e6}));
  cmd->add_option("--window-stride", g->window_stride,
                  "steps the window drops when full (1 = the paper; S re-encodes the history every S frames, faster)")
      ->check(number_in({1, 1e6}));
  cmd->add_option("--futures", g->futures, "futures sampled in one batch")->check(number_in({1, 1e6}));
  cmd->add_option("--actions", g->actions_csv, "CSV with speed,curvature columns, one row per generated frame");
  cmd->add_option("--steer", g->steer, "steering preset: left, right, strong-left, strong-right, straight");
  cmd->add_option("--speed", g->speed, "speed for every generated frame (m/s)")->check(number_in({0, 100}));
  cmd->add_option("--text", g->text, "text prompt for every frame");
  cmd->add_option("--negative", g->negative, "negative prompt: replaces the unconditional logits (§5.1)");
  add_weights_flag(cmd, Weights::T5, &g->t5, "encodes --text / --negative for a world model trained on its embeddings");
  cmd->add_option("--text-emb", g->text_emb, "text prompt as embeddings: .npy/.safetensors [m, dim] or [steps, m, dim]")
      ->excludes("--text");
  cmd->add_option("--negative-emb", g->negative_emb, "negative prompt as embeddings (as --text-emb)")
      ->excludes("--negative");
  cmd->add_option("--sampling", g->sampling, "argmax, sample, top-k (default) or top-p");
  cmd->add_option("--top-k", g->top_k, "k for top-k (default: config world.top_k)")->check(key_range("world.top_k"));
  cmd->add_option("--top-p", g->top_p, "p for top-p")->check(number_in({0, 1, true, false}));
  cmd->add_option("--temperature", g->temperature, "softmax temperature (default: config world.temperature)")
      ->check(key_range("world.temperature"));
  auto* guidance_opt = cmd->add_option("--guidance", g->guidance,
                  "classifier-free guidance scale s (0 = off; default: the weights' world.guidance_scale); guided on "
                  "actions alone, top-k tokens stay within the "
                  "unguided top k (--set world.guide_actions_within_top_k=false lifts that)")
      ->check(key_range("world.guidance_scale"));
  cmd->add_option("--action-negative", g->action_negative,
                  "what guidance contrasts the actions with: mirror (the counter-command: turning the other way at "
                  "the prompt's speed; default) or null (no actions, eq. 2 as in the paper)")
      ->check(CLI::IsMember({"null", "mirror"}));
  cmd->add_option("--guidance-tokens", g->token_schedule, "guidance over the tokens of a frame: constant or linear");
  cmd->add_option("--guidance-frames", g->frame_schedule, "guidance over frames: constant or cosine");
  cmd->add_option("--plateau", g->plateau, "frames at full guidance before the cosine decay");
  add_shared_flags(cmd, flags.get(), "output directory (rollout.safetensors, preview.mp4)");
  cmd->callback([=] {
    old_spelling_into(*old_tokens, g->tokens);
    Config run = resolve_config(*flags);
    apply_threads(run);
    if (flags->out.empty()) fail("gaia generate: --out DIR is required");
    auto dev = parse_device(run.run.device);
    world::WorldInfo info;
    auto model = world::load_world(g->world, dev, &info);
    apply_sampling_sets(*flags, "world", kWorldSamplingKeys, g->world, info.config);  // --top-k still wins
    const auto& L = model->layout;
    const int64_t F = g->frames;
    if (F < 1) fail("--frames must be >= 1");

    // Video prompt: tokens [P, n] and the prompt's own actions.
    world::GenerateRequest req;
    const int64_t want_p = g->prompt_frames >= 0 ? g->prompt_frames : std::min<int64_t>(L.T - 1, 4);
#ifdef GAIA_NO_VIDEO
    if (!g->tokenizer.empty() || !g->video.empty() || !g->actions_csv.empty())
      fail("--tokenizer, --video and --actions need a build with video support (this one was built with "
           "-DGAIA_WITH_VIDEO=OFF): prompt from TOKENS, steer with --steer / --speed, decode elsewhere");
#else
    tokenizer::ImageTokenizer tok{nullptr};
    Config tok_cfg;
    if (!g->tokenizer.empty()) {
      tok = tokenizer::load_tokenizer(g->tokenizer, dev, &tok_cfg);
      emerging::check_tokenizer_fits(info, g->world, tok, g->tokenizer);  // before anything is written
    }
#endif
    if (!g->tokens.empty()) {
      world::TokenDataset ds(g->tokens, token_format(g->format, run, false, &info));
      if (ds.grid_h() != info.grid_h || ds.grid_w() != info.grid_w)
        fail("{}: a {}x{} token grid, the world model {} takes {}x{}", g->tokens, ds.grid_h(), ds.grid_w(), g->world,
             info.grid_h, info.grid_w);
      const size_t e = g->episode.empty() ? 0 : ds.find(g->episode);
      const int64_t P = std::min<int64_t>(want_p, ds.steps(e) - g->start);
      if (P <= 0) fail("--start {} is past the end of episode {} ({} steps)", g->start, ds.ids()[e], ds.steps(e));
      auto ep = episode_prompt(ds, e, g->start, P);
      req.prompt_tokens = ep.tokens;
      req.prompt_actions = ep.actions;
    }
#ifndef GAIA_NO_VIDEO
    else if (!g->video.empty()) {
      if (!tok) fail("--video needs --tokenizer to turn the frames into tokens");
      req.prompt_tokens = tokenizer::video_prompt_tokens(tok, tok_cfg, g->video, want_p, L.n, dev);
    }
#endif
    const int64_t P = req.prompt_tokens.defined() ? req.prompt_tokens.size(0) : 0;
    const int64_t steps = P + F;

    // Commands for the generated steps: --actions, or --steer / --speed at the prompt's last speed.
#ifndef GAIA_NO_VIDEO
    if (!g->actions_csv.empty()) {
      auto rows = synth::read_actions_csv(g->actions_csv);
      if (int64_t(rows.size()) != F)
        fail("{}: {} action rows but --frames is {} (one row per generated frame)", g->actions_csv, rows.size(), F);
      req.actions = torch::empty({F, 2});
      for (int64_t k = 0; k < F; ++k) {
        req.actions[k][0] = rows[size_t(k)].speed;
        req.actions[k][1] = rows[size_t(k)].curvature;
      }
    } else
#endif
    if (g->steer != "none" || g->speed >= 0)
      req.actions = world::steer_actions(g->steer, g->speed, req.prompt_actions, F);
    req.text = g->text;
    req.negative = g->negative;
    req.mirror_negative = g->action_negative == "mirror";
    for (auto [file, neg] : {std::pair{&g->text_emb, false}, std::pair{&g->negative_emb, true}}) {
      if (file->empty()) continue;
      if (!info.embeds_text())
        fail("{}: reads text with its own words; --text-emb / --negative-emb are for models trained on text "
             "embeddings", g->world);
      (neg ? req.negative_emb : req.text_emb) = world::read_prompt_embeddings(*file, info, steps);
    }
    std::shared_ptr<text::TextEncoder> encoder;
    if (!g->text.empty() || !g->negative.empty()) encoder = world::prompt_encoder(info, g->world, g->t5, dev);

    world::RolloutOptions& o = req.options;
    o = world::default_options(info);
    o.frames = int(F);
    o.futures = g->futures;
    o.window_stride = g->window_stride;
    o.seed = uint64_t(run.run.seed);
    o.sampling.strategy = world::parse_strategy(g->sampling.empty() ? "top-k" : g->sampling);
    if (g->top_k > 0) o.sampling.top_k = g->top_k;
    o.sampling.top_p = g->top_p;
    if (g->temperature > 0) o.sampling.temperature = g->temperature;
    if (guidance_opt->count()) o.guidance.scale = g->guidance;
    o.guidance.tokens = world::parse_token_schedule(g->token_schedule);
    o.guidance.frames = world::parse_frame_schedule(g->frame_schedule);
    o.guidance.plateau = g->plateau;
    ProgressBar bar(F, "generate");
    const Precision precision = run_precision(run, dev, "generate");
    o.precision = precision;            // each rollout step (and its lookahead thread) under it
    Autocast autocast(precision, dev);  // run.precision: bf16 / fp16 for the text encoder and the prompt too
    auto r = world::generate(model, info, g->world, req, encoder, [&](int done, int) { bar.update(done); });
    const auto& acts = r.actions;
    bar.finish();
    fs::create_directories(flags->out);
    auto grid = r.tokens.view({g->futures, steps, info.grid_h, info.grid_w}).to(torch::kInt);
    nlohmann::json meta = {{"prompt_frames", P}, {"frames", F}, {"futures", g->futures}, {"window_stride", g->window_stride},
                           {"sampling", world::to_string(o.sampling.strategy)}, {"guidance", o.guidance.scale},
                           {"guide_actions_within_top_k", o.sampling.guide_actions_within_top_k},
                           {"text", g->text}, {"negative", g->negative}, {"steer", g->steer},
                           {"action_negative", g->action_negative},
                           {"seconds", r.seconds}, {"frames_per_second", double(F * g->futures) / r.seconds}};
    save_tensors({{"tokens", grid}, {"actions", acts}}, fs::path(flags->out) / "rollout.safetensors",
                 {{"gaia.rollout", meta.dump()}});
    std::printf("generated %lld frames x %d futures in %.2f s (%.2f frames/s) -> %s/rollout.safetensors\n",
                (long long)F, g->futures, r.seconds, double(F * g->futures) / r.seconds, flags->out.c_str());
#ifndef GAIA_NO_VIDEO
    if (tok) {
      // Quick preview through the tokenizer's own decoder (frame by frame; the video decoder is `gaia decode`).
      std::vector<std::vector<cv::Mat>> rows;
      for (int f = 0; f < g->futures; ++f)
        rows.push_back(tokenizer::decode_tokens(tok, grid[f].to(torch::kLong), dev));
      std::vector<cv::Mat> video;
      for (int64_t k = 0; k < steps; ++k) {
        std::vector<cv::Mat> cols;
        for (auto& row : rows) cols.push_back(row[size_t(k)]);
        cv::Mat frame;
        cv::hconcat(cols, frame);
        if (k < P) cv::rectangle(frame, {0, 0}, {frame.cols - 1, frame.rows - 1}, {255, 255, 255}, 1);  // prompt
        video.push_back(frame);
      }
      data::write_video(fs::path(flags->out) / "preview.mp4", video, info.config.data.world_fps);
      std::printf("preview (tokenizer decoder, futures side by side, prompt frames outlined): %s/preview.mp4\n",
                  flags->out.c_str());
    }
#endif
  });
}

}  // namespace gaia::app
