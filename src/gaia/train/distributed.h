#pragma once
// Data-parallel training on PyTorch's own distributed engine, c10d (§4: the paper trains on 64 GPUs): one process
// per rank. `--nproc N` starts N ranks on this machine; torchrun and SLURM start them with the usual variables
// (RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT), every rank running the same command. Gloo carries CPU
// tensors; NCCL carries CUDA tensors where LibTorch was built with it (else they travel through the CPU over Gloo).
#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

namespace gaia::train {

// The rank's place in the job, from the environment. WORLD_SIZE unset (or 1): a job of one, with no process group.
struct RankEnv {
  int rank = 0, world_size = 1, local_rank = 0;
  std::string master_addr = "127.0.0.1";
  int master_port = 29500;
  static RankEnv from_environment();  // a malformed or inconsistent variable fails naming it
  static int free_local_port();      // a TCP port free on 127.0.0.1 now: the rendezvous of ranks on this machine
};

class Distributed;

// How a trainer runs data-parallel: every rank builds the step's whole batch (a function of seed and step) and
// takes its own `accumulate` micro-batches of it, so the job trains on the same batches as one process would,
// whatever the world size, and resumes exactly on another.
struct Parallel {
  Distributed* dist = nullptr;  // this rank's job; nullptr = one process
  int accumulate = 1;           // micro-batches per rank and step
  bool shard_optimizer = false; // ZeRO-1 (train/parallel_adamw.h)
  bool shard_gradients = false; // ZeRO-2: also each averaged gradient on its owner only (implies shard_optimizer)
  bool overlap = true;          // gradients sent during the last backward pass (train/grad_reducer.h)
  // Examples per micro-batch for a batch of `batch` (named `key` in an error when it does not divide evenly).
  int64_t micro_batch(int64_t batch, const std::string& key) const;
  // The first example of this rank's micro-batch k.
  int64_t micro_offset(int64_t batch, int k) const;
  // The stream of per-step seeds for micro-batch k (0 for one process without accumulation).
  uint64_t micro_stream(int k) const;
  Distributed& job() const;  // `dist`, or a job of one
};

class Distributed {
 public:
  // A job of one: every collective below is a no-op.
  Distributed() = default;
  // Joins the job (blocks until every rank has joined; fails after `timeout`). Rank 0 serves the rendezvous store
  // at MASTER_ADDR:MASTER_PORT. A collective that waits longer than `timeout` (a rank died or hangs) fails with
  // one line instead of hanging.
  Distributed(const RankEnv& env, const torch::Device& device, std::chrono::milliseconds timeout);

  int rank() const { return env_.rank; }
  int size() const { return env_.world_size; }
  bool is_main() const { return env_.rank == 0; }  // writes checkpoints, metrics and the progress bar
  // The device this rank trains on: `requested`, with CUDA without an index taken as cuda:LOCAL_RANK.
  static torch::Device rank_device(const torch::Device& requested, const RankEnv& env);

  void barrier();
  // Starts summing the float tensor `flat` (on comm_device()) over the ranks, in place; the function returned waits
  // for it (a rank lost meanwhile fails with one line naming `what`). Gradients: train/grad_reducer.h.
  std::function<void()> start_sum(torch::Tensor& flat, const std::string& what);
  // The same sum delivered to rank `root` only (c10d's reduce): the other ranks' `flat` is left undefined in value.
  std::function<void()> start_sum_to(torch::Tensor& flat, int root, const std::string& what);
  torch::Device comm_device() const;  // where the tensors of a collective live
  // Rank `root`'s values of `tensors` copied into every rank's (one message).
  void broadcast(const std::vector<torch::Tensor>& tensors, int root);
  double sum(double v);  // over the ranks
  void average(torch::Tensor& t);  // in place: the mean over the ranks of a float tensor
  void sum(torch::Tensor& t);      // in place: the sum over the ranks of a float tensor

 private:
  struct Impl;
  std::shared_ptr<Impl> impl_;
  RankEnv env_;
  void all_reduce(torch::Tensor& flat, const std::string& what);
  std::function<void()> start(torch::Tensor& flat, int root, const std::string& what);  // root -1: every rank
};

}  // namespace gaia::train
