// Token statistics of the long-rollout evaluation (control/rollouts.h) on frames with known answers.
#include <cmath>

#include <torch/torch.h>

#include "gaia/control/rollouts.h"
#include "test_util.h"

using namespace gaia;

TEST(ControlStats, CopyRateAndEntropyOfKnownFrames) {
  // Three frames of 4 tokens; frame 1 repeats frame 0 in 3 of 4 positions, frame 2 repeats frame 1 in 1 of 4.
  auto f = torch::tensor({0, 1, 2, 3, 0, 1, 2, 0, 5, 5, 5, 0}, torch::kLong).view({3, 4});
  EXPECT_DOUBLE_EQ(control::copy_rate(f), (3.0 + 1.0) / 8.0);
  EXPECT_TRUE(std::isnan(control::copy_rate(f.slice(0, 0, 1))));  // one frame: no pairs
  // A frozen video copies everything; four equally frequent tokens have 2 bits of entropy, one token 0 bits.
  EXPECT_DOUBLE_EQ(control::copy_rate(f[0].unsqueeze(0).repeat({5, 1})), 1.0);
  EXPECT_NEAR(control::unigram_entropy_bits(f[0].unsqueeze(0), 16), 2.0, 1e-12);
  EXPECT_NEAR(control::unigram_entropy_bits(torch::full({2, 4}, 7, torch::kLong), 16), 0.0, 1e-12);
}
