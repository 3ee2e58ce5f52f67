#pragma once
// The world model's training data (§2.1, §2.3, §4.2): token episodes from `gaia tokenize` (docs/formats.md,
// "Token dataset"), cut into windows of T consecutive steps, drawn with the §3 balancing, and turned into
// WorldBatch examples that are unconditional, action- or text-conditioned in the §4.2 ratios (20/40/40).
//
//   TokenDataset   TOKENS/ (dataset.json, episodes/<id>/{tokens.npy, actions.npy, captions.jsonl, episode.json},
//                  text embeddings where given: text_embeddings.h);
//                  or token files of another tokenizer (token_file.h), without actions or text, with metadata
//                  from a sidecar X.json where given: one file = one drive split in time (the last val_fraction
//                  held out), a directory of them = one episode a file, held out by file (or by its split.json,
//                  which `gaia data split --geofence` writes from the sidecars' positions)
//   Window         steps [start, start + steps) of one episode; never crosses episodes
//   WindowSampler  uniform or balanced (data::Balancer over weather, time of day, location, steering, speed)
//   make_batch     windows -> tokens [B,T,n], actions [B,T,2] (normalised), text_ids [B,T,m] or text_emb
//                  [B,T,m,dim], use_action/use_text
//
// Memory: every episode's metadata and actions (8 bytes a step) are read at open, because balancing needs the
// features of every window. Tokens and captions are read when an episode is first used, checked (shape, ids in
// [0, K)), and the most recently used `cache_episodes` are kept: the default config's 144 int16 tokens a step make
// a few thousand 200-step episodes ~170 MB, but the paper's 576 would be ~0.7 GB, so nothing assumes they all fit.
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <vector>

#include "gaia/config.h"
#include "gaia/core/fs.h"
#include "gaia/data/balance.h"
#include "gaia/data/episode.h"
#include "gaia/data/geofence.h"
#include "gaia/text/vocab.h"
#include "gaia/world/batch.h"
#include "gaia/world/text_embeddings.h"
#include "gaia/world/token_file.h"

namespace gaia::world {

// Steps [start, start + steps) of episode `episode` (an index into TokenDataset::ids()).
struct Window {
  size_t episode = 0;
  int64_t start = 0, steps = 0;
  int64_t scored_from = 0;  // scoring counts steps from this one on; those before are context (stream_windows)
  bool operator==(const Window& o) const {
    return episode == o.episode && start == o.start && steps == o.steps && scored_from == o.scored_from;
  }
};

// Paper §4.2: each training example is one of these, so one network gives the conditioned and the unconditioned
// logits that classifier-free guidance mixes (§5.1).
enum class Conditioning { kUnconditional, kAction, kText };

struct ConditioningMix {
  double p_uncond = 0.2, p_action = 0.4, p_text = 0.4;  // paper §4.2: 20% / 40% / 40%
  double p_action_replay = -1;  // action share on counterfactual replays (world.p_action_replay); -1 = as above
  static ConditioningMix from(const WorldConfig& c) { return {c.p_uncond, c.p_action, c.p_text, c.p_action_replay}; }
  // One uniform draw; fails unless the p's are >= 0 with sum > 0. For a window of a replay (`replay`) with
  // p_action_replay >= 0: action with that probability, else unconditional or text in the ratio p_uncond : p_text.
  Conditioning draw(std::mt19937_64& rng, bool replay = false) const;
};

// What is loaded on demand for one episode.
struct TokenEpisode {
  std::vector<int32_t> tokens;        // [steps, h, w] row-major, every id in [0, K)
  std::vector<std::string> captions;  // [steps] ("" = none), or empty when the dataset has no captions
  TextEmbeddings text_emb;            // precomputed embeddings of the captions, or empty (m = 0)
};

// How a batch carries text (§2.1): word ids of the built-in vocabulary, or the dataset's precomputed embeddings
// (the world model's text_dim wide), or none. A vocabulary pointer converts: nullptr = no text.
struct TextSource {
  const text::Vocab* vocab = nullptr;
  bool embeddings = false;
  TextSource(const text::Vocab* v = nullptr) : vocab(v) {}  // NOLINT: implicit, words or nothing
  static TextSource precomputed() {
    TextSource s;
    s.embeddings = true;
    return s;
  }
  bool any() const { return vocab || embeddings; }
};

class TokenDataset {
 public:
  // `format.codebook_size` > 0 states K: it must equal dataset.json's for a gaia token dataset, and sets K for
  // other tokenizers' files (whose K is otherwise their largest token + 1). The rest of `format` applies to other
  // tokenizers' files only. Errors name the file at fault.
  explicit TokenDataset(const fs::path& path, const TokenFormat& format, size_t cache_episodes = 256);
  explicit TokenDataset(const fs::path& path, int64_t codebook_size = 0, size_t cache_episodes = 256);

  const fs::path& path() const { return path_; }
  bool bare() const { return !preloaded_.empty(); }  // one file: the drive and its held-out end, both in memory
  bool foreign() const { return !files_.empty() || bare(); }  // another tokenizer's: no actions, text or metadata
  int64_t grid_h() const { return h_; }
  int64_t grid_w() const { return w_; }
  int64_t tokens_per_step() const { return h_ * w_; }  // n
  int64_t codebook_size() const { return K_; }          // K
  double rate_hz() const { return rate_hz_; }           // dataset.json "rate_hz" (6.25, §2.3); 0 when unknown
  bool has_captions() const { return has_captions_; }
  // Precomputed text embeddings of every episode (text_embeddings.h): who made them, m and dim; undefined = none.
  const TextEmbInfo& text_emb() const { return text_emb_; }
  bool has_text_emb() const { return text_emb_.defined(); }

  size_t size() const { return ids_.size(); }  // episodes
  const std::vector<std::string>& ids() const { return ids_; }
  // The episode named `id`, or at index `id` when no episode has that name; an error names both otherwise.
  size_t find(const std::string& id) const;
  const data::EpisodeMeta& meta(size_t e) const { return info_.at(e).meta; }
  int64_t steps(size_t e) const { return info_.at(e).steps; }
  const std::vector<float>& actions(size_t e) const { return info_.at(e).actions; }  // [steps * 2] m/s, 1/m; NaN
  fs::path episode_dir(size_t e) const;

  // Tokens and captions of an episode, read and checked on first use (then cached). Thread-safe.
  std::shared_ptr<const TokenEpisode> episode(size_t e) const;
  void check_all() const;  // reads and checks every episode (streaming), e.g. before a long training run

  // TOKENS/split.json when present (`gaia tokenize` copies the source dataset's, so geofenced validation carries
  // over), otherwise the seeded random hold-out of data::load_or_default_split. One file: its end, in time.
  data::Split split(double val_fraction = 0.1, uint64_t seed = 0) const;
  std::vector<size_t> indices(const std::vector<std::string>& ids) const;  // fails naming split.json on unknown ids

  // Every window of `T` steps whose starts are `stride` steps apart, episode by episode (short episodes give none).
  std::vector<Window> windows(const std::vector<size_t>& episodes, int64_t T, int64_t stride) const;
  // Balancing features of a window (data::example_features): episode metadata + the window's speeds / curvatures.
  data::FeatureRow features(const Window& w) const;

  // The batch of these windows (all of the same length T): tokens [B,T,n] int64, actions [B,T,2] float32 divided
  // by kSpeedScale / kCurvatureScale (NaN kept), text as `text` says: text_ids [B,T,m] via its vocabulary
  // (undefined without captions), or text_emb [B,T,m,dim] (the dataset's embeddings; m must be theirs); and one
  // conditioning mode per example drawn from `mix` with `rng` (use_action / use_text; windows of counterfactual
  // replays draw with ConditioningMix::p_action_replay).
  WorldBatch make_batch(const std::vector<Window>& windows, const TextSource& text, int64_t m,
                        const ConditioningMix& mix, std::mt19937_64& rng) const;

 private:
  struct Info {
    data::EpisodeMeta meta;
    int64_t steps = 0;
    std::vector<float> actions;
  };
  std::shared_ptr<const TokenEpisode> load(size_t e) const;
  void check_tokens(const std::vector<int32_t>& t, const fs::path& file) const;

  void open_file(const TokenFormat& f);
  void open_files(const std::vector<fs::path>& files, const TokenFormat& f);

  fs::path path_;
  TokenFormat format_;
  std::vector<fs::path> files_;  // a directory of other tokenizers' files: episode e is files_[e]
  std::vector<double> file_rate_;  // ... and its frame rate (--token-fps, or its sidecar's fps)
  int64_t h_ = 0, w_ = 0, K_ = 0;
  double rate_hz_ = 0;
  bool has_captions_ = false;
  TextEmbInfo text_emb_;
  std::vector<std::string> ids_;
  std::vector<Info> info_;
  std::vector<std::shared_ptr<const TokenEpisode>> preloaded_;  // one file: its training part and held-out end

  // Least-recently-used cache of loaded episodes (front = most recent).
  size_t cache_capacity_;
  mutable std::mutex mu_;
  mutable std::list<std::pair<size_t, std::shared_ptr<const TokenEpisode>>> cache_;
};

// Draws windows uniformly, or balanced over `features` (paper §3; world model: cfg.data.balance_world) by
// rejection: a uniformly drawn window is kept with the Balancer's probability.
class WindowSampler {
 public:
  WindowSampler(const TokenDataset& ds, std::vector<Window> windows, std::vector<std::string> features = {},
                double exponent = 0.5, int bins = 10);
  std::vector<Window> sample(int64_t count, std::mt19937_64& rng) const;
  const std::vector<Window>& windows() const { return windows_; }
  const std::vector<data::FeatureRow>& rows() const { return rows_; }  // features of windows()[i]
  const data::Balancer& balancer() const { return balancer_; }
  bool balanced() const { return !balancer_.features().empty(); }

 private:
  std::vector<Window> windows_;
  std::vector<data::FeatureRow> rows_;
  data::Balancer balancer_;
};

// The vocabulary of these episodes' captions (at most max_size ids; world.text_vocab).
text::Vocab build_vocab(const TokenDataset& ds, const std::vector<size_t>& episodes, int64_t max_size);

// Random stream of the world-model batches in train::step_seed(seed, step, stream).
inline constexpr uint64_t kBatchStream = 0;

// Training batch number `step`: cfg.world.batch_size windows from the sampler, then make_batch with the config's
// m and conditioning mix, all drawn from std::mt19937_64(train::step_seed(seed, step, kBatchStream)), so a
// resumed run sees exactly the batches of an uninterrupted one.
WorldBatch training_batch(const TokenDataset& ds, const WindowSampler& sampler, const TextSource& text,
                          const WorldConfig& cfg, uint64_t seed, int step);

}  // namespace gaia::world
