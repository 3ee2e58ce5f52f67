#include "gaia/train/parallel_adamw.h"

#include <cmath>
#include <sstream>
#include <type_traits>

#include "gaia/train/optim.h"

namespace gaia::train {

namespace {

using StateMap = std::decay_t<decltype(std::declval<torch::optim::Optimizer&>().state())>;

// The key LibTorch's optimisers file a parameter's state under: its TensorImpl's address, printed (or, where a
// LibTorch keys by the pointer itself, the pointer).
template <typename Key = StateMap::key_type>
Key state_key(const torch::Tensor& p) {
  if constexpr (std::is_same_v<Key, std::string>) {
    std::ostringstream s;
    s << p.unsafeGetTensorImpl();
    return s.str();
  } else {
    return p.unsafeGetTensorImpl();
  }
}

// Contiguous shares of the parameter list with about equal element counts, one per rank.
std::vector<int> partition(const std::vector<torch::Tensor>& params, int ranks) {
  int64_t total = 0;
  for (const auto& p : params) total += p.numel();
  std::vector<int> owner(params.size());
  int64_t seen = 0;
  for (size_t i = 0; i < params.size(); ++i) {
    // The share a parameter's middle falls in.
    const double mid = double(seen) + double(params[i].numel()) / 2;
    owner[i] = std::min(ranks - 1, int(mid * ranks / double(std::max<int64_t>(1, total))));
    seen += params[i].numel();
  }
  return owner;
}

double global_norm(const std::vector<torch::Tensor>& params) {
  double sq = 0;
  for (const auto& p : params)
    if (p.grad().defined()) sq += p.grad().pow(2).sum().item<double>();
  return std::sqrt(sq);
}

}  // namespace

ParallelAdamW::ParallelAdamW(const std::vector<torch::Tensor>& params, const AdamWSettings& s, const Parallel& par)
    : dist_(par.job()) {
  Distributed& dist = dist_;
  for (const auto& p : params)
    if (p.requires_grad()) params_.push_back(p);
  full_ = make_adamw(params_, s.lr, s.weight_decay, s.beta1, s.beta2);
  const bool shard = par.shard_optimizer || par.shard_gradients;
  if (shard) owner_ = partition(params_, dist.size());
  shard_gradients_ = par.shard_gradients && dist.size() > 1;
  if (dist.size() > 1)
    reducer_ = std::make_unique<GradientReducer>(params_, dist, par.overlap, 25, 1,
                                                 shard_gradients_ ? owner_ : std::vector<int>{});
  if (!shard) return;
  std::vector<torch::Tensor> mine;
  for (size_t i = 0; i < params_.size(); ++i)
    if (owner_[i] == dist.rank()) mine.push_back(params_[i]);
  own_ = make_adamw(mine, s.lr, s.weight_decay, s.beta1, s.beta2);
}

void ParallelAdamW::set_lr(double lr) {
  train::set_lr(*full_, lr);
  if (own_) train::set_lr(*own_, lr);
}

void ParallelAdamW::zero_grad() { full_->zero_grad(); }

void ParallelAdamW::backward(const torch::Tensor& loss, int k, int accumulate) {
  if (reducer_) reducer_->backward(loss, k + 1 == accumulate);
  else loss.backward();
}

double ParallelAdamW::step(double max_norm, double loss_scale) {
  if (reducer_) reducer_->finish();
  if (loss_scale != 1) {
    torch::NoGradGuard no_grad;
    for (auto& p : params_)
      if (p.grad().defined()) p.mutable_grad().div_(loss_scale);
  }
  // fp16 measures the norm even unclipped: an overflow must be seen.
  double norm = 0;
  if (shard_gradients_) {
    // Each rank holds its own parameters' gradients: the norm of all of them is summed over the ranks, and each
    // rank clips its own as torch::nn::utils::clip_grad_norm_ would clip them all.
    if (max_norm >= 0 || loss_scale != 1) {
      double sq = 0;
      for (const auto& p : params_)
        if (p.grad().defined()) sq += p.grad().to(torch::kDouble).pow(2).sum().item<double>();
      norm = std::sqrt(dist_.sum(sq));
    }
    if (max_norm > 0 && std::isfinite(norm)) {
      torch::NoGradGuard no_grad;
      const double coef = std::min(1.0, max_norm / (norm + 1e-6));
      for (auto& p : params_)
        if (p.grad().defined()) p.mutable_grad().mul_(coef);
    }
  } else if (max_norm > 0) {
    norm = clip_grad_norm(params_, max_norm);
  } else if (max_norm == 0 || loss_scale != 1) {
    norm = global_norm(params_);
  }
  if (!std::isfinite(norm)) return norm;
  if (!own_) {
    full_->step();
    return norm;
  }
  own_->step();
  // Each share from the rank that updated it.
  for (int r = 0; r < dist_.size(); ++r) {
    std::vector<torch::Tensor> share;
    for (size_t i = 0; i < params_.size(); ++i)
      if (owner_[i] == r) share.push_back(params_[i]);
    dist_.broadcast(share, r);
  }
  return norm;
}

torch::optim::Optimizer& ParallelAdamW::gathered() {
  if (!own_) return *full_;
  // Parameter by parameter from its owner: (step, exp_avg, exp_avg_sq); a parameter never stepped has step 0.
  auto& mine = own_->state();
  auto& all = full_->state();
  for (size_t i = 0; i < params_.size(); ++i) {
    const auto& p = params_[i];
    const auto key = state_key(p);
    auto opts = torch::TensorOptions().dtype(torch::kFloat).device(p.device());
    torch::Tensor step = torch::zeros({1}, opts), m = torch::zeros_like(p, opts), v = torch::zeros_like(p, opts);
    if (owner_[i] == dist_.rank()) {
      auto it = mine.find(key);
      if (it != mine.end()) {
        auto& st = static_cast<torch::optim::AdamWParamState&>(*it->second);
        step.fill_(double(st.step()));
        m.copy_(st.exp_avg());
        v.copy_(st.exp_avg_sq());
      }
    }
    dist_.broadcast({step, m, v}, owner_[i]);
    const auto n = int64_t(std::llround(step.item<double>()));
    if (!dist_.is_main() || n == 0) continue;
    // Held in CPU memory until saved: the whole state would not fit beside the model on one device.
    auto st = std::make_unique<torch::optim::AdamWParamState>();
    st->step(n);
    st->exp_avg(m.to(torch::kCPU, p.scalar_type()));
    st->exp_avg_sq(v.to(torch::kCPU, p.scalar_type()));
    all[key] = std::move(st);
  }
  return *full_;
}

void ParallelAdamW::release() {
  if (own_) full_->state().clear();
}

void ParallelAdamW::loaded() {
  if (!own_) return;
  auto& all = full_->state();
  auto& mine = own_->state();
  mine.clear();
  for (size_t i = 0; i < params_.size(); ++i) {
    if (owner_[i] != dist_.rank()) continue;
    auto it = all.find(state_key(params_[i]));
    if (it == all.end()) continue;
    auto& st = static_cast<torch::optim::AdamWParamState&>(*it->second);
    const auto dev = params_[i].device();
    st.exp_avg(st.exp_avg().to(dev));
    st.exp_avg_sq(st.exp_avg_sq().to(dev));
    mine[it->first] = std::move(it->second);
  }
  all.clear();
}

}  // namespace gaia::train
