#include "gaia/train/distributed.h"

#include <cstdlib>

// LibTorch's CMake package does not pass its c10d backends on: Gloo is in every LibTorch build, NCCL in those with
// CUDA (GAIA_WITH_NCCL, set by CMakeLists.txt).
#ifndef USE_C10D_GLOO
#define USE_C10D_GLOO
#endif
#if defined(GAIA_WITH_NCCL) && !defined(USE_C10D_NCCL)
#define USE_C10D_NCCL
#endif
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>
#ifdef GAIA_WITH_NCCL
#include <torch/csrc/distributed/c10d/ProcessGroupNCCL.hpp>
#endif

#include "gaia/core/error.h"

namespace gaia::train {

namespace {

int env_int(const char* name, int fallback, int lo, int hi) {
  const char* v = std::getenv(name);
  if (!v || !*v) return fallback;
  char* end = nullptr;
  const long x = std::strtol(v, &end, 10);
  if (*end || x < lo || x > hi) fail("environment variable {}={}: expected a whole number in [{}, {}]", name, v, lo, hi);
  return int(x);
}

// The one line a failed collective becomes: c10d's own message is a backtrace.
[[noreturn]] void lost_contact(int rank, const std::string& what, const std::string& why) {
  std::string first = why.substr(0, why.find('\n'));
  fail("rank {}: {} failed, the other ranks are gone or stuck ({}); the last checkpoint is intact: run the same "
       "command again to resume", rank, what, first);
}

}  // namespace

int64_t Parallel::micro_batch(int64_t batch, const std::string& key) const {
  const int64_t ranks = dist ? dist->size() : 1, parts = ranks * accumulate;
  if (accumulate < 1) fail("--accumulate must be at least 1, got {}", accumulate);
  if (batch % parts != 0)
    fail("{} = {} does not split into {} rank(s) x --accumulate {} equal micro-batches", key, batch, ranks, accumulate);
  return batch / parts;
}

int64_t Parallel::micro_offset(int64_t batch, int k) const {
  const int rank = dist ? dist->rank() : 0;
  return (int64_t(rank) * accumulate + k) * micro_batch(batch, "batch");
}

uint64_t Parallel::micro_stream(int k) const { return uint64_t((dist ? dist->rank() : 0) * accumulate + k); }

Distributed& Parallel::job() const {
  static Distributed one;  // no process group: stateless, shared
  return dist ? *dist : one;
}

RankEnv RankEnv::from_environment() {
  RankEnv e;
  e.world_size = env_int("WORLD_SIZE", 1, 1, 1 << 20);
  if (e.world_size == 1) return e;
  if (!std::getenv("RANK")) fail("environment variable WORLD_SIZE={} is set but RANK is not", e.world_size);
  e.rank = env_int("RANK", 0, 0, e.world_size - 1);
  e.local_rank = env_int("LOCAL_RANK", 0, 0, 1 << 16);
  if (const char* a = std::getenv("MASTER_ADDR"); a && *a) e.master_addr = a;
  e.master_port = env_int("MASTER_PORT", e.master_port, 1, 65535);
  return e;
}

struct Distributed::Impl {
  c10::intrusive_ptr<c10d::TCPStore> store;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> gloo;
#ifdef GAIA_WITH_NCCL
  c10::intrusive_ptr<c10d::ProcessGroupNCCL> nccl;
#endif
  torch::Device comm_device = torch::kCPU;  // where the flat buffers of a collective live
};

torch::Device Distributed::rank_device(const torch::Device& requested, const RankEnv& env) {
  if (requested.is_cuda() && !requested.has_index()) return torch::Device(torch::kCUDA, int8_t(env.local_rank));
  return requested;
}

Distributed::Distributed(const RankEnv& env, const torch::Device& device, std::chrono::milliseconds timeout)
    : env_(env) {
  if (env.world_size == 1) return;
  impl_ = std::make_shared<Impl>();
  try {
    c10d::TCPStoreOptions so;
    so.port = uint16_t(env.master_port);
    so.isServer = env.rank == 0;
    so.numWorkers = size_t(env.world_size);
    so.waitWorkers = true;
    so.timeout = timeout;
    impl_->store = c10::make_intrusive<c10d::TCPStore>(env.master_addr, so);
  } catch (const std::exception& e) {
    fail("rank {}: cannot join the job at {}:{} (MASTER_ADDR, MASTER_PORT): {}", env.rank, env.master_addr,
         env.master_port, std::string(e.what()).substr(0, std::string(e.what()).find('\n')));
  }
#ifdef GAIA_WITH_NCCL
  if (device.is_cuda()) {
    auto o = c10d::ProcessGroupNCCL::Options::create();
    o->timeout = timeout;
    impl_->nccl = c10::make_intrusive<c10d::ProcessGroupNCCL>(impl_->store, env.rank, env.world_size, o);
    impl_->comm_device = device;
    return;
  }
#else
  (void)device;  // CUDA tensors travel through the CPU: this LibTorch has no NCCL
#endif
  try {
    auto o = c10d::ProcessGroupGloo::Options::create(timeout);
    // As torch.distributed: GLOO_SOCKET_IFNAME names the network interfaces, else the host name's address.
    if (const char* ifs = std::getenv("GLOO_SOCKET_IFNAME"); ifs && *ifs) {
      std::string s = ifs;
      for (size_t a = 0; a <= s.size();) {
        size_t b = s.find(',', a);
        if (b == std::string::npos) b = s.size();
        if (b > a) o->devices.push_back(c10d::ProcessGroupGloo::createDeviceForInterface(s.substr(a, b - a)));
        a = b + 1;
      }
    } else if (env.master_addr == "127.0.0.1" || env.master_addr == "localhost") {
      o->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname("127.0.0.1"));
    } else {
      o->devices.push_back(c10d::ProcessGroupGloo::createDefaultDevice());
    }
    impl_->gloo = c10::make_intrusive<c10d::ProcessGroupGloo>(impl_->store, env.rank, env.world_size, o);
  } catch (const std::exception& e) {
    lost_contact(env.rank, "joining the process group", e.what());
  }
}

void Distributed::all_reduce(torch::Tensor& flat, const std::string& what) {
  std::vector<torch::Tensor> v{flat};
  try {
#ifdef GAIA_WITH_NCCL
    if (impl_->nccl) {
      impl_->nccl->allreduce(v)->wait();
      return;
    }
#endif
    impl_->gloo->allreduce(v)->wait();
  } catch (const std::exception& e) {
    lost_contact(env_.rank, what, e.what());
  }
}

void Distributed::barrier() {
  if (!impl_) return;
  auto t = torch::zeros({1}, torch::TensorOptions().device(impl_->comm_device));
  all_reduce(t, "a barrier");  // an all-reduce, so that a dead rank fails it within the timeout like any other
}

void Distributed::average_gradients(const std::vector<torch::Tensor>& params, double bucket_mb) {
  if (!impl_) return;
  torch::NoGradGuard no_grad;
  const int64_t bucket_elems = std::max<int64_t>(1, int64_t(bucket_mb * 1024 * 1024 / 4));
  struct Bucket {
    std::vector<size_t> params;
    torch::Tensor flat;
  };
  std::vector<Bucket> buckets(1);
  int64_t filled = 0;
  for (size_t i = 0; i < params.size(); ++i) {
    if (filled > 0 && filled + params[i].numel() > bucket_elems) {
      buckets.emplace_back();
      filled = 0;
    }
    buckets.back().params.push_back(i);
    filled += params[i].numel();
  }
  // Which parameters have a gradient on some rank: one unused by every rank keeps none, as in one process.
  auto has_grad = torch::zeros({int64_t(params.size())});
  for (size_t i = 0; i < params.size(); ++i)
    if (params[i].grad().defined()) has_grad[int64_t(i)] = 1;
  has_grad = has_grad.to(impl_->comm_device);
  std::vector<c10::intrusive_ptr<c10d::Work>> works;
  auto start = [&](torch::Tensor& flat) {
    std::vector<torch::Tensor> v{flat};
#ifdef GAIA_WITH_NCCL
    if (impl_->nccl) {
      works.push_back(impl_->nccl->allreduce(v));
      return;
    }
#endif
    works.push_back(impl_->gloo->allreduce(v));
  };
  try {
    start(has_grad);
    for (auto& bucket : buckets) {
      std::vector<torch::Tensor> parts;
      for (size_t i : bucket.params) {
        const auto& p = params[i];
        parts.push_back((p.grad().defined() ? p.grad() : torch::zeros_like(p)).reshape({-1}).to(torch::kFloat));
      }
      if (parts.empty()) continue;
      bucket.flat = torch::cat(parts).to(impl_->comm_device);
      start(bucket.flat);
    }
    for (auto& w : works) w->wait();
  } catch (const std::exception& e) {
    lost_contact(env_.rank, "averaging gradients", e.what());
  }
  const auto used_t = has_grad.to(torch::kCPU);
  const auto used = used_t.accessor<float, 1>();
  const double inv = 1.0 / double(env_.world_size);
  for (auto& bucket : buckets) {
    if (!bucket.flat.defined()) continue;
    int64_t off = 0;
    for (size_t i : bucket.params) {
      auto p = params[i];
      if (used[int64_t(i)] > 0) {
        auto g = bucket.flat.narrow(0, off, p.numel()).view(p.sizes()).mul(inv).to(p.device(), p.scalar_type());
        if (p.grad().defined()) p.mutable_grad().copy_(g);
        else p.mutable_grad() = g.clone();
      }
      off += p.numel();
    }
  }
}

void Distributed::broadcast(const std::vector<torch::Tensor>& tensors, int root) {
  if (!impl_ || tensors.empty()) return;
  torch::NoGradGuard no_grad;
  std::vector<torch::Tensor> parts;
  for (const auto& t : tensors) parts.push_back(t.reshape({-1}).to(torch::kFloat));
  std::vector<torch::Tensor> v{torch::cat(parts).to(impl_->comm_device)};
  c10d::BroadcastOptions o;
  o.rootRank = root;
  try {
#ifdef GAIA_WITH_NCCL
    if (impl_->nccl) impl_->nccl->broadcast(v, o)->wait();
    else
#endif
      impl_->gloo->broadcast(v, o)->wait();
  } catch (const std::exception& e) {
    lost_contact(env_.rank, "a broadcast", e.what());
  }
  if (env_.rank == root) return;
  int64_t off = 0;
  for (const auto& t : tensors) {
    auto src = v[0].narrow(0, off, t.numel()).view(t.sizes()).to(t.device(), t.scalar_type());
    const_cast<torch::Tensor&>(t).copy_(src);
    off += t.numel();
  }
}

double Distributed::sum(double x) {
  if (!impl_) return x;
  auto t = torch::tensor({x}, torch::TensorOptions().dtype(torch::kDouble)).to(impl_->comm_device);
  all_reduce(t, "a sum");
  return t.to(torch::kCPU).to(torch::kDouble).item<double>();
}

void Distributed::sum(torch::Tensor& t) {
  if (!impl_) return;
  auto flat = t.detach().reshape({-1}).to(impl_->comm_device, torch::kFloat).contiguous();
  all_reduce(flat, "a sum");
  torch::NoGradGuard no_grad;
  t.copy_(flat.view(t.sizes()).to(t.device(), t.scalar_type()));
}

void Distributed::average(torch::Tensor& t) {
  if (!impl_) return;
  sum(t);
  torch::NoGradGuard no_grad;
  t.div_(double(env_.world_size));
}

}  // namespace gaia::train
