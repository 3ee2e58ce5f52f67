// Data-parallel runs of the training commands: --nproc starts the ranks of a job on this machine; inside a job
// (WORLD_SIZE set, by --nproc, torchrun or SLURM) each process joins it (train/distributed.h).
#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <thread>

#include <sys/wait.h>
#include <unistd.h>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/distributed.h"

namespace gaia::app {

namespace {

std::string describe(int status) {
  if (WIFSIGNALED(status)) return fmt::format("was killed by signal {}", WTERMSIG(status));
  return fmt::format("exited with status {}", WEXITSTATUS(status));
}

}  // namespace

std::vector<std::string> g_args;

void add_parallel_flags(CLI::App* cmd, ParallelFlags* f) {
  const std::string g = "Data-parallel training";
  cmd->add_option("--nproc", f->nproc,
                  "start this many ranks on this machine (data-parallel; torchrun / SLURM start ranks with RANK, "
                  "WORLD_SIZE, MASTER_ADDR, MASTER_PORT instead)")
      ->check(number_in({1, 1024}))->group(g);
  cmd->add_option("--accumulate", f->accumulate,
                  "split each step's batch into this many micro-batches per rank (gradient accumulation: the same "
                  "global batch on fewer ranks or less memory)")
      ->check(number_in({1, 1 << 16}))->group(g);
  cmd->add_flag("--shard-optimizer", f->shard_optimizer,
                "keep AdamW's state sharded over the ranks (ZeRO-1): 1/N of it on each")->group(g);
  cmd->add_flag("--shard-gradients", f->shard_gradients,
                "also keep each averaged gradient on the one rank that updates it (ZeRO-2; implies "
                "--shard-optimizer)")->group(g);
  cmd->add_flag("--no-overlap", f->no_overlap,
                "average the gradients after the backward pass instead of during it (the same numbers, later)")
      ->group(g);
  cmd->add_option("--dist-timeout", f->timeout_s,
                  "seconds a rank waits for the others (joining, every collective) before failing")
      ->check(number_in({1, 86400}))->group(g);
}

train::Parallel parallel_of(const ParallelFlags& f, train::Distributed* dist) {
  train::Parallel p;
  p.dist = dist;
  p.accumulate = f.accumulate;
  p.shard_optimizer = f.shard_optimizer || f.shard_gradients;
  p.shard_gradients = f.shard_gradients;
  p.overlap = !f.no_overlap;
  return p;
}

bool launch_local_ranks(const ParallelFlags& f) {
  if (f.nproc <= 1 || std::getenv("WORLD_SIZE")) return false;
  // The same command without --nproc, once per rank.
  std::vector<std::string> args;
  for (size_t i = 1; i < g_args.size(); ++i) {
    if (g_args[i] == "--nproc") {
      ++i;
      continue;
    }
    if (g_args[i].rfind("--nproc=", 0) == 0) continue;
    args.push_back(g_args[i]);
  }
  std::error_code ec;
  const std::string exe = fs::read_symlink("/proc/self/exe", ec).string();
  if (ec) fail("--nproc: cannot find the gaia binary ({})", ec.message());
  const int port = train::RankEnv::free_local_port();
  std::fflush(stdout);
  std::fflush(stderr);
  std::vector<pid_t> pids;
  for (int r = 0; r < f.nproc; ++r) {
    const pid_t pid = fork();
    if (pid < 0) fail("--nproc: fork failed for rank {}", r);
    if (pid == 0) {
      ::setenv("RANK", std::to_string(r).c_str(), 1);
      ::setenv("LOCAL_RANK", std::to_string(r).c_str(), 1);
      ::setenv("WORLD_SIZE", std::to_string(f.nproc).c_str(), 1);
      ::setenv("LOCAL_WORLD_SIZE", std::to_string(f.nproc).c_str(), 1);
      ::setenv("MASTER_ADDR", "127.0.0.1", 1);
      ::setenv("MASTER_PORT", std::to_string(port).c_str(), 1);
      std::vector<char*> argv{const_cast<char*>(exe.c_str())};
      for (auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(exe.c_str(), argv.data());
      _exit(127);
    }
    pids.push_back(pid);
  }
  // Wait for all. The first rank to fail stops the others (a rank waiting on a dead one would wait its timeout),
  // after a moment in which the ranks that fail with it are counted as causes too: a killed rank's peers fail at
  // once, and which of them is reaped first is chance.
  std::vector<int> status(pids.size(), -1);
  std::vector<bool> cause(pids.size(), false);
  size_t running = pids.size();
  using Clock = std::chrono::steady_clock;
  auto grace = Clock::time_point::max(), deadline = Clock::time_point::max();
  bool failing = false, stopped = false;
  while (running > 0) {
    int st = 0;
    const pid_t pid = waitpid(-1, &st, failing ? WNOHANG : 0);
    if (pid > 0) {
      const auto it = std::find(pids.begin(), pids.end(), pid);
      if (it == pids.end()) continue;
      const size_t r = size_t(it - pids.begin());
      status[r] = st;
      --running;
      if (!stopped && !(WIFEXITED(st) && WEXITSTATUS(st) == 0)) {
        cause[r] = true;
        if (!failing) grace = Clock::now() + std::chrono::milliseconds(300);
        failing = true;
      }
      continue;
    }
    if (pid < 0 && !failing) break;
    if (!stopped && Clock::now() > grace) {
      stopped = true;
      for (size_t r = 0; r < pids.size(); ++r)
        if (status[r] == -1) ::kill(pids[r], SIGTERM);
      deadline = Clock::now() + std::chrono::seconds(10);
    }
    if (Clock::now() > deadline)
      for (size_t r = 0; r < pids.size(); ++r)
        if (status[r] == -1) ::kill(pids[r], SIGKILL);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  if (!failing) return true;
  std::string failed;
  for (int killed : {1, 0})  // ranks killed by a signal first: the others failed waiting for them
    for (size_t r = 0; r < pids.size(); ++r)
      if (cause[r] && WIFSIGNALED(status[r]) == bool(killed))
        failed += fmt::format("{}rank {} {}", failed.empty() ? "" : ", ", r, describe(status[r]));
  fail("--nproc {}: {}; the job was stopped, and its last checkpoint is intact: the same command resumes", f.nproc,
       failed);
}

std::unique_ptr<train::Distributed> join_job(const ParallelFlags& f, Config& c) {
  const auto env = train::RankEnv::from_environment();
  if (env.world_size > 1) {
    // Ranks sharing this machine share its cores.
    int local = 1;
    if (const char* l = std::getenv("LOCAL_WORLD_SIZE"); l && std::atoi(l) > 0) local = std::atoi(l);
    if (c.run.threads == 0 && local > 1)
      c.run.threads = std::max(1, int(std::thread::hardware_concurrency()) / local);
    c.run.device = train::Distributed::rank_device(parse_device(c.run.device), env).str();
  }
  apply_threads(c);
  return std::make_unique<train::Distributed>(
      env, parse_device(c.run.device), std::chrono::milliseconds(int64_t(f.timeout_s * 1000)));
}

}  // namespace gaia::app
