#include "gaia/emerging/common.h"

#include <algorithm>

#include <opencv2/imgproc.hpp>

#include "gaia/core/error.h"
#include "gaia/data/gif.h"
#include "gaia/probe/trainer.h"
#include "gaia/tokenizer/io.h"
#include "gaia/world/batch.h"
#include "gaia/world/prompt_text.h"

namespace gaia::emerging {

Models load_models(const fs::path& world, const fs::path& tokenizer, const fs::path& dynamics_probe,
                   const fs::path& scene_probe, const torch::Device& dev, const fs::path& t5) {
  Models m;
  m.dev = dev;
  m.world_path = world;
  m.world = world::load_world(world, dev, &m.info);
  if (!m.info.embeds_text() || !t5.empty()) m.text = world::prompt_encoder(m.info, world.string(), t5, dev);
  m.tok = tokenizer::load_tokenizer(tokenizer, dev);
  check_tokenizer_fits(m.info, world, m.tok, tokenizer);
  m.dynamics = probe::load_probe(dynamics_probe, dev);
  if (m.dynamics->kind != probe::ProbeKind::kDynamics) fail("{}: not a dynamics probe", dynamics_probe.string());
  m.scene = probe::load_probe(scene_probe, dev);
  if (m.scene->kind != probe::ProbeKind::kScene) fail("{}: not a scene probe", scene_probe.string());
  return m;
}

void load_realism_probe(Models& m, const fs::path& path) {
  m.realism = probe::load_probe(path, m.dev);
  if (m.realism->kind != probe::ProbeKind::kRealism) fail("{}: not a realism probe", path.string());
}

text::TextEncoder& Models::text_encoder() const {
  if (!text) world::prompt_encoder(info, world_path.string(), {});  // fails, saying which flag to give
  if (!text->embeds() && info.vocab.size() == 0)
    fail("{}: the world model has no text vocabulary (trained without captions)", world_path.string());
  return *text;
}

void check_tokenizer_fits(const world::WorldInfo& info, const fs::path& world, const tokenizer::ImageTokenizer& tok,
                          const fs::path& tokenizer) {
  const int64_t D = tok->cfg.downsample, K = tok->cfg.codebook_size;
  if (tok->height / D != info.grid_h || tok->width / D != info.grid_w || K != info.K)
    fail("{}: the tokenizer makes {}x{} tokens of K = {}, the world model {} takes {}x{} of K = {}", tokenizer.string(),
         tok->height / D, tok->width / D, K, world.string(), info.grid_h, info.grid_w, info.K);
}

torch::Tensor episode_tokens(const world::TokenDataset& ds, size_t e) {
  auto ep = ds.episode(e);
  return torch::from_blob(const_cast<int32_t*>(ep->tokens.data()), {ds.steps(e), ds.tokens_per_step()}, torch::kInt)
      .to(torch::kLong);
}

Prompts held_out_prompts(const world::TokenDataset& ds, int count, int64_t frames, int64_t need, uint64_t seed,
                         Footage footage, const std::function<bool(size_t)>& keep) {
  auto split = ds.split(0.1, seed);
  auto ids = split.held_out();
  const int64_t skip = int64_t(std::lround(ds.rate_hz() > 0 ? ds.rate_hz() : 6.25));  // the first second
  std::vector<std::pair<size_t, int64_t>> pool;  // (episode, start): every held-out window, then spread
  for (size_t e : ds.indices(ids))
    if (footage_matches(ds, e, footage) && (!keep || keep(e)))
      for (int64_t s = skip; s + need <= ds.steps(e); s += frames) pool.push_back({e, s});
  if (pool.empty())
    fail("{}: no held-out {}episode has {} steps for a prompt (validation split of the token dataset)",
         ds.path().string(), footage == Footage::kAny ? "" : to_string(footage) + " ", need + skip);
  Prompts p;
  const int64_t n = ds.tokens_per_step();
  p.tokens = torch::zeros({count, frames, n}, torch::kLong);
  p.actions = torch::zeros({count, frames, 2});
  for (int i = 0; i < count; ++i) {
    // Evenly over the pool, and over episodes first: pool order is episode by episode.
    auto [e, s] = pool[(size_t(i) * pool.size()) / size_t(count)];
    p.episodes.push_back(e);
    p.starts.push_back(s);
    p.tokens[i].copy_(episode_tokens(ds, e).narrow(0, s, frames));
    p.actions[i].copy_(torch::from_blob(const_cast<float*>(ds.actions(e).data()) + 2 * s, {frames, 2}, torch::kFloat));
    p.actions[i].select(1, 0).div_(world::kSpeedScale);
    p.actions[i].select(1, 1).div_(world::kCurvatureScale);
  }
  return p;
}

std::vector<std::vector<cv::Mat>> decode(Models& m, const torch::Tensor& tokens) {
  const int64_t N = tokens.size(0), S = tokens.size(1);
  auto grid = tokens.reshape({N * S, m.info.grid_h, m.info.grid_w}).to(torch::kLong);
  auto frames = tokenizer::decode_tokens(m.tok, grid, m.dev);
  std::vector<std::vector<cv::Mat>> out(static_cast<size_t>(N));
  for (int64_t i = 0; i < N; ++i)
    out[size_t(i)].assign(frames.begin() + i * S, frames.begin() + (i + 1) * S);
  return out;
}

namespace {

torch::Tensor run_probe(probe::ProbeNet& net, const std::vector<torch::Tensor>& inputs, const torch::Device& dev,
                        torch::Tensor* features) {
  torch::NoGradGuard ng;
  net->eval();
  std::vector<torch::Tensor> outs, feats;
  for (size_t i = 0; i < inputs.size(); i += 64) {
    auto x = torch::stack(std::vector<torch::Tensor>(inputs.begin() + long(i),
                                                     inputs.begin() + long(std::min(inputs.size(), i + 64))))
                 .to(dev);
    auto f = net->features(x);
    outs.push_back(net->head(f).cpu());
    if (features) feats.push_back(f.cpu());
  }
  if (features) *features = torch::cat(feats);
  return torch::cat(outs);
}

}  // namespace

torch::Tensor read_dynamics(Models& m, const std::vector<cv::Mat>& frames) {
  const size_t K = size_t(m.dynamics->frames);
  if (frames.size() < K)
    fail("dynamics read-back: the probe reads {} consecutive frames, the sequence has {}", K, frames.size());
  std::vector<torch::Tensor> in;
  for (size_t k = 0; k + K <= frames.size(); ++k)
    in.push_back(probe::probe_input(std::vector<cv::Mat>(frames.begin() + long(k), frames.begin() + long(k + K))));
  auto y = run_probe(m.dynamics, in, m.dev, nullptr);
  y.select(1, 0).mul_(world::kSpeedScale);
  y.select(1, 1).mul_(world::kCurvatureScale);
  return y;
}

torch::Tensor read_scene(Models& m, const std::vector<cv::Mat>& frames, torch::Tensor* features) {
  std::vector<torch::Tensor> in;
  for (const auto& f : frames) in.push_back(probe::probe_input({f}));
  auto logits = run_probe(m.scene, in, m.dev, features);
  std::vector<torch::Tensor> ids;
  for (auto& head : probe::split_scene_logits(logits)) ids.push_back(head.argmax(1));
  return torch::stack(ids, 1);
}

torch::Tensor read_realism(Models& m, const std::vector<cv::Mat>& frames) {
  if (!m.realism) fail("realism read-back needs a realism probe (--realism-probe)");
  std::vector<torch::Tensor> in;
  for (const auto& f : frames) in.push_back(probe::probe_input({f}));
  return torch::sigmoid(run_probe(m.realism, in, m.dev, nullptr).select(1, 0).to(torch::kFloat64));
}

std::vector<cv::Mat> tile(const std::vector<std::vector<cv::Mat>>& rows, const std::vector<std::string>& labels) {
  std::vector<cv::Mat> out;
  if (rows.empty()) return out;
  size_t S = rows[0].size();
  for (const auto& r : rows) S = std::min(S, r.size());
  for (size_t k = 0; k < S; ++k) {
    std::vector<cv::Mat> cols;
    for (size_t i = 0; i < rows.size(); ++i) {
      cv::Mat f = rows[i][k].clone();
      if (i < labels.size() && !labels[i].empty())
        cv::putText(f, labels[i], {3, 11}, cv::FONT_HERSHEY_PLAIN, 0.8, {255, 255, 255}, 1, cv::LINE_AA);
      cols.push_back(f);
    }
    cv::Mat frame;
    cv::hconcat(cols, frame);
    out.push_back(frame);
  }
  return out;
}

void Output::gif(const std::string& rel, const std::vector<cv::Mat>& frames, double fps) const {
  fs::create_directories((dir / rel).parent_path());
  data::write_gif(dir / rel, frames, fps);
}

void Output::text(const std::string& rel, const std::string& content) const {
  fs::create_directories((dir / rel).parent_path());
  write_file_atomic(dir / rel, content);
}

}  // namespace gaia::emerging
