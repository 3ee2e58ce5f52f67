#include "gaia/decoder/evaluate.h"

#include <chrono>
#include <cmath>

#include "gaia/core/dtype.h"
#include "gaia/core/error.h"
#include "gaia/data/clip_sampler.h"
#include "gaia/data/frame_set.h"
#include "gaia/data/geofence.h"
#include "gaia/decoder/trainer.h"
#include "gaia/decoder/video.h"

namespace gaia::decoder {

double temporal_change(const torch::Tensor& f) {
  if (f.size(0) < 2) return 0.0;
  return ((f.slice(0, 1) - f.slice(0, 0, -1)).abs().mean().item<double>()) * 127.5;
}

double temporal_error(const torch::Tensor& f, const torch::Tensor& x) {
  if (f.sizes() != x.sizes()) fail("temporal_error: frames {} and truth {} differ in shape", shape_str(f.sizes().vec()),
                                   shape_str(x.sizes().vec()));
  if (f.size(0) < 2) return 0.0;
  const auto g = f.clamp(-1, 1);
  auto df = g.slice(0, 1) - g.slice(0, 0, -1), dx = x.slice(0, 1) - x.slice(0, 0, -1);
  return (df - dx).abs().mean().item<double>() * 127.5;
}

double edge_energy(const torch::Tensor& f) {
  const auto g = f.clamp(-1, 1);
  const double dx = (g.slice(-1, 1) - g.slice(-1, 0, -1)).abs().mean().item<double>();
  const double dy = (g.slice(-2, 1) - g.slice(-2, 0, -1)).abs().mean().item<double>();
  return (dx + dy) / 2 * 127.5;
}

double psnr_pm1(const torch::Tensor& a, const torch::Tensor& b) {
  const double mse = (a.clamp(-1, 1) - b).pow(2).mean().item<double>() / 4.0;
  return 10 * std::log10(1.0 / std::max(mse, 1e-12));
}

torch::Tensor blend_to_rate(const torch::Tensor& key, int factor) {
  if (factor < 1 || key.size(0) < 1) fail("decoder: blend_to_rate needs frames and a factor >= 1");
  std::vector<torch::Tensor> out;
  for (int64_t k = 0; k + 1 < key.size(0); ++k)
    for (int i = 0; i < factor; ++i) {
      const double f = double(i) / factor;
      out.push_back((1 - f) * key[k] + f * key[k + 1]);
    }
  out.push_back(key[key.size(0) - 1]);
  return torch::stack(out);
}

nlohmann::json evaluate_decoder(const Config& cfg, VideoUNet& model, tokenizer::ImageTokenizer& tok,
                                const fs::path& dataset, const DecoderEvalOptions& o,
                                const std::function<void(int, int)>& progress) {
  torch::NoGradGuard ng;
  const torch::Device dev = model->parameters().front().device();
  data::Dataset ds(dataset);
  std::vector<size_t> eps;
  for (size_t e : data::episode_indices(ds, data::held_out_ids(ds, cfg.run.seed)))
    if (world::footage_matches(ds.meta(e).is_procedural(), o.footage))
      eps.push_back(e);
  const int N = o.token_frames, M = 4 * N - 3;  // 25 Hz frames spanned by N frames at 6.25 Hz
  std::vector<std::unique_ptr<data::Episode>> episodes;
  std::vector<ClipRef> refs;
  nlohmann::json where = nlohmann::json::array();
  for (auto& c : data::spread_clips(ds, eps, M, 25.0, o.clips)) {  // spread over every held-out drive
    episodes.push_back(std::make_unique<data::Episode>(ds.episode(c.episode)));
    where.push_back({{"episode", ds.ids()[c.episode]}, {"start_s", episodes.back()->times()[size_t(c.frames[0])]}});
    refs.push_back({episodes.size() - 1, c.frames});
  }
  if (refs.empty())
    fail("{}: no held-out episode{} has {} frames at 25 Hz for a {}-frame token clip", dataset.string(),
         o.footage == world::Footage::kAny ? "" : " of " + world::to_string(o.footage) + " footage", M, N);
  NoiseSchedule sched{-15.0, 15.0, cfg.decoder.schedule_shift};
  DecodeOptions d;
  d.sample = sample_options(cfg.decoder, 0, o.seed);
  d.sample.precision = o.precision;
  d.token_fps = o.token_fps;
  // The 25 Hz frames that get tokens: every 4th, 2nd or each one.
  const int stride = o.token_fps == 6.25 ? 4 : o.token_fps == 12.5 ? 2 : o.token_fps == 25.0 ? 1 : 0;
  if (stride == 0) fail("decoder eval: --token-fps must be 6.25, 12.5 or 25, got {}", o.token_fps);
  if (o.generate && stride != 4) fail("decoder eval: generated tokens come at 6.25 Hz; --token-fps must be 6.25");
  const int windows = count_windows((M - 1) / stride + 1, cfg.decoder.frames, o.token_fps, 25.0);
  int total = 0, done = 0;
  for (int s : o.steps) total += int(refs.size()) * windows * s;

  nlohmann::json out;
  out["clips"] = refs.size();
  out["footage"] = world::to_string(o.footage);
  out["clip_starts"] = where;
  out["token_frames"] = N;
  out["frames_25hz"] = M;
  out["noise_correlation"] = d.sample.noise_correlation;
  out["noise_scale"] = d.sample.noise_scale;
  out["start_time"] = d.sample.start_time;
  out["token_fps"] = o.token_fps;
  out["tokens"] = o.generate ? "generated" : "true";
  std::vector<double> tok_key, tok_all, gt_key_change, gt_all_change, tok_key_change, tok_all_change;
  std::vector<double> tok_key_err, tok_all_err, blend_all, blend_all_change, blend_all_err;
  std::vector<double> gt_edges, tok_edges, blend_edges;  // edge_energy over the 25 Hz frames
  std::map<int, std::vector<double>> dif_key, dif_all, dif_key_change, dif_all_change, dif_key_err, dif_all_err, secs;
  std::map<int, std::vector<double>> dif_edges;
  for (size_t c = 0; c < refs.size(); ++c) {
    auto clip = load_clips(episodes, {refs[c]}, tok, true, dev);  // all 25 Hz frames, their tokens and decodings
    auto gt = clip.frames[0];                                      // [M, 3, H, W]
    auto key = torch::arange(0, M, 4, torch::kLong).to(dev);       // the 6.25 Hz frames
    auto gt_key = gt.index_select(0, key);
    auto tok_dec = clip.cond[0];  // the tokenizer decoder on every frame's own tokens
    auto tok_dec_key = tok_dec.index_select(0, key);
    auto tokens_key = clip.tokens[0].index_select(0, key);  // [N, h, w]
    if (o.generate) {  // both decoders get the generated token frames; 25 Hz has no tokens of its own then
      auto acts = torch::empty({N, 2}, torch::kFloat32);
      const auto& ep = *episodes[refs[c].episode];
      for (int k = 0; k < N; ++k) {
        const int64_t f = refs[c].frames[size_t(4 * k)];
        acts[k][0] = ep.speed(f);
        acts[k][1] = ep.curvature(f);
      }
      auto gen = o.generate(tokens_key, acts).to(dev);
      if (gen.sizes() != tokens_key.sizes())
        fail("decoder eval: the token generator gave {} for a clip of {}", shape_str(gen.sizes().vec()),
             shape_str(tokens_key.sizes().vec()));
      tokens_key = gen;
      tok_dec_key = tok->decode_tokens(gen).clamp(-1, 1);
    }
    auto blended = blend_to_rate(tok_dec_key, 4);  // the tokenizer decoder with the 6.25 Hz tokens only
    if (o.generate) tok_dec = blended;
    tok_key.push_back(psnr_pm1(tok_dec_key, gt_key));
    tok_all.push_back(psnr_pm1(tok_dec, gt));
    gt_key_change.push_back(temporal_change(gt_key));
    gt_all_change.push_back(temporal_change(gt));
    tok_key_change.push_back(temporal_change(tok_dec_key));
    tok_all_change.push_back(temporal_change(tok_dec));
    tok_key_err.push_back(temporal_error(tok_dec_key, gt_key));
    tok_all_err.push_back(temporal_error(tok_dec, gt));
    blend_all.push_back(psnr_pm1(blended, gt));
    blend_all_change.push_back(temporal_change(blended));
    blend_all_err.push_back(temporal_error(blended, gt));
    gt_edges.push_back(edge_energy(gt));
    tok_edges.push_back(edge_energy(tok_dec));
    blend_edges.push_back(edge_energy(blended));
    auto given = torch::arange(0, M, stride, torch::kLong).to(dev);  // the frames whose tokens the decoder gets
    auto tokens = clip.tokens.index_select(1, given);                  // [1, (M - 1) / stride + 1, h, w]
    auto cond = model->cfg.cond_image ? clip.cond.index_select(1, given) : torch::Tensor();
    if (o.generate) {
      tokens = tokens_key.unsqueeze(0);
      if (cond.defined()) cond = tok_dec_key.unsqueeze(0);
    }
    for (int s : o.steps) {
      d.sample.steps = s;
      auto t0 = std::chrono::steady_clock::now();
      auto video = decode_video(model, sched, tokens, cond, d, [&](int, int) {
        done += s;
        if (progress) progress(done, total);
      })[0];
      secs[s].push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      auto video_key = video.index_select(0, key);
      dif_key[s].push_back(psnr_pm1(video_key, gt_key));
      dif_all[s].push_back(psnr_pm1(video, gt));
      dif_key_change[s].push_back(temporal_change(video_key));
      dif_all_change[s].push_back(temporal_change(video));
      dif_key_err[s].push_back(temporal_error(video_key, gt_key));
      dif_all_err[s].push_back(temporal_error(video, gt));
      dif_edges[s].push_back(edge_energy(video));
    }
  }
  auto mean = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / double(v.size());
  };
  // Each clip's flicker (its change minus the truth's over the same frames): whether a decoder is lower on most
  // clips or on a few.
  auto per_clip = [](const std::vector<double>& change, const std::vector<double>& truth) {
    std::vector<double> f;
    for (size_t i = 0; i < change.size(); ++i) f.push_back(change[i] - truth[i]);
    return f;
  };
  const double gk = mean(gt_key_change), ga = mean(gt_all_change);
  const double ge = mean(gt_edges);
  out["ground_truth"] = {{"change_6.25hz", gk}, {"change_25hz", ga}, {"edge_energy", ge}};
  if (o.generate)
    out["psnr_note"] = "generated frames after the prompt: PSNR is against the recorded future, one of many";
  else
    out["tokenizer_decoder"] = {
        {"psnr_6.25hz", mean(tok_key)}, {"psnr_25hz", mean(tok_all)},
        {"flicker_6.25hz", mean(tok_key_change) - gk}, {"flicker_25hz", mean(tok_all_change) - ga},
        {"temporal_error_6.25hz", mean(tok_key_err)}, {"temporal_error_25hz", mean(tok_all_err)},
        {"sharpness", mean(tok_edges) / ge},
        {"note", "frame by frame from every frame's own tokens (at 25 Hz it gets 4x the tokens)"}};
  out["tokenizer_decoder_blended"] = {
      {"psnr_6.25hz", mean(tok_key)},      {"psnr_25hz", mean(blend_all)},
      {"flicker_6.25hz", mean(tok_key_change) - gk}, {"flicker_25hz", mean(blend_all_change) - ga},
      {"flicker_6.25hz_per_clip", per_clip(tok_key_change, gt_key_change)},
      {"flicker_25hz_per_clip", per_clip(blend_all_change, gt_all_change)},
      {"temporal_error_6.25hz", mean(tok_key_err)}, {"temporal_error_25hz", mean(blend_all_err)},
      {"sharpness", mean(blend_edges) / ge},
      {"note", "frame by frame from the 6.25 Hz tokens, linearly blended to 25 Hz (the video decoder's information)"}};
  for (int s : o.steps) {
    const double sec = mean(secs[s]);
    out["video_decoder"][std::to_string(s)] = {
        {"ddim_steps", s},
        {"psnr_6.25hz", mean(dif_key[s])},
        {"psnr_25hz", mean(dif_all[s])},
        {"flicker_6.25hz", mean(dif_key_change[s]) - gk},
        {"flicker_25hz", mean(dif_all_change[s]) - ga},
        {"flicker_6.25hz_per_clip", per_clip(dif_key_change[s], gt_key_change)},
        {"flicker_25hz_per_clip", per_clip(dif_all_change[s], gt_all_change)},
        {"temporal_error_6.25hz", mean(dif_key_err[s])},
        {"temporal_error_25hz", mean(dif_all_err[s])},
        {"sharpness", mean(dif_edges[s]) / ge},  // edge energy at 25 Hz over the ground truth's
        {"seconds_per_clip", sec},
        {"seconds_per_ddim_step", sec / (windows * s)},  // one step of one T'-frame window (mixing included)
        {"seconds_per_output_second", sec / ((M - 1) / 25.0)}};
  }
  return out;
}

}  // namespace gaia::decoder
