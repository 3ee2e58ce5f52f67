#pragma once
// Random frames for tokenizer training, balanced over per-episode features (paper §3: latitude, longitude,
// weather for the tokenizer). Episodes are opened once (memory maps) and frames decoded on demand.
#include <memory>
#include <random>
#include <utility>
#include <vector>

#include "gaia/data/balance.h"
#include "gaia/data/episode.h"

namespace gaia::data {

class FrameSampler {
 public:
  // `episodes`: indices into ds; frames must be height x width (else an error naming the episode).
  FrameSampler(const Dataset& ds, std::vector<size_t> episodes, int height, int width,
               const std::vector<std::string>& balance, double exponent, int bins);
  // n (episode position, frame) pairs drawn uniformly over frames and kept by the balancer.
  std::vector<std::pair<size_t, int64_t>> sample(size_t n, std::mt19937_64& rng) const;
  cv::Mat frame(size_t episode_pos, int64_t i) const { return episodes_[episode_pos]->frame_bgr(i); }
  const Episode& episode(size_t pos) const { return *episodes_[pos]; }
  size_t num_episodes() const { return episodes_.size(); }
  int64_t num_frames() const { return total_; }

 private:
  std::vector<std::unique_ptr<Episode>> episodes_;
  std::vector<int64_t> cum_;  // cumulative frame counts
  std::vector<double> keep_;  // keep probability per episode
  int64_t total_ = 0;
};

}  // namespace gaia::data
