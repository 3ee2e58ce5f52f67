#include "gaia/world/token_dataset.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <nlohmann/json.hpp>

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/core/npy.h"
#include "gaia/world/token_file.h"
#include "gaia/train/checkpoint.h"

namespace gaia::world {

using nlohmann::json;

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

std::vector<std::string> read_jsonl_strings(const fs::path& p) {
  std::string text = read_file(p);
  std::vector<std::string> out;
  for (size_t start = 0; start < text.size();) {
    size_t nl = text.find('\n', start);
    if (nl == std::string::npos) nl = text.size();
    try {
      out.push_back(json::parse(text.substr(start, nl - start)).get<std::string>());
    } catch (const std::exception&) {
      fail("{}: line {} is not a JSON string", p.string(), out.size() + 1);
    }
    start = nl + 1;
  }
  return out;
}

// Token ids of an integer .npy as int32 (int16 from gaia tokenize).
std::vector<int32_t> token_ids(const NpyArray& a, const fs::path& file) {
  if (!is_integer(a.dtype) || a.dtype == DType::BOOL)
    fail("{}: token array has dtype {}; token ids must be integers", file.string(), safetensors_name(a.dtype));
  std::vector<int32_t> out;
  out.reserve(static_cast<size_t>(a.size()));
  for (int64_t v : a.to_int64()) {
    // Anything beyond int32 is out of every codebook; keep it negative so the range check reports it.
    out.push_back(v >= 0 && v <= std::numeric_limits<int32_t>::max() ? static_cast<int32_t>(v) : -1);
  }
  return out;
}

std::vector<fs::path> token_files_in(const fs::path& dir) {
  std::vector<fs::path> out;
  for (auto& d : fs::directory_iterator(dir))
    if (is_token_file(d.path())) out.push_back(d.path());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

Conditioning ConditioningMix::draw(std::mt19937_64& rng, bool replay) const {
  const double total = p_uncond + p_action + p_text;
  if (!(p_uncond >= 0 && p_action >= 0 && p_text >= 0 && total > 0))
    fail("world.p_uncond / p_action / p_text must be >= 0 with a positive sum, got {} / {} / {}", p_uncond, p_action, p_text);
  if (replay && p_action_replay >= 0) {
    if (p_action_replay > 1) fail("world.p_action_replay must be in [0, 1], got {}", p_action_replay);
    const double u = std::uniform_real_distribution<double>(0, 1)(rng), rest = p_uncond + p_text;
    if (u < p_action_replay || rest <= 0) return Conditioning::kAction;
    return (u - p_action_replay) < (1 - p_action_replay) * p_uncond / rest ? Conditioning::kUnconditional
                                                                           : Conditioning::kText;
  }
  double u = std::uniform_real_distribution<double>(0, total)(rng);
  if (u < p_uncond) return Conditioning::kUnconditional;
  if (u < p_uncond + p_action) return Conditioning::kAction;
  return Conditioning::kText;
}

TokenDataset::TokenDataset(const fs::path& path, int64_t codebook_size, size_t cache_episodes)
    : TokenDataset(path, [&] {
        TokenFormat f;
        f.codebook_size = codebook_size;
        return f;
      }(), cache_episodes) {}

TokenDataset::TokenDataset(const fs::path& path, const TokenFormat& format, size_t cache_episodes)
    : path_(path), format_(format), cache_capacity_(std::max<size_t>(cache_episodes, 1)) {
  if (!fs::exists(path))
    fail("{}: no such token dataset (a directory from gaia tokenize, or token files: docs/formats.md)", path.string());
  if (fs::is_regular_file(path)) {
    if (!is_token_file(path)) fail("{}: not a token file (want .npy or .safetensors)", path.string());
    open_file(format);
    return;
  }
  fs::path hf = path / "dataset.json";
  if (!fs::exists(hf)) {
    auto files = token_files_in(path);
    if (files.empty())
      fail("{}: not a token dataset (no dataset.json from gaia tokenize, and no .npy or .safetensors token files)",
           path.string());
    open_files(files, format);
    return;
  }
  const int64_t codebook_size = format.codebook_size;
  json header = read_json(hf);
  try {
    if (header.at("format").get<std::string>() != "gaia-tokens")
      fail("{}: format is '{}', not gaia-tokens", hf.string(), header.at("format").get<std::string>());
    if (header.at("schema_version").get<int>() != 1)
      fail("{}: schema_version {} is not supported (this gaia reads 1)", hf.string(), header.at("schema_version").get<int>());
    auto grid = header.at("grid").get<std::vector<int64_t>>();
    if (grid.size() != 2 || grid[0] < 1 || grid[1] < 1) fail("{}: grid must be [h, w] with h, w >= 1", hf.string());
    h_ = grid[0];
    w_ = grid[1];
    K_ = header.at("codebook_size").get<int64_t>();
    rate_hz_ = header.value("rate_hz", 0.0);
  } catch (const json::exception& e) {
    fail("{}: bad token dataset header ({})", hf.string(), e.what());
  }
  if (K_ < 1) fail("{}: codebook_size must be >= 1, got {}", hf.string(), K_);
  if (codebook_size > 0 && codebook_size != K_)
    fail("{}: codebook_size is {}, but {} was expected (tokens from a different tokenizer?)", hf.string(), K_, codebook_size);

  // Same rule as data::Dataset: a directory with episode.json is a finished episode; staging dirs are skipped.
  if (fs::exists(path / "episodes"))
    for (auto& d : fs::directory_iterator(path / "episodes")) {
      std::string name = d.path().filename().string();
      if (d.is_directory() && name.rfind(".tmp-", 0) != 0 && fs::exists(d.path() / "episode.json")) ids_.push_back(name);
    }
  std::sort(ids_.begin(), ids_.end());
  for (size_t e = 0; e < ids_.size(); ++e) {
    fs::path dir = episode_dir(e), mf = dir / "episode.json";
    json j = read_json(mf);
    Info info;
    info.meta = data::EpisodeMeta::from_json(j, mf.string());
    try {
      info.steps = j.at("steps").get<int64_t>();
    } catch (const json::exception& ex) {
      fail("{}: no step count ({})", mf.string(), ex.what());
    }
    if (info.steps < 1) fail("{}: steps must be >= 1, got {}", mf.string(), info.steps);
    fs::path af = dir / "actions.npy";
    if (fs::exists(af)) {
      NpyArray a = npy_read(af);
      if (a.shape != std::vector<int64_t>{info.steps, 2})
        fail("{}: shape {}, want [{}, 2] (steps from episode.json, speed and curvature)", af.string(),
             shape_str(a.shape), info.steps);
      std::vector<double> v = a.to_double();
      info.actions.assign(v.begin(), v.end());
    } else {
      info.actions.assign(static_cast<size_t>(info.steps) * 2, kNaN);  // no signals: every action is missing
    }
    has_captions_ = has_captions_ || fs::exists(dir / "captions.jsonl");
    info_.push_back(std::move(info));
  }
  // Text embeddings come for every episode or for none, so no batch mixes embedded and missing text.
  size_t with = 0;
  for (size_t e = 0; e < ids_.size(); ++e) with += !text_emb_file(episode_dir(e)).empty();
  if (fs::exists(path / kTextEmbPartialFile)) {
    // gaia text embed is writing them (or was interrupted): none until it finishes.
  } else if (with > 0) {
    for (size_t e = 0; e < ids_.size(); ++e)
      if (text_emb_file(episode_dir(e)).empty())
        fail("{}: no text_emb.npy, but {} of the {} episodes have text embeddings (all or none; docs/formats.md)",
             episode_dir(e).string(), with, ids_.size());
    text_emb_ = probe_text_emb_info(path, text_emb_file(episode_dir(0)));
  } else if (fs::exists(path / kTextEmbInfoFile)) {
    fail("{}: describes text embeddings, but no episode has a text_emb.npy", (path / kTextEmbInfoFile).string());
  }
}

void TokenDataset::open_file(const TokenFormat& stated) {
  // One drive: training on its first part, validation on its end, so early stopping and the best checkpoint work.
  const TokenSidecar side = read_token_sidecar(path_);
  const TokenFormat f = file_format(stated, side, path_);
  if (f.keep_rate && f.rate_hz <= 0)
    fail("{}: --keep-rate needs the file's own frame rate: --token-fps, or 'fps' in its sidecar", path_.string());
  TokenArray a = read_token_file(path_, f);
  h_ = a.h;
  w_ = a.w;
  K_ = f.codebook_size > 0 ? f.codebook_size : *std::max_element(a.ids.begin(), a.ids.end()) + 1;
  rate_hz_ = f.dataset_rate_hz();
  if (!(f.val_fraction >= 0 && f.val_fraction < 1)) fail("validation fraction must be in [0, 1), got {}", f.val_fraction);
  const int64_t held = std::min(a.steps - 1, static_cast<int64_t>(std::llround(double(a.steps) * f.val_fraction)));
  const int64_t n = h_ * w_, cut = a.steps - held;
  const std::string stem = path_.stem().string();
  for (int part = 0; part < (held > 0 ? 2 : 1); ++part) {
    const int64_t s0 = part == 0 ? 0 : cut, s1 = part == 0 ? cut : a.steps;
    auto ep = std::make_shared<TokenEpisode>();
    ep->tokens.assign(a.ids.begin() + s0 * n, a.ids.begin() + s1 * n);
    Info info;
    info.meta = side.meta;
    info.meta.id = part == 0 ? stem : stem + ".held-out";  // sorts after the stem: ids_ stays sorted
    info.steps = s1 - s0;
    info.actions.assign(static_cast<size_t>(info.steps) * 2, kNaN);
    ids_.push_back(info.meta.id);
    info_.push_back(std::move(info));
    preloaded_.push_back(std::move(ep));
  }
}

void TokenDataset::open_files(const std::vector<fs::path>& files, const TokenFormat& stated) {
  // Every file is read once here (frame counts, one grid, K); later reads go through the episode cache.
  int64_t top = -1;
  double kept_rate = 0;  // --keep-rate: the one rate every file must share
  for (const auto& file : files) {
    const TokenSidecar side = read_token_sidecar(file);
    const TokenFormat f = file_format(stated, side, file);
    if (f.keep_rate) {
      if (f.rate_hz <= 0)
        fail("{}: --keep-rate needs each file's own frame rate: --token-fps, or 'fps' in its sidecar", file.string());
      if (kept_rate > 0 && std::abs(kept_rate - f.rate_hz) > 0.01 * kept_rate)
        fail("{}: {} fps, but {} has {} fps; --keep-rate trains at one rate, so the files must share it",
             file.string(), f.rate_hz, files_.at(0).string(), kept_rate);
      kept_rate = f.rate_hz;
    }
    TokenArray a = read_token_file(file, f);
    if (files_.empty()) {
      h_ = a.h;
      w_ = a.w;
    } else if (a.h != h_ || a.w != w_) {
      fail("{}: a {}x{} token grid, but {} has {}x{}", file.string(), a.h, a.w, files_[0].string(), h_, w_);
    }
    top = std::max<int64_t>(top, *std::max_element(a.ids.begin(), a.ids.end()));
    Info info;
    info.meta = side.meta;
    if (!ids_.empty() && ids_.back() == info.meta.id)
      fail("{}: two token files named '{}' (.npy and .safetensors?); keep one", path_.string(), info.meta.id);
    info.steps = a.steps;
    info.actions.assign(static_cast<size_t>(info.steps) * 2, kNaN);
    ids_.push_back(info.meta.id);
    info_.push_back(std::move(info));
    files_.push_back(file);
    file_rate_.push_back(f.rate_hz);
  }
  K_ = stated.codebook_size > 0 ? stated.codebook_size : top + 1;
  TokenFormat rate = stated;
  if (kept_rate > 0) rate.rate_hz = kept_rate;
  rate_hz_ = rate.dataset_rate_hz();
}

fs::path TokenDataset::episode_dir(size_t e) const {
  if (bare()) return path_;
  if (!files_.empty()) return files_.at(e);
  return path_ / "episodes" / ids_.at(e);
}

void TokenDataset::check_tokens(const std::vector<int32_t>& t, const fs::path& file) const {
  for (size_t i = 0; i < t.size(); ++i)
    if (t[i] < 0 || t[i] >= K_) {
      const int64_t n = h_ * w_, s = static_cast<int64_t>(i) / n;
      fail("{}: token {} at step {}, position {} is outside [0, {}) (codebook_size K = {})", file.string(), t[i], s,
           static_cast<int64_t>(i) - s * n, K_, K_);
    }
}

std::shared_ptr<const TokenEpisode> TokenDataset::load(size_t e) const {
  if (!files_.empty()) {
    auto ep = std::make_shared<TokenEpisode>();
    TokenFormat f = format_;
    f.codebook_size = K_;
    f.rate_hz = file_rate_.at(e);
    TokenArray a = read_token_file(files_.at(e), f);
    if (a.steps != steps(e) || a.h != h_ || a.w != w_) fail("{}: changed while in use", files_[e].string());
    ep->tokens = std::move(a.ids);
    return ep;
  }
  fs::path dir = episode_dir(e), tf = dir / "tokens.npy";
  const int64_t T = steps(e);
  NpyArray a = npy_read(tf);
  if (a.shape != std::vector<int64_t>{T, h_, w_})
    fail("{}: shape {}, want [{}, {}, {}] (steps from episode.json, grid from dataset.json)", tf.string(),
         shape_str(a.shape), T, h_, w_);
  auto ep = std::make_shared<TokenEpisode>();
  ep->tokens = token_ids(a, tf);
  check_tokens(ep->tokens, tf);
  fs::path cf = dir / "captions.jsonl";
  if (fs::exists(cf)) {
    ep->captions = read_jsonl_strings(cf);
    if (static_cast<int64_t>(ep->captions.size()) != T)
      fail("{}: has {} captions, episode.json says {} steps", cf.string(), ep->captions.size(), T);
  }
  if (has_text_emb()) ep->text_emb = read_text_embeddings(text_emb_file(dir), T, text_emb_);
  return ep;
}

std::shared_ptr<const TokenEpisode> TokenDataset::episode(size_t e) const {
  if (e >= size()) fail("{}: episode {} out of range [0, {})", path_.string(), e, size());
  if (bare()) return preloaded_.at(e);
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto it = cache_.begin(); it != cache_.end(); ++it)
      if (it->first == e) {
        cache_.splice(cache_.begin(), cache_, it);
        return cache_.front().second;
      }
  }
  auto ep = load(e);  // outside the lock: reading a file should not stall other threads' cache hits
  std::lock_guard<std::mutex> lock(mu_);
  for (auto& [k, v] : cache_)
    if (k == e) return v;  // another thread loaded it meanwhile: keep one copy
  cache_.emplace_front(e, ep);
  while (cache_.size() > cache_capacity_) cache_.pop_back();
  return ep;
}

void TokenDataset::check_all() const {
  if (bare()) return;  // checked at open
  for (size_t e = 0; e < size(); ++e) load(e);
}

data::Split TokenDataset::split(double val_fraction, uint64_t seed) const {
  if (bare()) return data::Split{{ids_[0]}, {}, {ids_.begin() + 1, ids_.end()}};
  return data::load_or_default_split(path_, ids_, val_fraction, seed);
}

std::vector<size_t> TokenDataset::indices(const std::vector<std::string>& ids) const {
  std::vector<size_t> out;
  for (auto& id : ids) {
    auto it = std::lower_bound(ids_.begin(), ids_.end(), id);  // ids_ is sorted
    if (it == ids_.end() || *it != id)
      fail("{}: split names episode '{}' which is not in the token dataset (an interrupted gaia tokenize? run it "
           "again to finish)", (path_ / "split.json").string(), id);
    out.push_back(static_cast<size_t>(it - ids_.begin()));
  }
  return out;
}

std::vector<Window> TokenDataset::windows(const std::vector<size_t>& episodes, int64_t T, int64_t stride) const {
  if (T < 1) fail("window length must be >= 1 step, got {}", T);
  if (stride < 1) fail("window stride must be >= 1 step, got {}", stride);
  std::vector<Window> out;
  for (size_t e : episodes)
    for (int64_t s = 0; s + T <= steps(e); s += stride) out.push_back(Window{e, s, T});
  return out;
}

data::FeatureRow TokenDataset::features(const Window& w) const {
  const auto& a = actions(w.episode);
  std::vector<float> v, k;
  for (int64_t t = w.start; t < w.start + w.steps; ++t) {
    v.push_back(a[static_cast<size_t>(2 * t)]);
    k.push_back(a[static_cast<size_t>(2 * t + 1)]);
  }
  return data::example_features(meta(w.episode), v, k);
}

WorldBatch TokenDataset::make_batch(const std::vector<Window>& windows, const TextSource& source, int64_t m,
                                    const ConditioningMix& mix, std::mt19937_64& rng) const {
  if (windows.empty()) fail("{}: a batch needs at least one window", path_.string());
  const int64_t B = static_cast<int64_t>(windows.size()), T = windows[0].steps, n = tokens_per_step();
  const text::Vocab* vocab = source.embeddings ? nullptr : source.vocab;
  const bool text = vocab && has_captions_;
  if (text && m < 1) fail("text tokens per step (world.text_tokens) must be >= 1, got {}", m);
  if (source.embeddings && !has_text_emb())
    fail("{}: has no text embeddings (text_emb.npy per episode; gaia text embed makes them)", path_.string());
  if (source.embeddings && m != text_emb_.m)
    fail("{}: text embeddings have m = {} tokens a step, but {} were asked for (world.text_tokens)", path_.string(),
         text_emb_.m, m);
  const int64_t row = source.embeddings ? text_emb_.m * text_emb_.dim : 0;
  auto tokens = torch::empty({B, T, n}, torch::kInt64);
  auto act = torch::empty({B, T, 2}, torch::kFloat32);
  auto text_ids = text ? torch::zeros({B, T, m}, torch::kInt64) : torch::Tensor();
  auto text_emb = source.embeddings ? torch::empty({B, T, text_emb_.m, text_emb_.dim}) : torch::Tensor();
  auto use_action = torch::empty({B}, torch::kBool), use_text = torch::empty({B}, torch::kBool);
  auto procedural = torch::empty({B}, torch::kBool);
  int64_t* tp = tokens.data_ptr<int64_t>();
  float* ap = act.data_ptr<float>();
  auto ua = use_action.accessor<bool, 1>(), ut = use_text.accessor<bool, 1>();
  for (int64_t b = 0; b < B; ++b) {
    const Window& w = windows[static_cast<size_t>(b)];
    if (w.steps != T) fail("{}: windows of one batch must have the same length ({} and {})", path_.string(), T, w.steps);
    if (w.episode >= size() || w.start < 0 || w.start + w.steps > steps(w.episode))
      fail("{}: window [{}, {}) is outside episode {} ({} steps)", path_.string(), w.start, w.start + w.steps,
           w.episode, w.episode < size() ? steps(w.episode) : 0);
    auto ep = episode(w.episode);
    std::copy_n(ep->tokens.begin() + w.start * n, T * n, tp + b * T * n);
    const auto& a = actions(w.episode);
    for (int64_t t = 0; t < T; ++t) {
      // NaN stays NaN (NaN / scale): the model swaps missing actions for its null action token.
      ap[(b * T + t) * 2 + 0] = static_cast<float>(a[static_cast<size_t>(2 * (w.start + t))] / kSpeedScale);
      ap[(b * T + t) * 2 + 1] = static_cast<float>(a[static_cast<size_t>(2 * (w.start + t) + 1)] / kCurvatureScale);
    }
    if (text && !ep->captions.empty())
      for (int64_t t = 0; t < T; ++t) {
        auto ids = vocab->encode(ep->captions[static_cast<size_t>(w.start + t)], m);
        std::copy(ids.begin(), ids.end(), text_ids.data_ptr<int64_t>() + (b * T + t) * m);
      }
    if (source.embeddings)
      for (int64_t t = 0; t < T; ++t)
        std::copy_n(ep->text_emb.step(w.start + t), row, text_emb.data_ptr<float>() + (b * T + t) * row);
    Conditioning c = mix.draw(rng, meta(w.episode).is_replay());
    ua[b] = c == Conditioning::kAction;
    ut[b] = c == Conditioning::kText;
    // A change of conditions (synth --change-at) is new to a teacher of the procedural world: not held to it.
    procedural[b] = meta(w.episode).is_procedural() && !meta(w.episode).extra.count("synth_change_at");
  }
  WorldBatch out;
  out.tokens = tokens;
  out.actions = act;
  out.text_ids = text_ids;
  out.text_emb = text_emb;
  out.use_action = use_action;
  out.use_text = use_text;
  out.procedural = procedural;
  return out;
}

WindowSampler::WindowSampler(const TokenDataset& ds, std::vector<Window> windows, std::vector<std::string> features,
                             double exponent, int bins)
    : windows_(std::move(windows)), balancer_(std::move(features), exponent, bins) {
  if (windows_.empty())
    fail("{}: no windows to sample (are all episodes shorter than the context of T steps?)", ds.path().string());
  rows_.reserve(windows_.size());
  for (auto& w : windows_) rows_.push_back(ds.features(w));
  balancer_.fit(rows_);
}

std::vector<Window> WindowSampler::sample(int64_t count, std::mt19937_64& rng) const {
  std::uniform_int_distribution<size_t> pick(0, windows_.size() - 1);
  std::vector<Window> out;
  out.reserve(static_cast<size_t>(std::max<int64_t>(count, 0)));
  while (static_cast<int64_t>(out.size()) < count) {
    size_t i = pick(rng);
    // Rejection (paper §3): the window with the highest weight is always kept, so this terminates.
    if (!balanced() || balancer_.keep(rows_[i], rng)) out.push_back(windows_[i]);
  }
  return out;
}

text::Vocab build_vocab(const TokenDataset& ds, const std::vector<size_t>& episodes, int64_t max_size) {
  std::map<std::string, int64_t> counts;
  for (size_t e : episodes)
    for (auto& c : ds.episode(e)->captions) text::Vocab::count(c, counts);
  return text::Vocab::from_counts(counts, max_size);
}

WorldBatch training_batch(const TokenDataset& ds, const WindowSampler& sampler, const TextSource& text,
                          const WorldConfig& cfg, uint64_t seed, int step) {
  std::mt19937_64 rng(train::step_seed(seed, step, kBatchStream));
  auto windows = sampler.sample(cfg.batch_size, rng);
  return ds.make_batch(windows, text, cfg.text_tokens, ConditioningMix::from(cfg), rng);
}

size_t TokenDataset::find(const std::string& id) const {
  auto it = std::find(ids_.begin(), ids_.end(), id);
  if (it != ids_.end()) return size_t(it - ids_.begin());
  if (!id.empty() && id.size() < 10 && id.find_first_not_of("0123456789") == std::string::npos && std::stoul(id) < ids_.size())
    return std::stoul(id);
  fail("'{}' is not an episode id or index of {} ({} episodes)", id, path_.string(), ids_.size());
}

}  // namespace gaia::world
