#pragma once
// Gradient averaging over the ranks of a data-parallel job, in buckets, overlapped with the backward pass in the
// manner of PyTorch's DistributedDataParallel (Li et al. 2020): the parameters are taken in reverse (the backward
// pass reaches the last layers first) and cut into buckets (the first small, so that communication starts early);
// during the step's last backward pass every parameter's gradient is copied into its bucket as autograd produces it,
// and a bucket's all-reduce starts as soon as it is full and every bucket before it has started. Buckets start in
// the same order on every rank, so the collectives match whatever order the gradients arrive in.
#include <memory>
#include <vector>

#include <torch/torch.h>

#include "gaia/train/distributed.h"

namespace gaia::train {

class GradientReducer {
 public:
  // `params`: in the same order on every rank; `dist` outlives this object. `overlap` false: everything is sent
  // after the backward passes (the same sums, later). `owner` (one rank per parameter; empty: none): ZeRO-2, each
  // bucket holds one owner's parameters and is summed to that rank alone (c10d reduce), and after finish() a rank
  // keeps the gradients of its own parameters only, the others' freed with their buckets.
  GradientReducer(const std::vector<torch::Tensor>& params, Distributed& dist, bool overlap = true,
                  double bucket_mb = 25, double first_bucket_mb = 1, const std::vector<int>& owner = {});
  ~GradientReducer();
  GradientReducer(const GradientReducer&) = delete;
  GradientReducer& operator=(const GradientReducer&) = delete;

  // loss.backward(); on the step's last micro-batch (`last`) the gradients leave for the other ranks as they are
  // made, and every bucket has started when it returns. Earlier micro-batches only accumulate, as DDP's no_sync.
  void backward(const torch::Tensor& loss, bool last);
  // Every parameter's gradient replaced by its mean over the ranks: sends what backward() has not sent yet, waits
  // for all of it. A parameter without a gradient on any rank keeps none (as in one process); one with a gradient on
  // some rank counts as zero where it has none. With owners, only the owner's parameters keep a gradient.
  void finish();

  size_t buckets() const;
  // Buckets the last step's backward pass started while it ran (the overlap; the rest started when it ended).
  size_t sent_during_backward() const;

 private:
  struct State;
  std::shared_ptr<State> state_;  // the hooks hold it weakly: a hook outliving the reducer does nothing
  std::vector<unsigned> hooks_;
};

}  // namespace gaia::train
