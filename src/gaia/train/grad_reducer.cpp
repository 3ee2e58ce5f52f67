#include "gaia/train/grad_reducer.h"

#include <functional>
#include <unordered_map>
#include <unordered_set>

#include <torch/csrc/autograd/functions/accumulate_grad.h>

#include "gaia/core/error.h"

namespace gaia::train {

namespace {

// The leaf tensors a backward pass from `loss` reaches (DDP's find_unused_parameters): their gradient
// accumulators in the autograd graph.
std::unordered_set<const void*> reached_leaves(const torch::Tensor& loss) {
  std::unordered_set<const void*> leaves;
  std::unordered_set<const torch::autograd::Node*> seen;
  std::vector<torch::autograd::Node*> todo;
  if (auto f = loss.grad_fn()) todo.push_back(f.get());
  while (!todo.empty()) {
    auto* node = todo.back();
    todo.pop_back();
    if (!seen.insert(node).second) continue;
    if (auto* acc = dynamic_cast<torch::autograd::AccumulateGrad*>(node)) leaves.insert(acc->variable.unsafeGetTensorImpl());
    for (const auto& e : node->next_edges())
      if (e.function) todo.push_back(e.function.get());
  }
  return leaves;
}

}  // namespace

struct GradientReducer::State {
  struct Bucket {
    std::vector<size_t> params;  // indices into `params`, in the order they fill `flat`
    torch::Tensor flat;          // float32 on the job's communication device (another owner's: only while it is sent)
    int64_t elems = 0;
    int owner = -1;              // the rank its sum goes to; -1: every rank
    size_t ready = 0;            // parameters whose gradient is in `flat`
  };
  std::vector<torch::Tensor> params;
  std::vector<size_t> bucket_of, offset;
  std::vector<char> filled;
  std::vector<Bucket> buckets;
  std::vector<std::function<void()>> pending;  // waits for the started all-reduces, in the order they started
  size_t next = 0;                             // the first bucket not started
  size_t sent_in_pass = 0;                     // buckets the last armed pass started from its hooks
  bool armed = false;
  Distributed* dist = nullptr;

  bool mine(const Bucket& b) const { return b.owner < 0 || b.owner == dist->rank(); }
  void fill(size_t i, const torch::Tensor& g) {
    const auto& p = params[i];
    auto& b = buckets[bucket_of[i]];
    if (!b.flat.defined())
      b.flat = torch::empty({b.elems}, torch::TensorOptions().dtype(torch::kFloat).device(dist->comm_device()));
    b.flat.narrow(0, int64_t(offset[i]), p.numel()).copy_(g.reshape({-1}));
    filled[i] = 1;
    ++b.ready;
  }
  // Starts every full bucket from `next` on, in order: the same order on every rank.
  void start_ready() {
    while (next < buckets.size() && buckets[next].ready == buckets[next].params.size()) {
      auto& b = buckets[next];
      pending.push_back(b.owner < 0 ? dist->start_sum(b.flat, "averaging gradients")
                                    : dist->start_sum_to(b.flat, b.owner, "averaging gradients"));
      ++next;
    }
  }
  // Fills the buckets not yet started with the gradients as they stand (zeros where none) and starts them.
  void send_rest() {
    for (size_t b = next; b < buckets.size(); ++b)
      for (size_t i : buckets[b].params)
        if (!filled[i]) fill(i, params[i].grad().defined() ? params[i].grad() : torch::zeros_like(params[i]));
    start_ready();
  }
  void reset() {
    std::fill(filled.begin(), filled.end(), 0);
    for (auto& b : buckets) b.ready = 0;
    pending.clear();
    next = 0;
  }
};

GradientReducer::GradientReducer(const std::vector<torch::Tensor>& params, Distributed& dist, bool overlap,
                                 double bucket_mb, double first_bucket_mb, const std::vector<int>& owner)
    : state_(std::make_shared<State>()) {
  if (!owner.empty() && owner.size() != params.size())
    fail("gradient sharding: {} owners for {} parameters", owner.size(), params.size());
  auto& s = *state_;
  s.dist = &dist;
  s.params = params;
  if (dist.size() == 1) return;  // a job of one: nothing to average
  const size_t n = params.size();
  s.bucket_of.resize(n);
  s.offset.resize(n);
  s.filled.assign(n, 0);
  // Reverse order: the backward pass makes the last layers' gradients first.
  int64_t limit = std::max<int64_t>(1, int64_t(first_bucket_mb * 1024 * 1024 / 4)), size = 0;
  s.buckets.emplace_back();
  auto owner_of = [&](size_t k) { return owner.empty() ? -1 : owner[k]; };
  if (n > 0) s.buckets.back().owner = owner_of(n - 1);
  for (size_t k = n; k-- > 0;) {
    const bool full = size > 0 && size + params[k].numel() > limit;
    if (full || (size > 0 && owner_of(k) != s.buckets.back().owner)) {  // a bucket holds one owner's parameters
      s.buckets.emplace_back();
      s.buckets.back().owner = owner_of(k);
      size = 0;
      if (full) limit = std::max<int64_t>(1, int64_t(bucket_mb * 1024 * 1024 / 4));
    }
    s.bucket_of[k] = s.buckets.size() - 1;
    s.offset[k] = size_t(size);
    s.buckets.back().params.push_back(k);
    size += params[k].numel();
  }
  for (auto& b : s.buckets) {
    for (size_t k : b.params) b.elems += params[k].numel();
    if (s.mine(b)) b.flat = torch::zeros({b.elems}, torch::TensorOptions().dtype(torch::kFloat).device(dist.comm_device()));
  }
  if (!overlap) return;
  for (size_t i = 0; i < n; ++i) {
    if (!params[i].requires_grad()) fail("gradient averaging: parameter {} does not require a gradient", i);
    hooks_.push_back(params[i].register_hook([w = std::weak_ptr<State>(state_), i](const torch::Tensor& grad) {
      auto s = w.lock();
      if (!s || !s->armed || !grad.defined() || s->filled[i]) return;
      torch::NoGradGuard no_grad;
      const auto& acc = s->params[i].grad();  // the earlier micro-batches' sum: this pass adds to it after the hook
      s->fill(i, acc.defined() ? acc + grad : grad);
      const size_t before = s->next;
      s->start_ready();
      s->sent_in_pass += s->next - before;
    }));
  }
}

GradientReducer::~GradientReducer() {
  for (size_t i = 0; i < hooks_.size(); ++i) state_->params[i].remove_hook(hooks_[i]);
}

void GradientReducer::backward(const torch::Tensor& loss, bool last) {
  auto& s = *state_;
  s.armed = last && !hooks_.empty();
  if (s.armed) {
    s.reset();
    s.sent_in_pass = 0;
    // Parameters this pass will not reach are ready now, so that they hold no bucket back.
    torch::NoGradGuard no_grad;
    const auto reached = reached_leaves(loss);
    for (size_t i = 0; i < s.params.size(); ++i)
      if (!reached.count(s.params[i].unsafeGetTensorImpl()))
        s.fill(i, s.params[i].grad().defined() ? s.params[i].grad() : torch::zeros_like(s.params[i]));
    s.start_ready();
  }
  try {
    loss.backward();
  } catch (...) {
    s.armed = false;
    throw;
  }
  s.armed = false;
  if (!last || hooks_.empty()) return;
  // Parameters this pass did not reach are sent now, so that every bucket has started when backward() returns:
  // a collective the trainer calls next (a loss summed over the ranks) then follows them on every rank alike.
  torch::NoGradGuard no_grad;
  s.send_rest();
}

size_t GradientReducer::buckets() const { return state_->buckets.size(); }
size_t GradientReducer::sent_during_backward() const { return state_->sent_in_pass; }

void GradientReducer::finish() {
  auto& s = *state_;
  if (s.buckets.empty()) return;
  torch::NoGradGuard no_grad;
  s.send_rest();
  // Which parameters have a gradient on some rank: sent last, after every bucket, on every rank alike.
  const size_t n = s.params.size();
  auto used = torch::zeros({int64_t(n)});
  for (size_t i = 0; i < n; ++i)
    if (s.params[i].grad().defined()) used[int64_t(i)] = 1;
  used = used.to(s.dist->comm_device());
  s.pending.push_back(s.dist->start_sum(used, "averaging gradients"));
  for (auto& wait : s.pending) wait();
  const auto used_cpu = used.to(torch::kCPU);
  const auto u = used_cpu.accessor<float, 1>();
  const double inv = 1.0 / double(s.dist->size());
  for (size_t i = 0; i < n; ++i) {
    auto p = s.params[i];
    if (!s.mine(s.buckets[s.bucket_of[i]])) {  // another rank's to update: its gradient is not kept here
      p.mutable_grad() = torch::Tensor();
      continue;
    }
    if (u[int64_t(i)] == 0) continue;
    auto g = s.buckets[s.bucket_of[i]].flat.narrow(0, int64_t(s.offset[i]), p.numel()).view(p.sizes());
    g = g.mul(inv).to(p.device(), p.scalar_type());
    if (p.grad().defined()) p.mutable_grad().copy_(g);
    else p.mutable_grad() = g;
  }
  for (auto& b : s.buckets)
    if (!s.mine(b)) b.flat = torch::Tensor();
  s.reset();
}

}  // namespace gaia::train
