// World model cross-check against the PyTorch-Python peer (tools/bench_world_torch.py --make-fixture, fixtures in
// tests/fixtures/world_peer/): the same weights and batch give the same logits (relative error <= 1e-4) and the
// same image-token loss (1e-5).
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/core/safetensors.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/batch.h"
#include "gaia/world/model.h"
#include "test_util.h"

using namespace gaia;
using namespace gaia::world;

namespace {

fs::path peer_dir() { return test::source_dir() / "tests" / "fixtures" / "world_peer"; }


}  // namespace

TEST(WorldPeer, LogitsAndLossMatchThePyTorchPeer) {
  Config c = test::config("tiny.yaml");
  SafetensorsFile io(peer_dir() / "world_peer_io.safetensors");
  auto get = [&](const std::string& name) { return tensor_from_view(io.get(name)); };
  const auto want_logits = get("logits");  // [B, T, n, K]
  ASSERT_EQ(want_logits.dim(), 4);
  const int64_t n = want_logits.size(2), K = want_logits.size(3);
  ASSERT_EQ(n, int64_t{6});
  ASSERT_EQ(K, int64_t{32});

  torch::manual_seed(0);
  WorldModel m(c.world, n, K);
  load_module(*m, peer_dir() / "world_peer.safetensors");  // strict: every name and shape as the peer's
  m->eval();

  WorldBatch b;
  b.tokens = get("tokens");
  b.actions = get("actions");
  b.text_ids = get("text_ids");
  b.use_action = get("use_action").to(torch::kBool);
  b.use_text = get("use_text").to(torch::kBool);
  ASSERT_EQ(b.tokens.scalar_type(), torch::kLong);
  ASSERT_EQ(b.text_ids.scalar_type(), torch::kLong);
  // The fixture exercises the per-entry NaN -> null action path and the per-example use_action switch.
  EXPECT_TRUE(torch::isnan(b.actions).any().item<bool>());
  EXPECT_FALSE(b.use_action.all().item<bool>());

  torch::NoGradGuard ng;
  auto logits = m->forward(b);
  ASSERT_EQ(logits.sizes(), want_logits.sizes());
  EXPECT_TRUE(torch::isfinite(logits).all().item<bool>());
  EXPECT_LE(test::rel_err(logits, want_logits), 1e-4);

  const double want_loss = get("loss").item<double>();
  EXPECT_NEAR(image_token_loss(logits, b.tokens).item<double>(), want_loss, 1e-5);
  // The loss function alone, on the peer's own logits.
  EXPECT_NEAR(image_token_loss(want_logits, b.tokens).item<double>(), want_loss, 1e-6);
}
