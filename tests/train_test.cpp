// train::StepLoop: a resumed run's metrics.jsonl keeps each step once (the steps an interrupted run did past its
// last checkpoint are trained again and logged again), and a torn last line of a killed run is dropped.
#include <sys/resource.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "gaia/core/progress.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/checkpoint.h"
#include "gaia/train/step_loop.h"
#include "test_util.h"

using namespace gaia;

// A resumed run's progress bar counts its rate from the resume point: 1 step in ~20 ms is ~50 steps/s, not
// (resume step + 1) / 20 ms, which would promise an ETA a thousand times too short.
TEST(ProgressBar, ResumedRunRateCountsOnlyNewSteps) {
  testing::internal::CaptureStderr();
  {
    ProgressBar bar(2000, "train", true, 1000);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    bar.update(1001);
    bar.finish();
  }
  const std::string out = testing::internal::GetCapturedStderr();
  const auto at = out.rfind("% ");
  ASSERT_NE(at, std::string::npos) << out;
  const double rate = std::stod(out.substr(at + 2));
  EXPECT_GT(rate, 0.5) << out;
  EXPECT_LT(rate, 60.0) << out;  // counting the 1000 earlier steps would give ~50000/s
  EXPECT_NE(out.find("1001/2000"), std::string::npos) << out;
}

TEST(StepLoop, ResumeDropsRecordsPastTheCheckpoint) {
  test::TempDir d;
  const fs::path f = d / "metrics.jsonl";
  write_file_atomic(f, "{\"step\":1}\n{\"step\":2}\n{\"step\":3}\n{\"step\":4}\n{\"step\":5}\n{\"step\":6,\"lo");
  {
    train::StepLoop loop(f, 3, 10, 0, -1);  // resumed at step 3 of 10
    int saves = 0;
    for (int s = 4; s <= 10; ++s) loop.end_step(s, {{"step", s}}, [&] { ++saves; });
    EXPECT_EQ(saves, 1);  // only the last step (checkpoint_every 0)
  }
  std::ifstream in(f);
  std::string line;
  int expect = 1;
  while (std::getline(in, line)) EXPECT_EQ(nlohmann::json::parse(line)["step"].get<int>(), expect++) << line;
  EXPECT_EQ(expect, 11);
  // A fresh run (step 0) in a directory with an old curve starts a new one.
  { train::StepLoop fresh(f, 0, 5, 0, -1); }
  EXPECT_EQ(read_file(f), "");
}

// Fine-tuning (--init): every tensor of the run's model comes from the file; a tensor the file has and the run's
// config lacks is dropped and said (init_from's note), never silently; one the run has and the file lacks fails
// unless the run marks it fresh.
TEST(InitFrom, CopiesByNameAndSaysWhatItDrops) {
  torch::nn::Sequential small(torch::nn::Linear(3, 4)), big(torch::nn::Linear(3, 4), torch::nn::Linear(4, 2));
  torch::nn::init::constant_(big[0]->as<torch::nn::Linear>()->weight, 0.5);
  EXPECT_EQ(train::init_from(*small, *small, "same.safetensors"), "");
  const std::string note = train::init_from(*small, *big, "big.safetensors");
  EXPECT_TRUE(torch::equal(small[0]->as<torch::nn::Linear>()->weight, torch::full({4, 3}, 0.5)));
  EXPECT_NE(note.find("big.safetensors: 2 tensors"), std::string::npos) << note;
  EXPECT_NE(note.find("'1.weight'"), std::string::npos) << note;
  EXPECT_NE(test::error_of([&] { train::init_from(*big, *small, "small.safetensors"); }).find("small.safetensors: no tensor '1."),
            std::string::npos);
  EXPECT_EQ(train::init_from(*big, *small, "small.safetensors", [](const std::string& k) { return k.rfind("1.", 0) == 0; }), "");
}

// configure_allocator keeps freed memory in the process however much of it there is: a default training step frees
// over 1 GiB of attention scores at its end, all at the heap's top, and glibc's trim point (it was 1 GiB) gave it
// back to the OS only for the next step to fault and clear every page of it again.
TEST(Allocator, AFreedGibibyteIsReusedWithoutPageFaults) {
  configure_allocator();
  auto faults = [] {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_minflt;
  };
  const size_t bytes = (size_t(1) << 30) + (size_t(64) << 20);  // 1 GiB + 64 MiB
  const long pages = long(bytes / 4096);
  auto touch = [&](char fill) {  // through a volatile pointer, so that the compiler keeps malloc, writes and free
    char* volatile p = static_cast<char*>(std::malloc(bytes));
    ASSERT_NE(p, nullptr);
    std::memset(p, fill, bytes);
    EXPECT_EQ(p[bytes / 2], fill);
    std::free(p);
  };
  touch(1);
  const long before = faults();
  touch(2);
  EXPECT_LT(faults() - before, pages / 20) << "of " << pages << " pages";
}
