#include "gaia/train/distributed.h"

#include <cstdlib>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

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

int RankEnv::free_local_port() {
  const int s = ::socket(AF_INET, SOCK_STREAM, 0);
  if (s < 0) fail("cannot open a socket to find a free port");
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  socklen_t len = sizeof a;
  const bool ok = ::bind(s, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
                  ::getsockname(s, reinterpret_cast<sockaddr*>(&a), &len) == 0;
  ::close(s);
  if (!ok) fail("cannot find a free port on 127.0.0.1");
  return ntohs(a.sin_port);
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

void Distributed::all_reduce(torch::Tensor& flat, const std::string& what) { start_sum(flat, what)(); }

void Distributed::barrier() {
  if (!impl_) return;
  auto t = torch::zeros({1}, torch::TensorOptions().device(impl_->comm_device));
  all_reduce(t, "a barrier");  // an all-reduce, so that a dead rank fails it within the timeout like any other
}

std::function<void()> Distributed::start_sum(torch::Tensor& flat, const std::string& what) { return start(flat, -1, what); }

std::function<void()> Distributed::start_sum_to(torch::Tensor& flat, int root, const std::string& what) {
  return start(flat, root, what);
}

std::function<void()> Distributed::start(torch::Tensor& flat, int root, const std::string& what) {
  if (!impl_) return [] {};
  std::vector<torch::Tensor> v{flat};
  c10d::ReduceOptions o;
  o.rootRank = std::max(0, root);
  c10::intrusive_ptr<c10d::Work> work;
  try {
#ifdef GAIA_WITH_NCCL
    if (impl_->nccl) work = root < 0 ? impl_->nccl->allreduce(v) : impl_->nccl->reduce(v, o);
    else
#endif
      work = root < 0 ? impl_->gloo->allreduce(v) : impl_->gloo->reduce(v, o);
  } catch (const std::exception& e) {
    lost_contact(env_.rank, what, e.what());
  }
  return [work, what, rank = env_.rank] {
    try {
      work->wait();
    } catch (const std::exception& e) {
      lost_contact(rank, what, e.what());
    }
  };
}

torch::Device Distributed::comm_device() const { return impl_ ? impl_->comm_device : torch::Device(torch::kCPU); }

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
