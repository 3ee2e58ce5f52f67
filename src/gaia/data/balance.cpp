#include "gaia/data/balance.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "gaia/core/error.h"

namespace gaia::data {

namespace {
constexpr double kStraight = 0.002;  // |curvature| below 1/500 m counts as driving straight
const std::vector<std::string> kNumeric{"latitude", "longitude", "speed", "curvature"};
const std::vector<std::string> kCategorical{"weather", "time_of_day", "steering", "speed_category", "footage"};

bool is_numeric(const std::string& f) { return std::find(kNumeric.begin(), kNumeric.end(), f) != kNumeric.end(); }

double mean_present(const std::vector<float>& v) {
  double s = 0;
  int n = 0;
  for (float x : v)
    if (!std::isnan(x)) { s += x; ++n; }
  return n ? s / n : std::nan("");
}
}  // namespace

const std::vector<std::string>& known_features() {
  static const std::vector<std::string> all = [] {
    std::vector<std::string> a = kNumeric;
    a.insert(a.end(), kCategorical.begin(), kCategorical.end());
    return a;
  }();
  return all;
}

bool is_known_feature(const std::string& f) {
  const auto& k = known_features();
  return std::find(k.begin(), k.end(), f) != k.end();
}

FeatureRow clip_features(const Episode& ep, const std::vector<int64_t>& frames) {
  std::vector<float> v, k;
  for (auto i : frames) {
    v.push_back(ep.speeds()[static_cast<size_t>(i)]);
    k.push_back(ep.curvatures()[static_cast<size_t>(i)]);
  }
  return example_features(ep.meta(), v, k);
}

FeatureRow example_features(const EpisodeMeta& m, const std::vector<float>& speeds, const std::vector<float>& curvatures) {
  FeatureRow r;
  r.cat["weather"] = m.weather.empty() ? "missing" : m.weather;
  r.cat["time_of_day"] = m.time_of_day.empty() ? "missing" : m.time_of_day;
  r.cat["footage"] = m.is_procedural() ? "procedural" : "real";
  r.num["latitude"] = m.latitude;
  r.num["longitude"] = m.longitude;
  double v = mean_present(speeds), k = mean_present(curvatures);
  r.num["speed"] = v;
  r.num["curvature"] = k;
  r.cat["steering"] = std::isnan(k) ? "missing" : k > kStraight ? "left" : k < -kStraight ? "right" : "straight";
  r.cat["speed_category"] = std::isnan(v) ? "missing" : v < 0.5 ? "stopped" : v < 5 ? "slow" : v < 12 ? "medium" : "fast";
  return r;
}

Balancer::Balancer(std::vector<std::string> features, double exponent, int bins)
    : features_(std::move(features)), exponent_(exponent), bins_(bins) {
  for (auto& f : features_)
    if (!is_known_feature(f)) fail("unknown balancing feature '{}' (known: {})", f, fmt::join(known_features(), ", "));
  if (!(exponent >= 0 && exponent <= 1)) fail("balancing exponent must be in [0, 1], got {}", exponent);
  if (bins < 1) fail("balancing bins must be >= 1");
}

std::string Balancer::bin(const std::string& f, const FeatureRow& row) const {
  if (!is_numeric(f)) {
    auto it = row.cat.find(f);
    return it == row.cat.end() ? "missing" : it->second;
  }
  auto it = row.num.find(f);
  if (it == row.num.end() || std::isnan(it->second)) return "missing";
  auto rg = range_.find(f);
  if (rg == range_.end()) fail("Balancer: fit() before bin()");
  auto [lo, hi] = rg->second;
  int b = hi > lo ? static_cast<int>((it->second - lo) / (hi - lo) * bins_) : 0;
  b = std::clamp(b, 0, bins_ - 1);  // values outside the fitted range fall into the edge bins
  double w = hi > lo ? (hi - lo) / bins_ : 0;
  return fmt::format("{:02d}:[{:.4g}, {:.4g})", b, lo + b * w, lo + (b + 1) * w);
}

void Balancer::fit(const std::vector<FeatureRow>& rows) {
  if (rows.empty()) fail("balancing: no examples to fit");
  range_.clear();
  prob_.clear();
  for (auto& f : features_) {
    if (!is_numeric(f)) continue;
    double lo = INFINITY, hi = -INFINITY;
    for (auto& r : rows) {
      auto it = r.num.find(f);
      if (it != r.num.end() && !std::isnan(it->second)) { lo = std::min(lo, it->second); hi = std::max(hi, it->second); }
    }
    range_[f] = lo <= hi ? std::make_pair(lo, hi) : std::make_pair(0.0, 0.0);
  }
  for (auto& f : features_) {
    auto& p = prob_[f];
    for (auto& r : rows) p[bin(f, r)] += 1.0 / static_cast<double>(rows.size());
  }
  max_weight_ = 0;
  for (auto& r : rows) max_weight_ = std::max(max_weight_, weight(r));
}

double Balancer::weight(const FeatureRow& row) const {
  double w = 1;
  for (auto& f : features_) {
    auto pf = prob_.find(f);
    if (pf == prob_.end()) fail("Balancer: fit() before weight()");
    auto pb = pf->second.find(bin(f, row));
    // A bin never seen during fit gets the rarest seen probability (the highest weight) rather than infinity.
    double p = pb != pf->second.end() ? pb->second : 0;
    if (p <= 0) {
      p = 1;
      for (auto& kv : pf->second) p = std::min(p, kv.second);
    }
    w *= std::pow(p, -exponent_);
  }
  return w;
}

bool Balancer::keep(const FeatureRow& row, std::mt19937_64& rng) const {
  return std::uniform_real_distribution<double>(0, 1)(rng) < keep_probability(row);
}

Balancer::Histogram Balancer::histogram(const std::string& f, const std::vector<FeatureRow>& rows) const {
  std::map<std::string, double> emp, smp;
  double total_keep = 0;
  for (auto& r : rows) {
    std::string b = bin(f, r);
    double k = keep_probability(r);
    emp[b] += 1;
    smp[b] += k;
    total_keep += k;
  }
  Histogram h;
  for (auto& [b, c] : emp) {
    if (b == "missing") continue;
    h.bins.push_back(b);
    h.empirical.push_back(c / static_cast<double>(rows.size()));
    h.sampled.push_back(total_keep > 0 ? smp[b] / total_keep : 0);
  }
  if (emp.count("missing")) {
    h.bins.push_back("missing");
    h.empirical.push_back(emp["missing"] / static_cast<double>(rows.size()));
    h.sampled.push_back(total_keep > 0 ? smp["missing"] / total_keep : 0);
  }
  for (auto& b : h.bins)  // numeric bins carry an "NN:" ordering prefix; drop it for display
    if (b.size() > 3 && b[2] == ':') b = b.substr(3);
  return h;
}

double Balancer::acceptance_rate(const std::vector<FeatureRow>& rows) const {
  double s = 0;
  for (auto& r : rows) s += keep_probability(r);
  return rows.empty() ? 0 : s / static_cast<double>(rows.size());
}

}  // namespace gaia::data
