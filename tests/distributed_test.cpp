// Data-parallel training on c10d (train/distributed.h, train/parallel_adamw.h): two Gloo ranks on this machine train
// the same weights as one process with the same global batch, with and without sharded optimiser state and with
// gradient accumulation; a checkpoint of two ranks resumes on one; a killed rank ends the job with one line and
// leaves a checkpoint that resumes.
#include <cmath>
#include <thread>

#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "gaia/train/distributed.h"
#include "gaia/train/grad_reducer.h"
#include "gaia/world/batch.h"
#include "test_util.h"

using namespace gaia;
using test::q;

namespace {

// Random tokens of a 4x8 grid, K = 64, as another tokenizer's file: enough for windows of the tiny world model.
fs::path token_file(const fs::path& dir) {
  const fs::path f = dir / "tokens.npy";
  if (fs::exists(f)) return f;
  torch::manual_seed(3);
  auto t = torch::randint(0, 64, {160, 4, 8}, torch::kLong).contiguous();
  std::vector<int64_t> v(t.data_ptr<int64_t>(), t.data_ptr<int64_t>() + t.numel());
  npy_write(f, npy_make(DType::I64, {160, 4, 8}, v));
  return f;
}

std::string train_args(const fs::path& tokens, const fs::path& out) {
  return "world train " + q(tokens) + " --grid 4x8 --codebook-size 64 --config " +
         q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1 --val-every 0 --out " + q(out);
}

// The largest difference between two weight files' tensors (every name of `a` must be in `b`).
double max_difference(const fs::path& a, const fs::path& b) {
  SafetensorsFile fa(a), fb(b);
  double d = 0;
  for (const auto& name : fa.names()) {
    auto x = fa.to_float(name), y = fb.to_float(name);
    EXPECT_EQ(x.size(), y.size()) << name;
    for (size_t i = 0; i < std::min(x.size(), y.size()); ++i) d = std::max(d, double(std::abs(x[i] - y[i])));
  }
  return d;
}

}  // namespace

TEST(Distributed, MicroBatchesSplitTheStepsBatchAmongRanksAndAccumulation) {
  train::Parallel one;
  EXPECT_EQ(one.micro_batch(8, "world.batch_size"), 8);
  one.accumulate = 4;
  EXPECT_EQ(one.micro_batch(8, "world.batch_size"), 2);
  EXPECT_EQ(one.micro_offset(8, 3), 6);
  EXPECT_EQ(one.micro_stream(3), 3u);
  one.accumulate = 3;
  EXPECT_NE(test::error_of([&] { one.micro_batch(8, "world.batch_size"); }).find("world.batch_size = 8"),
            std::string::npos);

  world::WorldBatch b{torch::arange(6).view({6, 1, 1}), torch::zeros({6, 1, 2}), {}, {},
                      torch::tensor({true, false, true, false, true, false}), {}};
  auto part = b.examples(2, 4);
  EXPECT_EQ(part.batch(), 2);
  EXPECT_EQ(part.tokens.flatten()[0].item<int64_t>(), 2);
  EXPECT_TRUE(part.use_action[0].item<bool>());
  EXPECT_FALSE(part.text_ids.defined());
  EXPECT_FALSE(test::error_of([&] { b.examples(4, 7); }).empty());
}

TEST(Distributed, RankEnvironmentIsReadAndCheckedByName) {
  ::unsetenv("WORLD_SIZE");
  EXPECT_EQ(train::RankEnv::from_environment().world_size, 1);
  ::setenv("WORLD_SIZE", "2", 1);
  ::setenv("RANK", "5", 1);
  auto msg = test::error_of([] { train::RankEnv::from_environment(); });
  EXPECT_NE(msg.find("RANK=5"), std::string::npos) << msg;
  ::setenv("RANK", "1", 1);
  ::setenv("MASTER_PORT", "http", 1);
  msg = test::error_of([] { train::RankEnv::from_environment(); });
  EXPECT_NE(msg.find("MASTER_PORT"), std::string::npos) << msg;
  ::setenv("MASTER_PORT", "29611", 1);
  auto e = train::RankEnv::from_environment();
  EXPECT_EQ(e.rank, 1);
  EXPECT_EQ(e.master_port, 29611);
  EXPECT_EQ(train::Distributed::rank_device(torch::Device("cuda"), e).str(), "cuda:0");
  for (const char* v : {"WORLD_SIZE", "RANK", "MASTER_PORT"}) ::unsetenv(v);
}

// Two ranks as two threads of this process, each with its own process group: a three-layer net, two micro-batches
// per rank, a parameter only rank 1 uses and one nobody uses, buckets of a few hundred values so that several start
// while the last backward pass runs. Each rank ends with the mean of both ranks' gradients, which each thread also
// works out alone.
TEST(Distributed, GradientsAveragedDuringTheBackwardPassEqualThoseAveragedAfterIt) {
  auto make_params = [] {  // a generator of its own: the two ranks' threads draw at the same time
    auto gen = at::detail::createCPUGenerator(7);
    std::vector<torch::Tensor> p;
    for (auto shape : std::vector<std::vector<int64_t>>{{8, 16}, {16, 16}, {16, 4}, {5}, {3}})
      p.push_back(torch::randn(shape, gen));
    for (auto& t : p) t.set_requires_grad(true);
    return p;
  };
  // Rank r's loss on micro-batch k; p[3] only on rank 1, p[4] never.
  auto loss_of = [](const std::vector<torch::Tensor>& p, int r, int k) {
    auto x = torch::linspace(-1, 1, 8 * 6).view({6, 8}) * double(1 + 2 * r + k);
    auto y = torch::tanh(torch::tanh(x.matmul(p[0])).matmul(p[1])).matmul(p[2]);
    auto l = y.pow(2).mean();
    return r == 1 ? l + p[3].pow(2).sum() : l;
  };
  struct Result {
    double max_error = 1;
    size_t buckets = 0, sent_during = 0;
    bool never_has_grad = true, only1_has_grad = false, others_freed = false;
    std::string error;
  };
  // sharded: ZeRO-2, p[0] and p[1] rank 0's, the rest rank 1's.
  auto run = [&](bool overlap, bool sharded = false) {
    const std::vector<int> owner = sharded ? std::vector<int>{0, 0, 1, 1, 1} : std::vector<int>{};
    const int port = train::RankEnv::free_local_port();
    std::vector<Result> results(2);
    auto rank = [&](int r) {
      auto& out = results[size_t(r)];
      try {
        train::RankEnv env;
        env.rank = r;
        env.world_size = 2;
        env.master_port = port;
        train::Distributed dist(env, torch::kCPU, std::chrono::seconds(60));
        auto p = make_params();
        train::GradientReducer reducer(p, dist, overlap, 0.001, 0.0005, owner);
        for (int step = 0; step < 2; ++step) {  // twice: the hooks re-arm
          for (auto& t : p) t.mutable_grad() = torch::Tensor();
          for (int k = 0; k < 2; ++k) reducer.backward(loss_of(p, r, k), k == 1);
          reducer.finish();
        }
        auto ref = make_params();
        for (int rr = 0; rr < 2; ++rr)
          for (int k = 0; k < 2; ++k) loss_of(ref, rr, k).backward();
        out.max_error = 0;
        out.others_freed = true;
        for (size_t i = 0; i < 4; ++i) {
          if (sharded && owner[i] != r) {
            out.others_freed = out.others_freed && !p[i].grad().defined();
            continue;
          }
          out.max_error = std::max(out.max_error, (p[i].grad() - ref[i].grad() / 2).abs().max().item<double>());
        }
        out.buckets = reducer.buckets();
        out.sent_during = reducer.sent_during_backward();
        out.never_has_grad = p[4].grad().defined();
        out.only1_has_grad = p[3].grad().defined();
      } catch (const std::exception& e) {
        out.error = e.what();
      }
    };
    std::thread t1(rank, 1);
    rank(0);
    t1.join();
    return results;
  };
  const auto overlapped = run(true);
  for (const auto& r : overlapped) {
    ASSERT_TRUE(r.error.empty()) << r.error;
    EXPECT_LT(r.max_error, 1e-6);
    EXPECT_GE(r.buckets, 3u);
    EXPECT_GE(r.sent_during, 1u);  // buckets left while backward ran
    EXPECT_FALSE(r.never_has_grad);
    EXPECT_TRUE(r.only1_has_grad);  // rank 0 did not use it, but averages rank 1's half
  }
  for (const auto& r : run(false)) {
    ASSERT_TRUE(r.error.empty()) << r.error;
    EXPECT_LT(r.max_error, 1e-6);
    EXPECT_EQ(r.sent_during, 0u);
  }
  // ZeRO-2: each rank ends with the mean of its own parameters' gradients and none of the others'.
  for (bool overlap : {true, false}) {
    const auto sharded = run(overlap, true);
    for (int r = 0; r < 2; ++r) {
      const auto& x = sharded[size_t(r)];
      ASSERT_TRUE(x.error.empty()) << x.error;
      EXPECT_LT(x.max_error, 1e-6) << "rank " << r;
      EXPECT_TRUE(x.others_freed) << "rank " << r;
      EXPECT_GE(x.buckets, 3u);
      EXPECT_FALSE(x.never_has_grad);
      EXPECT_EQ(x.only1_has_grad, r == 1);  // rank 1's own, and rank 1 used it
    }
  }
}

TEST(DistributedCli, TwoRanksTrainTheWeightsOfOneProcess) {
  test::TempDir dir;
  const auto tokens = token_file(dir.path);
  // The tiny world batch of 4: one process, two ranks of 2, two ranks with sharded AdamW state (ZeRO-1), and with
  // sharded gradients too (ZeRO-2), one process accumulating two micro-batches of 2.
  const std::vector<std::pair<std::string, std::string>> runs = {
      {"one", ""}, {"two", " --nproc 2"}, {"zero", " --nproc 2 --shard-optimizer"},
      {"zero2", " --nproc 2 --shard-gradients"}, {"accumulate", " --accumulate 2"}};
  for (const auto& [name, flags] : runs) {
    auto r = test::run_gaia(train_args(tokens, dir / name) + " --steps 6" + flags);
    ASSERT_EQ(r.status, 0) << name << ": " << r.output;
    // Rank 0 alone reports.
    const auto first = r.output.find("world: step 6 (done)");
    EXPECT_NE(first, std::string::npos) << name << ": " << r.output;
    EXPECT_EQ(r.output.find("world: step 6 (done)", first + 1), std::string::npos) << name << ": " << r.output;
  }
  for (const auto& run : {"two", "zero", "zero2", "accumulate"}) {
    EXPECT_LT(max_difference(dir / "one" / "world.safetensors", dir / run / "world.safetensors"), 2e-5) << run;
    auto a = test::jsonl_numbers(dir / "one" / "metrics.jsonl", "loss");
    auto b = test::jsonl_numbers(dir / run / "metrics.jsonl", "loss");
    ASSERT_EQ(a.size(), 6u);
    ASSERT_EQ(b.size(), 6u) << run;
    for (size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1e-5) << run << " step " << i + 1;
  }
  // One step moves the weights far more than that tolerance: the runs agree on training, not on doing nothing.
  auto r5 = test::run_gaia(train_args(tokens, dir / "five") + " --steps 6 --stop-after 5");
  ASSERT_EQ(r5.status, 0) << r5.output;
  EXPECT_GT(max_difference(dir / "one" / "world.safetensors", dir / "five" / "latest.safetensors"), 1e-4);
  auto r = test::run_gaia(train_args(tokens, dir / "three") + " --steps 2 --nproc 3");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("world.batch_size = 4 does not split into 3 rank(s)"), std::string::npos) << r.output;
}

TEST(DistributedCli, ShardedCheckpointOfTwoRanksResumesOnOneExactly) {
  test::TempDir dir;
  const auto tokens = token_file(dir.path);
  auto r = test::run_gaia(train_args(tokens, dir / "whole") + " --steps 6");
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(train_args(tokens, dir / "moved") + " --steps 6 --stop-after 3 --nproc 2 --shard-optimizer");
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(train_args(tokens, dir / "moved") + " --steps 6");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("resumed from"), std::string::npos) << r.output;
  EXPECT_LT(max_difference(dir / "whole" / "world.safetensors", dir / "moved" / "world.safetensors"), 2e-5);
  EXPECT_EQ(test::jsonl_numbers(dir / "moved" / "metrics.jsonl", "loss").size(), 6u);
}

TEST(DistributedCli, AKilledRankEndsTheJobWithOneLineAndItResumes) {
  test::TempDir dir;
  const auto tokens = token_file(dir.path);
  const fs::path out = dir / "run";
  const std::string cmd = test::gaia_command(train_args(tokens, out) +
                                             " --steps 100000 --nproc 2 --dist-timeout 20 --set run.checkpoint_every=5");
  // Rank 1 (the child with RANK=1 in its environment) is killed once the first checkpoint is there.
  const std::string script =
      cmd + " > " + q(dir / "log") + " 2>&1 & P=$!\n"
      "for i in $(seq 1200); do [ -f " + q(out / "checkpoint" / "state.json") + " ] && break; sleep 0.05; done\n"
      "for c in $(pgrep -P $P); do tr '\\0' '\\n' < /proc/$c/environ | grep -qx RANK=1 && kill -9 $c; done\n"
      "S=$(date +%s); wait $P; echo \"status=$? seconds=$(( $(date +%s) - S ))\"\n";
  auto r = test::run_shell("bash -c " + q(script));
  const std::string log = read_file(dir / "log");
  EXPECT_NE(r.output.find("status=1"), std::string::npos) << r.output << log;
  EXPECT_NE(log.find("--nproc 2: rank 1 was killed by signal 9"), std::string::npos) << log;
  const auto secs = std::stoi(r.output.substr(r.output.find("seconds=") + 8));
  EXPECT_LT(secs, 20) << log;  // within the timeout: the others are stopped, not left waiting
  // The last checkpoint is intact and the job resumes from it.
  r = test::run_gaia(train_args(tokens, out) + " --steps 100000 --nproc 2 --stop-after 2");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("resumed from"), std::string::npos) << r.output;
}

#ifndef GAIA_NO_VIDEO
TEST(DistributedCli, TokenizerAndDecoderTrainOnTwoRanks) {
  test::TempDir dir;
  test::synth_dataset(dir / "ds", 3, 2.0);
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  const std::string tok = "tokenizer train " + q(dir / "ds") + tiny + " --val-every 0 --steps 3";
  auto r = test::run_gaia(tok + " --out " + q(dir / "tok1"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(tok + " --nproc 2 --shard-optimizer --out " + q(dir / "tok2"));
  ASSERT_EQ(r.status, 0) << r.output;
  // The tokenizer's batch of 4 as two ranks of 2: the same loss at every step, and the same weights to within what
  // AdamW makes of float noise (the biases before a group norm have no gradient but rounding, which AdamW turns
  // into steps of up to the learning rate).
  auto losses = [&](const fs::path& run) {
    std::vector<double> out;
    std::istringstream in(read_file(run / "metrics.jsonl"));
    for (std::string line; std::getline(in, line);)
      out.push_back(nlohmann::json::parse(line).at("losses").at("loss").get<double>());
    return out;
  };
  const auto l1 = losses(dir / "tok1"), l2 = losses(dir / "tok2");
  ASSERT_EQ(l1.size(), 3u);
  ASSERT_EQ(l2.size(), 3u);
  for (size_t i = 0; i < 3; ++i) EXPECT_NEAR(l1[i], l2[i], 1e-5) << "step " << i + 1;
  EXPECT_LT(max_difference(dir / "tok1" / "tokenizer.safetensors", dir / "tok2" / "tokenizer.safetensors"), 1e-3);
  // The decoder's ranks draw their own noise: the run and its resume on one process are what is checked.
  const std::string dec = "decoder train " + q(dir / "ds") + " --tokenizer " + q(dir / "tok1" / "tokenizer.safetensors") +
                          tiny + " --val-every 0 --steps 3 --out " + q(dir / "dec");
  r = test::run_gaia(dec + " --stop-after 2 --nproc 2");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(test::jsonl_numbers(dir / "dec" / "metrics.jsonl", "loss").size(), 2u);
  r = test::run_gaia(dec);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("resumed from"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(dir / "dec" / "decoder.safetensors"));
}
#endif
