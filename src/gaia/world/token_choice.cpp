#include "gaia/world/token_choice.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "gaia/core/error.h"

namespace gaia::world {

namespace {

// The k largest of v[0, K) by value, the lower index first among equals (exactly k, as keep_top_k), written to
// `ids` in ascending order: a heap of the k best so far, whose worst most values fail to beat.
void top_k_ids(const float* v, int64_t K, int64_t k, std::vector<int64_t>& ids) {
  ids.resize(static_cast<size_t>(k));
  auto worse = [v](int64_t a, int64_t b) { return v[a] > v[b] || (v[a] == v[b] && a < b); };  // heap: worst on top
  for (int64_t j = 0; j < k; ++j) ids[size_t(j)] = j;
  std::make_heap(ids.begin(), ids.end(), worse);
  for (int64_t j = k; j < K; ++j)
    if (v[j] > v[ids.front()]) {  // a later index never wins a tie
      std::pop_heap(ids.begin(), ids.end(), worse);
      ids.back() = j;
      std::push_heap(ids.begin(), ids.end(), worse);
    }
  std::sort(ids.begin(), ids.end());
}

int64_t first_max(const float* v, int64_t K) {  // as argmax: the first of equal maxima
  int64_t best = 0;
  for (int64_t j = 1; j < K; ++j)
    if (v[j] > v[best]) best = j;
  return best;
}

}  // namespace

bool TokenChoice::applies(const SamplingOptions& o) {
  return o.strategy == Strategy::Argmax || (o.strategy == Strategy::TopK && o.top_k >= 1 && o.temperature > 0);
}

void TokenChoice::operator()(const float* logits, int64_t N, int64_t K, const int64_t* prev, const float* bias,
                             double s, torch::Generator& gen, int64_t* out) const {
  if (!applies(sampling)) fail("token choice: only argmax and top-k sampling run on raw memory");
  thread_local std::vector<float> cond, guide_row, weights;
  thread_local std::vector<int64_t> ids;
  cond.resize(size_t(K));
  const float a = float(1.0 + s), b = float(s);  // as guide(): (1 + s) c - s u, each scalar as float
  const int64_t k = std::min<int64_t>(sampling.top_k, K);
  const bool argmax = sampling.strategy == Strategy::Argmax;
  for (int64_t r = 0; r < N; ++r) {
    std::memcpy(cond.data(), logits + r * K, sizeof(float) * size_t(K));
    if (prev) cond[size_t(prev[r])] += bias[r];  // with_copy_bias
    const float* u = guided ? logits + (N + r) * K : nullptr;
    auto guided_at = [&](int64_t j) {  // eq. 2 at code j
      const float uj = prev && j == prev[N + r] ? u[j] + bias[N + r] : u[j];
      const float cj = a * cond[size_t(j)], sj = b * uj;
      return cj - sj;
    };
    if (guided && within && !argmax) {
      // The candidates are the conditional top k: the guided logits are needed at those k codes only.
      top_k_ids(cond.data(), K, k, ids);
      weights.resize(ids.size());
      for (size_t j = 0; j < ids.size(); ++j) weights[j] = guided_at(ids[j]);
    } else {
      const float* v = cond.data();  // what is ranked and drawn from
      if (guided) {
        guide_row.resize(size_t(K));
        for (int64_t j = 0; j < K; ++j) guide_row[size_t(j)] = guided_at(j);
        v = guide_row.data();
      }
      if (argmax) {
        out[r] = first_max(v, K);
        continue;
      }
      top_k_ids(v, K, k, ids);  // the k highest of the (guided) logits
      weights.resize(ids.size());
      for (size_t j = 0; j < ids.size(); ++j) weights[j] = v[ids[j]];
    }
    const float t = float(sampling.temperature);  // softmax of the candidates' logits / t, unnormalised
    float top = -std::numeric_limits<float>::infinity();
    for (float& w : weights) top = std::max(top, w / t);
    for (float& w : weights) w = std::exp(w / t - top);
    out[r] = draw_token(ids.data(), weights.data(), k, gen);
  }
}

}  // namespace gaia::world
