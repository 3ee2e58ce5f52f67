// The one attention implementation (torch/attention.h) against the formula, written out: softmax(q k^T / sqrt(hd)
// + bias) v, with no bias, a 2-D mask (the fused path), a per-head bias and the causal mask.
#include <torch/torch.h>

#include <cmath>
#include <limits>

#include "gaia/torch/attention.h"
#include "gaia/torch/causal_softmax.h"
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

// Training on scores the causal softmax kernel does not take (here float64) goes through the masked softmax, on
// the scores already computed: the formula's values and gradients.
TEST(Attention, CausalTrainingOnScoresTheKernelDoesNotTake) {
  torch::manual_seed(5);
  const auto o = torch::TensorOptions().dtype(torch::kDouble);
  auto q = torch::randn({2, 6, 8}, o).requires_grad_(), k = torch::randn({2, 6, 8}, o).requires_grad_(),
       v = torch::randn({2, 6, 8}, o).requires_grad_();
  auto got = attention(q, k, v, {}, true);
  auto want = reference(q, k, v, causal_mask(6, 6, 0, o));
  EXPECT_TRUE(torch::allclose(got, want, 1e-12, 1e-12));
  auto g = torch::autograd::grad({got.sum()}, {q, k, v}), h = torch::autograd::grad({want.sum()}, {q, k, v});
  for (size_t i = 0; i < 3; ++i) EXPECT_TRUE(torch::allclose(g[i], h[i], 1e-10, 1e-12)) << i;
}

// The causal softmax kernel (torch/causal_softmax.h) against LibTorch's masked softmax, forward and backward, in
// float32 and bf16, on rows of every length from 1 to L (L not a multiple of eight): zeros after each query's keys,
// float32 to within rounding, bf16 to within its own rounding of the same float32 values.
TEST(Attention, CausalSoftmaxMatchesTheMaskedSoftmaxBothWays) {
  torch::manual_seed(5);
  const int64_t N = 3, L = 21;
  const double scale = 0.3;
  auto s = torch::randn({N, L, L}) * 4;
  auto g = torch::randn({N, L, L});
  const auto mask = causal_mask(L, L, 0, s.options());
  auto want_p = [&](const torch::Tensor& x) {
    auto xr = x.detach().to(torch::kFloat).clone().requires_grad_(true);
    auto p = torch::softmax(xr * scale + mask, -1);
    auto dx = torch::autograd::grad({p}, {xr}, {g})[0];
    return std::make_pair(p.detach(), dx);
  };
  for (auto dtype : {torch::kFloat, torch::kBFloat16}) {
    SCOPED_TRACE(dtype == torch::kFloat ? "float32" : "bf16");
    auto x = s.to(dtype).clone().requires_grad_(true);
    auto p = causal_softmax(x, scale);
    EXPECT_EQ(p.scalar_type(), dtype);
    auto dx = torch::autograd::grad({p}, {x}, {g.to(dtype)})[0];
    auto [ref_p, ref_g] = want_p(x);  // from the same (rounded) scores
    const double tol = dtype == torch::kFloat ? 1e-6 : 8e-3;
    EXPECT_LT((p.to(torch::kFloat) - ref_p).abs().max().item<double>(), tol);
    EXPECT_TRUE(torch::equal(p.to(torch::kFloat).triu(1), torch::zeros({N, L, L})));
    // Each row sums to one over the keys its query sees.
    EXPECT_LT((p.to(torch::kFloat).sum(-1) - 1).abs().max().item<double>(), dtype == torch::kFloat ? 1e-5 : 2e-2);
    auto got_g = dx.to(torch::kFloat);
    const double gtol = dtype == torch::kFloat ? 1e-6 : 2e-2 * ref_g.abs().max().item<double>();
    EXPECT_LT((got_g - ref_g).abs().max().item<double>(), gtol);
    EXPECT_TRUE(torch::equal(got_g.triu(1), torch::zeros({N, L, L})));
  }
  EXPECT_NE(test::error_of([&] { causal_softmax(torch::randn({2, 3, 4}), 1.0); }).find("square"), std::string::npos);
  EXPECT_NE(test::error_of([&] { causal_softmax(torch::randn({2, 3, 3}), 0.0); }).find("scale"), std::string::npos);
  // attention() takes this path for a causal square being trained on the CPU: the same values and gradients as
  // the formula's.
  auto q = torch::randn({2, 3, 9, 8}).requires_grad_(true), k = torch::randn({2, 3, 9, 8}), v = torch::randn({2, 3, 9, 8});
  auto m = causal_mask(9, 9, 0, q.options());
  auto y = attention(q, k, v, {}, true), y_ref = reference(q, k, v, m);
  EXPECT_TRUE(torch::allclose(y, y_ref, 1e-5, 1e-6));
  auto gy = torch::randn({2, 3, 9, 8});
  auto dq = torch::autograd::grad({y}, {q}, {gy})[0];
  auto dq_ref = torch::autograd::grad({y_ref}, {q}, {gy})[0];
  EXPECT_TRUE(torch::allclose(dq, dq_ref, 1e-4, 1e-5));
}
