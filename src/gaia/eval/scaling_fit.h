#pragma once
// The scaling law of §6: final validation loss against training compute, f(x) = c + (x / a)^b with b < 0, fitted to
// the smaller runs to predict the largest before it is trained. Torch-free.
#include <cstdint>
#include <vector>

namespace gaia::eval {

struct PowerLaw {
  double c = 0, a = 1, b = -1;  // c: the irreducible loss; b < 0
  double sse = 0;               // sum of squared residuals of the fit
  double operator()(double x) const;
};

// Least squares in the loss: for each c on a fine grid below the smallest loss, log(L - c) is linear in log x, which
// gives a and b in closed form; the c with the smallest squared error in L wins (then refined around it). Needs at
// least 3 points, x > 0, finite losses, and losses falling with x on the whole (else b >= 0: an error).
PowerLaw fit_power_law(const std::vector<double>& x, const std::vector<double>& loss);

// The spread of the prediction at `at`: the fit repeated on `draws` residual-bootstrap resamples (seeded), its
// `lo` and `hi` quantiles (5% and 95%).
struct Band {
  double lo = 0, hi = 0;
};
Band prediction_band(const std::vector<double>& x, const std::vector<double>& loss, const PowerLaw& fit, double at,
                     int draws = 400, uint64_t seed = 0, double lo = 0.05, double hi = 0.95);

}  // namespace gaia::eval
