// The one attention implementation (torch/attention.h) against the formula, written out: softmax(q k^T / sqrt(hd)
// + bias) v, with no bias, a 2-D mask (the fused path), a per-head bias and the causal mask.
#include <torch/torch.h>

#include <cmath>
#include <limits>

#include "gaia/torch/attention.h"
#include "test_util.h"

using namespace gaia;

namespace {

torch::Tensor reference(const torch::Tensor& q, const torch::Tensor& k, const torch::Tensor& v, const torch::Tensor& bias) {
  auto s = torch::matmul(q, k.transpose(-2, -1)) / std::sqrt(double(q.size(-1)));
  if (bias.defined()) s = s + bias;
  return torch::matmul(torch::softmax(s, -1), v);
}

}  // namespace

// On GAIA_TEST_DEVICE: with LibTorch 2 on CUDA, the fused kernels.
TEST(Attention, MatchesTheFormulaWithAndWithoutBiasAndMask) {
  torch::manual_seed(3);
  const auto o = torch::TensorOptions().device(torch::Device(test::device_name()));
  auto q = torch::randn({2, 3, 5, 8}, o), k = torch::randn({2, 3, 7, 8}, o), v = torch::randn({2, 3, 7, 4}, o);
  EXPECT_TRUE(torch::allclose(attention(q, k, v), reference(q, k, v, {}), 1e-5, 1e-6));
  auto mask2 = torch::randn({5, 7}, o);
  EXPECT_TRUE(torch::allclose(attention(q, k, v, mask2), reference(q, k, v, mask2), 1e-5, 1e-6));
  auto per_head = torch::randn({1, 3, 5, 7}, o);
  EXPECT_TRUE(torch::allclose(attention(q, k, v, per_head), reference(q, k, v, per_head), 1e-5, 1e-6));
  EXPECT_EQ(attention(q, k, v).sizes(), (std::vector<int64_t>{2, 3, 5, 4}));
}

TEST(Attention, CausalMaskSeesOnlyEarlierKeys) {
  torch::manual_seed(4);
  const auto o = torch::TensorOptions().device(torch::Device(test::device_name()));
  auto q = torch::randn({2, 6, 8}, o), k = torch::randn({2, 6, 8}, o), v = torch::randn({2, 6, 8}, o);
  const auto m = causal_mask(6, 6, 0, q.options());
  EXPECT_EQ(m[2][2].item<float>(), 0.0f);
  EXPECT_EQ(m[2][3].item<float>(), -std::numeric_limits<float>::infinity());
  EXPECT_TRUE(torch::allclose(attention(q, k, v, {}, true), reference(q, k, v, m), 1e-5, 1e-6));
  // The first query sees only the first key: its output is that key's value.
  EXPECT_TRUE(torch::allclose(attention(q, k, v, {}, true).select(1, 0), v.select(1, 0), 1e-5, 1e-6));
  // Queries at key positions 4 and 5 of 6 (a KV cache of 4): the mask is the last two rows of the square one.
  EXPECT_TRUE(torch::equal(causal_mask(2, 6, 4, q.options()), m.slice(0, 4)));
  EXPECT_NE(test::error_of([&] { attention(q.slice(1, 0, 2), k, v, {}, true); }).find("as many queries as keys"),
            std::string::npos);
}
