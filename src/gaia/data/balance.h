#pragma once
// Balanced sampling exactly as the paper's §3: for each chosen feature, a weight inversely proportional to its
// binned, precomputed empirical distribution, raised to an exponent (0 = empirical, 1 = uniform, 0.5 default);
// the joint weight over features decides stochastically whether an example is kept.
//
// With one feature of empirical bin probabilities p_b, the kept distribution is p_b^(1 - exponent) / Z.
#include <map>
#include <random>
#include <string>
#include <vector>

#include "gaia/data/clip_sampler.h"

namespace gaia::data {

// One example's feature values: categorical ("weather" -> "rain") or numeric ("speed" -> 8.3; NaN = missing).
struct FeatureRow {
  std::map<std::string, std::string> cat;
  std::map<std::string, double> num;
};

// Features a clip offers: weather, time_of_day (categorical); latitude, longitude, speed (mean m/s),
// curvature (mean 1/m) (numeric); steering (left/straight/right) and speed_category (stopped/slow/medium/fast)
// as behaviour categories; footage (real/procedural), so that a few real drives can weigh as much as many synthetic
// ones (`--set data.balance_tokenizer=[footage] --set data.balance_exponent=1`: half of each batch real).
FeatureRow clip_features(const Episode& ep, const std::vector<int64_t>& frames);
// The same features from an episode's metadata and the speeds / curvatures of the example's steps (NaN = missing):
// clips of frames and world-model windows of token steps share one definition of "left" or "fast".
FeatureRow example_features(const EpisodeMeta& meta, const std::vector<float>& speeds, const std::vector<float>& curvatures);
bool is_known_feature(const std::string& name);
const std::vector<std::string>& known_features();

class Balancer {
 public:
  Balancer(std::vector<std::string> features, double exponent, int bins);
  void fit(const std::vector<FeatureRow>& rows);  // bin edges + empirical histograms

  // Bin label of a row for a feature ("missing" when absent; numeric bins as "[lo, hi)").
  std::string bin(const std::string& feature, const FeatureRow& row) const;
  double weight(const FeatureRow& row) const;          // prod_f p_f(bin)^(-exponent)
  double keep_probability(const FeatureRow& row) const { return weight(row) / max_weight_; }
  bool keep(const FeatureRow& row, std::mt19937_64& rng) const;

  // Per feature: bins in order with empirical and expected-sampled probabilities.
  struct Histogram {
    std::vector<std::string> bins;
    std::vector<double> empirical, sampled;
  };
  Histogram histogram(const std::string& feature, const std::vector<FeatureRow>& rows) const;
  double acceptance_rate(const std::vector<FeatureRow>& rows) const;  // fraction of examples kept on average
  const std::vector<std::string>& features() const { return features_; }
  double exponent() const { return exponent_; }

 private:
  std::vector<std::string> features_;
  double exponent_;
  int bins_;
  std::map<std::string, std::pair<double, double>> range_;  // numeric features: [min, max]
  std::map<std::string, std::map<std::string, double>> prob_;  // feature -> bin -> empirical probability
  double max_weight_ = 1;
};

}  // namespace gaia::data
