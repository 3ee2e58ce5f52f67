#pragma once
// Noise schedule and v-parameterisation of the video decoder (§2.4, §4.3).
//
// Continuous time t' in [0, 1]; x_t = alpha_t x + sigma_t eps with alpha^2 + sigma^2 = 1 (variance preserving).
// Schedule: the cosine schedule written in log-SNR (Hoogeboom et al. 2023, cited in §4.3):
//   logsnr(t) = -2 log tan(pi t / 2) + 2 log(shift), clipped to [logsnr_min, logsnr_max];
//   alpha^2 = sigmoid(logsnr), sigma^2 = sigmoid(-logsnr).
// `shift` < 1 adds noise at every t (Hoogeboom's resolution shift for large images); 1 is the plain cosine.
// v-parameterisation (Salimans & Ho 2022): v = alpha eps - sigma x, so that
//   x = alpha x_t - sigma v,   eps = sigma x_t + alpha v   (exact identities; a test checks them).
#include <torch/torch.h>

namespace gaia::decoder {

struct NoiseSchedule {
  double logsnr_min = -15.0, logsnr_max = 15.0;  // keeps alpha and sigma away from exactly 0 at the ends
  double shift = 1.0;

  torch::Tensor logsnr(const torch::Tensor& t) const;  // any shape, float
  torch::Tensor alpha(const torch::Tensor& t) const { return torch::sigmoid(logsnr(t)).sqrt(); }
  torch::Tensor sigma(const torch::Tensor& t) const { return torch::sigmoid(-logsnr(t)).sqrt(); }
};

// x_t = alpha x + sigma eps. alpha/sigma broadcast against x (e.g. [B, T, 1, 1, 1] for [B, T, 3, H, W]).
inline torch::Tensor add_noise(const torch::Tensor& x, const torch::Tensor& eps, const torch::Tensor& alpha,
                               const torch::Tensor& sigma) {
  return alpha * x + sigma * eps;
}
inline torch::Tensor v_target(const torch::Tensor& x, const torch::Tensor& eps, const torch::Tensor& alpha,
                              const torch::Tensor& sigma) {
  return alpha * eps - sigma * x;
}
inline torch::Tensor x_from_v(const torch::Tensor& xt, const torch::Tensor& v, const torch::Tensor& alpha,
                              const torch::Tensor& sigma) {
  return alpha * xt - sigma * v;
}
inline torch::Tensor eps_from_v(const torch::Tensor& xt, const torch::Tensor& v, const torch::Tensor& alpha,
                                const torch::Tensor& sigma) {
  return sigma * xt + alpha * v;
}

// §4.3: L = 0.1 L1 + 1.0 L2 between predicted and target v, averaged over the frames selected by `weight`
// ([B, T], 1 = frame to predict, 0 = clean context frame that carries no loss).
torch::Tensor v_loss(const torch::Tensor& v_pred, const torch::Tensor& v_true, const torch::Tensor& weight,
                     double w_l1, double w_l2);
// Temporal consistency (an extension, config decoder.w_temporal): the mean |e[t+1] - e[t]| of the v error
// e = v_pred - v_true over pairs of consecutive frames that are both predicted (weight > 0). With one noise level
// per window the x0 error is -sigma_t e, so this is the flicker of the x0 estimate's error, up to sigma_t. 0 when
// the error is the same in every frame; 0 for windows with fewer than two predicted frames.
torch::Tensor temporal_v_loss(const torch::Tensor& v_pred, const torch::Tensor& v_true, const torch::Tensor& weight);

// One deterministic DDIM step (Song et al. 2021, eta = 0) from time t to an earlier time s, given the model's v:
//   x_hat = alpha_t x_t - sigma_t v,  eps_hat = sigma_t x_t + alpha_t v,  x_s = alpha_s x_hat + sigma_s eps_hat.
torch::Tensor ddim_step(const torch::Tensor& xt, const torch::Tensor& v, const torch::Tensor& alpha_t,
                        const torch::Tensor& sigma_t, const torch::Tensor& alpha_s, const torch::Tensor& sigma_s);

// What the diffusion runs on. With `cond_image` (the CPU default) the model is given the tokenizer decoder's coarse
// frame of the tokens and diffuses the residual x - coarse, as a cascaded refiner would: at initialisation the
// output is already the coarse frame, and training spends its steps on detail and temporal consistency. Frames
// without tokens (context, interpolation, dropped tokens) have a zero coarse frame there and diffuse the frame
// itself. Without cond_image (the paper's setting) the base is zero. -> the base to subtract, shaped like x.
inline torch::Tensor coarse_base(const torch::Tensor& cond_image, const torch::Tensor& x) {
  return cond_image.defined() ? cond_image : torch::zeros_like(x);
}

// decoder.interp_base: frames with neither tokens nor context (the frames between known ones in temporal
// upsampling) have no coarse frame of their own; give them the linear interpolation in time of the nearest context
// frames on either side (a copy of the one neighbour at an end; left at zero with none). The interpolate task in
// training and the upsampling windows at inference both go through here, so the two see the same base.
//   cond_image [B, T, 3, H, W] (zeros where no tokens), frames [B, T, 3, H, W] (clean where context),
//   context [B, T] (1 = context), has_tokens [B, T] bool -> cond_image with those frames filled.
torch::Tensor interpolation_base(const torch::Tensor& cond_image, const torch::Tensor& frames,
                                 const torch::Tensor& context, const torch::Tensor& has_tokens);

// The DDIM time grid: steps + 1 times from `start` (1 = pure noise) down to 0, uniformly spaced.
std::vector<double> ddim_times(int steps, double start = 1.0);

}  // namespace gaia::decoder
