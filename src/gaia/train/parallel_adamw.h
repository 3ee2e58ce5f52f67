#pragma once
// AdamW for data-parallel training: the gradients of each step's last backward pass are averaged over the ranks
// while it runs, then clipped by their global norm; then either every rank updates every parameter (replicated state), or, sharded in
// the ZeRO-1 manner (Rajbhandari et al. 2020, as DeepSpeed ZeRO in the paper's §4), each rank keeps AdamW's two
// moments for its own share of the parameters only, updates that share and sends it to the others. Sharding
// divides the optimiser state (8 bytes per parameter in float32) by the world size. ZeRO-2 (`shard_gradients`) also
// sums each gradient to its owner alone (reduce instead of all-reduce, bucket by bucket during the backward pass)
// and keeps only those: the averaged gradients held between the backward pass and the update are divided too.
//
// A checkpoint holds the state as one AdamW over every parameter, whatever the world size, so a run resumes on
// another number of ranks.
#include <memory>
#include <vector>

#include <torch/torch.h>

#include "gaia/train/distributed.h"
#include "gaia/train/grad_reducer.h"

namespace gaia::train {

struct AdamWSettings {
  double lr = 1e-4, weight_decay = 0.01, beta1 = 0.9, beta2 = 0.999;
};

class ParallelAdamW {
 public:
  // `params`: the trained parameters, in the same order on every rank. `par`'s job outlives this object.
  ParallelAdamW(const std::vector<torch::Tensor>& params, const AdamWSettings& s, const Parallel& par);

  void set_lr(double lr);
  void zero_grad();
  // loss.backward() for micro-batch k of the step's `accumulate`: the last one's gradients are averaged over the
  // ranks while the pass runs (train/grad_reducer.h).
  void backward(const torch::Tensor& loss, int k, int accumulate);
  // Averages the gradients over the ranks, divides them by `loss_scale` (fp16's, torch/precision.h), clips their
  // global norm to `max_norm` (0: no clipping; < 0: neither clipped nor measured, 0 returned), updates the
  // parameters. Returns the norm before clipping; not finite: an overflow, and nothing is updated (every rank sees
  // the same averaged gradients, so every rank skips).
  double step(double max_norm, double loss_scale = 1);

  // The state as one AdamW over every parameter (what save_checkpoint writes). Collective when sharded: every rank
  // calls it, rank 0 receives the whole state (in CPU memory); call release() after saving.
  torch::optim::Optimizer& gathered();
  void release();
  // The optimiser to load a checkpoint into; then loaded() hands each rank its share.
  torch::optim::Optimizer& to_load() { return *full_; }
  void loaded();

 private:
  std::vector<torch::Tensor> params_;
  std::vector<int> owner_;                      // the rank that updates each parameter (sharded)
  std::unique_ptr<torch::optim::AdamW> full_;  // every parameter: stepped when replicated; the checkpoint's view
  std::unique_ptr<torch::optim::AdamW> own_;   // this rank's share, when sharded
  Distributed& dist_;
  std::unique_ptr<GradientReducer> reducer_;   // in a job of more than one
  bool shard_gradients_ = false;               // ZeRO-2: each rank holds its own parameters' averaged gradients
};

}  // namespace gaia::train
