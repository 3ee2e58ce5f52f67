#pragma once
// Keeping what a fine-tune should not change (learning without forgetting, Li & Hoiem 2016): while a world model is
// fine-tuned for one kind of conditioning (e.g. actions, on counterfactual replays), its text-conditioned and
// unconditional predictions are held to those of the weights it started from by a KL term on those examples only.
// Classifier-free guidance (§5.1) mixes exactly these two distributions, so this is what text prompting depends on.
#include <torch/torch.h>

namespace gaia::world {

// Mean over the image tokens of the examples with keep[b] of KL(teacher || student) per token, in nats.
// student, teacher: logits [B, T, n, K] (teacher without gradient); keep: [B] bool. 0 (with a gradient path) when no
// example is kept.
torch::Tensor image_token_kl(const torch::Tensor& student, const torch::Tensor& teacher, const torch::Tensor& keep);

}  // namespace gaia::world
