#include "gaia/probe/trainer.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "gaia/core/error.h"
#include "gaia/data/frame_set.h"
#include "gaia/data/geofence.h"
#include "gaia/eval/metrics.h"
#include "gaia/tokenizer/autoencoder.h"
#include "gaia/tokenizer/io.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/checkpoint.h"
#include "gaia/train/optim.h"
#include "gaia/train/schedule.h"
#include "gaia/train/step_loop.h"
#include "gaia/world/batch.h"

namespace gaia::probe {

namespace F = torch::nn::functional;

// A scene label a frame does not have (recorded footage: light state, lead vehicle); cross-entropy's ignore index.
constexpr int64_t kUnlabelled = -100;

torch::Tensor probe_input(const std::vector<cv::Mat>& frames) {
  std::vector<torch::Tensor> xs;
  for (const auto& f : frames) {
    cv::Mat c = f.isContinuous() ? f : f.clone();
    xs.push_back(tokenizer::image_to_tensor(c.data, c.rows, c.cols));
  }
  return torch::cat(xs, 0);
}

int dynamics_stride(const Config& c) { return std::max(1, int(std::lround(c.data.native_fps / c.data.world_fps))); }

Span span_of(const ProbeNet& net, const Config& c) {
  return net->kind == ProbeKind::kDynamics ? Span{int(net->frames), dynamics_stride(c)} : Span{};
}

torch::Tensor inputs(const std::vector<std::unique_ptr<data::Episode>>& eps, const std::vector<Example>& ex,
                     const Span& span, const Through& through, const std::vector<bool>& decoded) {
  std::vector<std::vector<cv::Mat>> frames;
  std::vector<cv::Mat> coded;  // the frames to read through the tokenizer, in order
  for (size_t i = 0; i < ex.size(); ++i) {
    const auto& e = ex[i];
    std::vector<cv::Mat> f;
    for (int k = 0; k < span.frames; ++k) f.push_back(eps.at(e.episode)->frame_bgr(e.frame + int64_t(k) * span.stride));
    if (through.tokenizer && (decoded.empty() || decoded.at(i))) coded.insert(coded.end(), f.begin(), f.end());
    frames.push_back(std::move(f));
  }
  if (!coded.empty()) {
    auto back = tokenizer::decode_tokens(*through.tokenizer, tokenizer::encode_frames(*through.tokenizer, coded, through.device),
                                         through.device);
    size_t next = 0;
    for (size_t i = 0; i < ex.size(); ++i)
      if (decoded.empty() || decoded.at(i))
        for (auto& f : frames[i]) f = back[next++];
  }
  std::vector<torch::Tensor> xs;
  for (const auto& f : frames) xs.push_back(probe_input(f));
  return torch::stack(xs);
}

tokenizer::ImageTokenizer load_through(const fs::path& tokenizer, const cv::Mat& sample, const fs::path& dataset,
                                       const torch::Device& dev) {
  auto tok = tokenizer::load_tokenizer(tokenizer, dev);
  if (sample.rows != tok->height || sample.cols != tok->width)
    fail("{}: the tokenizer reads {}x{} frames, {} has {}x{}", tokenizer.string(), tok->height, tok->width,
         dataset.string(), sample.rows, sample.cols);
  return tok;
}

size_t keep_with_signals(ExampleSet& s, const Span& span) {
  const size_t before = s.frames.size();
  s.frames.erase(std::remove_if(s.frames.begin(), s.frames.end(),
                                [&](const Example& e) {
                                  const auto& ep = *s.episodes.at(e.episode);
                                  for (int64_t i = e.frame; i <= e.frame + span.reach(); ++i)
                                    if (!std::isfinite(ep.speed(i)) || !std::isfinite(ep.curvature(i))) return true;
                                  return false;
                                }),
                 s.frames.end());
  return before - s.frames.size();
}

void mirror_dynamics(torch::Tensor& x, torch::Tensor& y, const std::vector<bool>& flip) {
  std::vector<int64_t> rows;
  for (size_t i = 0; i < flip.size(); ++i)
    if (flip[i]) rows.push_back(int64_t(i));
  if (rows.empty()) return;
  auto idx = torch::tensor(rows, torch::kLong).to(x.device());
  x.index_copy_(0, idx, x.index_select(0, idx).flip({3}));
  auto c = y.select(1, 1);
  c.index_copy_(0, idx.to(y.device()), -c.index_select(0, idx.to(y.device())));
}

torch::Tensor targets(ProbeKind kind, const std::vector<std::unique_ptr<data::Episode>>& eps,
                      const std::vector<Example>& ex, const Span& span) {
  if (kind == ProbeKind::kDynamics) {
    const int64_t reach = span.reach();
    std::vector<float> v;
    for (const auto& e : ex) {
      const auto& ep = *eps.at(e.episode);
      double s = 0, c = 0;
      for (int64_t i = e.frame; i <= e.frame + reach; ++i) s += ep.speed(i), c += ep.curvature(i);
      s /= double(reach + 1);
      c /= double(reach + 1);
      if (!std::isfinite(s) || !std::isfinite(c))
        fail("{}: frame {} has no speed/curvature (the dynamics probe needs them)", ep.dir().string(), e.frame);
      v.push_back(float(s / world::kSpeedScale));
      v.push_back(float(c / world::kCurvatureScale));
    }
    return torch::tensor(v).view({int64_t(ex.size()), 2});
  }
  if (kind == ProbeKind::kRealism) {
    std::vector<float> v;
    for (const auto& e : ex) v.push_back(eps.at(e.episode)->meta().is_procedural() ? 0.f : 1.f);
    return torch::tensor(v).view({int64_t(ex.size()), 1});
  }
  std::vector<int64_t> v;
  for (const auto& e : ex) {
    const auto& ep = *eps.at(e.episode);
    if (!ep.has_labels() && !ep.meta().is_procedural()) {
      // Recorded footage: the episode's weather and time of day (a manifest's columns) label every frame; its
      // light state and lead vehicle are not known and stay out of the loss and the accuracies.
      const int64_t w = class_index(weather_classes(), ep.meta().weather), t = class_index(time_classes(), ep.meta().time_of_day);
      if (w < 0 && t < 0)
        fail("{}: no labels.jsonl, and its metadata gives no weather or time_of_day the scene probe knows ('{}', '{}')",
             ep.dir().string(), ep.meta().weather, ep.meta().time_of_day);
      v.insert(v.end(), {w < 0 ? kUnlabelled : w, t < 0 ? kUnlabelled : t, kUnlabelled, kUnlabelled});
      continue;
    }
    if (!ep.has_labels()) fail("{}: no labels.jsonl (the scene probe trains on gaia synth data)", ep.dir().string());
    const auto& j = ep.labels(e.frame);
    auto cls = [&](const std::vector<std::string>& classes, const char* key) {
      int k = class_index(classes, j.value(key, std::string()));
      if (k < 0) fail("{}: frame {}: label '{}' has an unknown value", ep.dir().string(), e.frame, key);
      return int64_t(k);
    };
    v.push_back(cls(weather_classes(), "weather"));
    v.push_back(cls(time_classes(), "time_of_day"));
    v.push_back(cls(light_classes(), "light_state"));
    v.push_back(j.value("lead_close", false) ? 1 : 0);
  }
  return torch::tensor(v, torch::kLong).view({int64_t(ex.size()), 4});
}

torch::Tensor predict(ProbeNet& net, const ExampleSet& s, const Span& span, const torch::Device& dev,
                      const Through& through) {
  if (s.frames.empty()) fail("probe: no examples to predict");
  torch::NoGradGuard ng;
  const bool was_training = net->is_training();
  net->eval();
  std::vector<torch::Tensor> preds;
  for (size_t i = 0; i < s.frames.size(); i += 64) {
    std::vector<Example> part(s.frames.begin() + long(i), s.frames.begin() + long(std::min(s.frames.size(), i + 64)));
    preds.push_back(net->forward(inputs(s.episodes, part, span, through).to(dev)).cpu());
  }
  net->train(was_training);
  return torch::cat(preds);
}

namespace {

torch::Tensor loss_of(ProbeKind kind, const torch::Tensor& out, const torch::Tensor& y) {
  if (kind == ProbeKind::kDynamics) return F::mse_loss(out, y);
  if (kind == ProbeKind::kRealism) return F::binary_cross_entropy_with_logits(out, y);
  auto heads = split_scene_logits(out);
  torch::Tensor l = torch::zeros({}, out.options());
  for (size_t k = 0; k < heads.size(); ++k) {
    auto yk = y.select(1, int64_t(k));
    if (yk.ne(kUnlabelled).any().item<bool>())  // a batch of recorded frames only has no light labels
      l = l + F::cross_entropy(heads[k], yk, F::CrossEntropyFuncOptions().ignore_index(kUnlabelled));
  }
  return l;
}

std::vector<double> col(const torch::Tensor& t, int64_t c, double scale) {
  auto v = t.select(1, c).to(torch::kFloat64).contiguous();
  std::vector<double> out(v.data_ptr<double>(), v.data_ptr<double>() + v.numel());
  for (auto& x : out) x *= scale;
  return out;
}

}  // namespace

torch::Tensor realism_augment(const torch::Tensor& x, std::mt19937_64& rng) {
  // A few real clips teach their own look (a grey camera, one sunny road, night) as easily as "real": colour, light,
  // framing and side are drawn afresh for every example, so what is left to learn is how camera footage differs
  // from rendered frames.
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<torch::Tensor> out;
  const int64_t H = x.size(2), W = x.size(3);
  for (int64_t i = 0; i < x.size(0); ++i) {
    auto f = x[i];
    const double scale = 0.7 + 0.3 * u(rng);
    const int64_t h = std::max<int64_t>(8, std::lround(double(H) * scale)), w = std::max<int64_t>(8, std::lround(double(W) * scale));
    const int64_t top = int64_t(u(rng) * double(H - h + 1)) % (H - h + 1), left = int64_t(u(rng) * double(W - w + 1)) % (W - w + 1);
    f = F::interpolate(f.slice(1, top, top + h).slice(2, left, left + w).unsqueeze(0),
                       F::InterpolateFuncOptions().size(std::vector<int64_t>{H, W}).mode(torch::kBilinear).align_corners(false))
            .squeeze(0);
    if (u(rng) < 0.5) f = f.flip({2});
    auto grey = f.mean(0, true);
    const double saturation = u(rng) < 0.25 ? 0.0 : 1.5 * u(rng);
    f = grey + saturation * (f - grey);
    const double contrast = 0.6 + 0.8 * u(rng), brightness = 0.6 * (u(rng) - 0.5);
    f = (f - f.mean()) * contrast + f.mean() + brightness;
    out.push_back(f.clamp(-1, 1));
  }
  return torch::stack(out);
}

ExampleSet footage_balanced_set(const data::Dataset& ds, const std::vector<std::string>& ids, int n) {
  std::vector<std::string> real, procedural;
  const auto idx = data::episode_indices(ds, ids);
  for (size_t k = 0; k < ids.size(); ++k) (ds.meta(idx[k]).is_procedural() ? procedural : real).push_back(ids[k]);
  const int half = n > 0 ? std::max(1, n / 2) : 0;
  auto a = data::frame_set(ds, real, 0, half), b = data::frame_set(ds, procedural, 0, n > 0 ? n - half : 0);
  return data::merge(std::move(a), std::move(b));
}

nlohmann::json score(ProbeKind kind, const torch::Tensor& pred, const torch::Tensor& y) {
  nlohmann::json j;
  j["examples"] = pred.size(0);
  if (kind == ProbeKind::kDynamics) {
    auto ps = col(pred, 0, world::kSpeedScale), ys = col(y, 0, world::kSpeedScale);
    auto pc = col(pred, 1, world::kCurvatureScale), yc = col(y, 1, world::kCurvatureScale);
    double mae_s = 0, mae_c = 0, bias_c = 0;
    int steer = 0, right = 0;
    for (size_t i = 0; i < ps.size(); ++i) {
      mae_s += std::abs(ps[i] - ys[i]) / double(ps.size());
      mae_c += std::abs(pc[i] - yc[i]) / double(ps.size());
      bias_c += (pc[i] - yc[i]) / double(ps.size());
      if (std::abs(yc[i]) >= 0.002) {
        ++steer;
        right += (pc[i] > 0) == (yc[i] > 0);
      }
    }
    j["speed_mae_mps"] = mae_s;
    j["curvature_mae_per_m"] = mae_c;
    j["curvature_bias_per_m"] = bias_c;  // + = reads more left than the drive turned
    j["speed_spearman"] = eval::spearman(ps, ys);
    j["curvature_spearman"] = eval::spearman(pc, yc);
    j["steering_sign_accuracy"] = steer ? double(right) / steer : 0.0;
    j["steering_examples"] = steer;
    return j;
  }
  if (kind == ProbeKind::kRealism) {
    auto real = y.select(1, 0) > 0.5, read_real = pred.select(1, 0) > 0;
    const int64_t n_real = real.sum().item<int64_t>(), n_proc = y.size(0) - n_real;
    j["accuracy"] = read_real.eq(real).to(torch::kFloat64).mean().item<double>();
    j["real_examples"] = n_real;
    j["procedural_examples"] = n_proc;
    // The share read as real of each kind: the first is the probe's recall on real frames, the second its false alarms.
    j["real_read_as_real"] = n_real ? (read_real & real).sum().item<double>() / double(n_real) : 0.0;
    j["procedural_read_as_real"] = n_proc ? (read_real & ~real).sum().item<double>() / double(n_proc) : 0.0;
    return j;
  }
  auto heads = split_scene_logits(pred);
  const char* names[4] = {"weather_accuracy", "time_of_day_accuracy", "light_state_accuracy", "lead_close_accuracy"};
  for (size_t k = 0; k < 4; ++k) {
    auto yk = y.select(1, int64_t(k));
    auto known = yk.ne(kUnlabelled);  // recorded frames have no light state or lead-vehicle label
    const int64_t n = known.sum().item<int64_t>();
    j[names[k]] = n ? heads[k].argmax(1).eq(yk).logical_and(known).sum().item<double>() / double(n) : std::nan("");
  }
  return j;
}

nlohmann::json score_by_footage(ProbeKind kind, const torch::Tensor& pred, const torch::Tensor& y, const ExampleSet& s) {
  auto j = score(kind, pred, y);
  if (kind == ProbeKind::kRealism) return j;  // its score already splits the two
  std::vector<int64_t> real;
  for (size_t i = 0; i < s.frames.size(); ++i)
    if (!s.episodes.at(s.frames[i].episode)->meta().is_procedural()) real.push_back(int64_t(i));
  if (!real.empty() && real.size() < s.frames.size()) {
    const auto idx = torch::tensor(real, torch::kLong);
    j["real"] = score(kind, pred.index_select(0, idx), y.index_select(0, idx));
  }
  return j;
}

ProbeTrainResult train_probe(const Config& cfg, const ProbeTrainOptions& opt,
                             const std::function<void(int, int, double, const nlohmann::json&)>& on_step,
                             const std::function<void(const std::string&)>& on_note) {
  const torch::Device dev = parse_device(cfg.run.device);
  ProbeTrainResult result;
  train::RunDir run_dir(opt.out, on_note);  // one run per --out; a checkpoint a kill broke is put back
  data::Dataset ds(opt.dataset);
  auto split = data::load_or_default_split(ds, data::kDefaultValFraction, cfg.run.seed);
  auto val_ids = split.held_out();
  torch::manual_seed(cfg.run.seed);
  ProbeNet net(opt.kind, opt.frames);
  const Span span = span_of(net, cfg);
  auto train = data::frame_set(ds, split.train, span.reach(), 0);
  // The realism probe scores its two classes on equal footing: a few real clips beside many procedural drives.
  auto val = opt.kind == ProbeKind::kRealism ? footage_balanced_set(ds, val_ids, opt.val_examples)
                                             : data::frame_set(ds, val_ids, span.reach(), opt.val_examples);
  if (opt.kind == ProbeKind::kDynamics) {
    const size_t dropped = keep_with_signals(train, span) + keep_with_signals(val, span);
    if (dropped && on_note)
      on_note(fmt::format("{} examples left out: a frame of theirs has no speed or curvature (recorded footage the "
                          "estimate could not read)", dropped));
  }
  const auto& train_eps = train.episodes;
  const auto& train_ex = train.frames;
  if (train_ex.empty()) fail("{}: no training frames for the {} probe", opt.dataset.string(), to_string(opt.kind));
  // Realism batches draw half their frames from each class, however few real frames there are.
  std::vector<Example> real_ex, procedural_ex;
  if (opt.kind == ProbeKind::kRealism) {
    for (const auto& e : train_ex) (train_eps.at(e.episode)->meta().is_procedural() ? procedural_ex : real_ex).push_back(e);
    if (real_ex.empty() || procedural_ex.empty())
      fail("{}: the realism probe needs real and procedural episodes among the training episodes; it has {} real and "
           "{} procedural frames there", opt.dataset.string(), real_ex.size(), procedural_ex.size());
  }
  if (val.frames.empty() && on_note) on_note("no held-out episodes: validation skipped");
  if (!(opt.decoded_share >= 0 && opt.decoded_share <= 1))
    fail("probe training: decoded_share must be in [0, 1], got {}", opt.decoded_share);
  tokenizer::ImageTokenizer tok{nullptr};
  Through through;
  if (!opt.tokenizer.empty()) {
    tok = load_through(opt.tokenizer, train_eps.at(train_ex[0].episode)->frame_bgr(train_ex[0].frame), opt.dataset, dev);
    through = {&tok, dev};
  }

  net->to(dev);
  auto optim = train::make_adamw(net->parameters(), opt.lr, 1e-4, 0.9, 0.999);
  train::WarmupCosine sched{opt.lr, opt.lr / 20, 50, opt.steps};
  const fs::path ckpt = opt.out / "checkpoint";
  int step = 0;
  if (train::has_checkpoint(ckpt)) {
    step = train::load_checkpoint(ckpt, {{"probe", net.ptr().get()}}, {{"probe", optim.get()}}).step;
    result.resumed = true;
    if (on_note) on_note(fmt::format("resumed from {} at step {}", ckpt.string(), step));
  }
  fs::create_directories(opt.out);
  train::StepLoop loop(opt.out / "metrics.jsonl", step, opt.steps, cfg.run.checkpoint_every, opt.stop_after);
  auto save = [&] { train::save_checkpoint(ckpt, {{"probe", net.ptr().get()}}, {{"probe", optim.get()}}, {step, {}}); };
  auto validate = [&] {
    nlohmann::json v;
    if (val.frames.empty()) return v;
    const auto y = targets(opt.kind, val.episodes, val.frames, span);
    v = score_by_footage(opt.kind, predict(net, val, span, dev), y, val);
    if (through.tokenizer) v["decoded"] = score_by_footage(opt.kind, predict(net, val, span, dev, through), y, val);
    return v;
  };
  net->train();
  while (step < opt.steps) {
    std::mt19937_64 rng(train::step_seed(cfg.run.seed, step));
    std::vector<Example> b;
    auto draw = [&](const std::vector<Example>& from, int n) {
      std::uniform_int_distribution<size_t> pick(0, from.size() - 1);
      for (int i = 0; i < n; ++i) b.push_back(from[pick(rng)]);
    };
    if (opt.kind == ProbeKind::kRealism) {
      draw(real_ex, opt.batch / 2);
      draw(procedural_ex, opt.batch - opt.batch / 2);
    } else {
      draw(train_ex, opt.batch);
    }
    std::vector<bool> decoded;
    if (through.tokenizer) {
      std::bernoulli_distribution coin(opt.decoded_share);
      for (int i = 0; i < opt.batch; ++i) decoded.push_back(coin(rng));
    }
    auto x = inputs(train_eps, b, span, through, decoded).to(dev);
    // Realism has no side; the dynamics probe's label is the side, so its flips negate the curvature too.
    if (opt.kind == ProbeKind::kRealism) x = realism_augment(x, rng);
    auto y = targets(opt.kind, train_eps, b, span).to(dev);
    if (opt.kind == ProbeKind::kDynamics && opt.mirror) {
      std::bernoulli_distribution coin(0.5);
      std::vector<bool> flip;
      for (size_t i = 0; i < b.size(); ++i) flip.push_back(coin(rng));
      mirror_dynamics(x, y, flip);
    }
    const double lr = sched(step);
    train::set_lr(*optim, lr);
    auto loss = loss_of(opt.kind, net->forward(x), y);
    const double lv = loss.item<double>();
    if (!std::isfinite(lv)) fail("{} probe training diverged at step {}", to_string(opt.kind), step);
    optim->zero_grad();
    loss.backward();
    optim->step();
    ++step;
    nlohmann::json val;
    if (loop.validate_now(step, opt.val_every)) result.last_val = val = validate();
    if (on_step) on_step(step, opt.steps, lv, val);
    if (loop.end_step(step, {{"step", step}, {"lr", lr}, {"loss", lv}, {"val", val}}, save)) break;
  }
  result.final_step = step;
  if (step >= opt.steps) {
    result.weights = opt.out / ("probe-" + to_string(opt.kind) + ".safetensors");
    save_module(*net, result.weights,
                {{"gaia.component", "probe"}, {"gaia.probe.kind", to_string(opt.kind)},
                 {"gaia.probe.frames", std::to_string(net->frames)}, {"gaia.probe.val", result.last_val.dump()},
                 {"gaia.probe.decoded_share", fmt::format("{}", through.tokenizer ? opt.decoded_share : 0.0)}});
  }
  return result;
}

ProbeNet load_probe(const fs::path& path, const torch::Device& device) {
  ProbeKind kind;
  int64_t frames = 0;
  {
    SafetensorsFile f(path);
    auto md = f.metadata();
    if (md["gaia.component"] != "probe" || !md.count("gaia.probe.kind"))
      fail("{}: not a gaia probe weights file (no probe metadata)", path.string());
    kind = parse_kind(md["gaia.probe.kind"]);
    if (kind == ProbeKind::kDynamics) frames = 2;  // saved before the frame count was recorded: a pair probe
    if (md.count("gaia.probe.frames")) {
      const std::string& v = md["gaia.probe.frames"];
      if (v.empty() || v.find_first_not_of("0123456789") != std::string::npos || std::stoll(v) < 1 || std::stoll(v) > 64)
        fail("{}: metadata gaia.probe.frames '{}' is not a frame count", path.string(), v);
      frames = std::stoll(v);
    }
  }
  ProbeNet net(kind, frames);
  load_module(*net, path);
  net->to(device);
  net->eval();
  return net;
}

}  // namespace gaia::probe
