#include "gaia/eval/scaling_fit.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "gaia/core/error.h"

namespace gaia::eval {

double PowerLaw::operator()(double x) const { return c + std::pow(x / a, b); }

namespace {

// For a fixed c: log(L - c) = b log x - b log a by ordinary least squares; the squared error is taken in L.
bool fit_at(const std::vector<double>& x, const std::vector<double>& loss, double c, PowerLaw* out) {
  const size_t n = x.size();
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t i = 0; i < n; ++i) {
    if (!(loss[i] > c)) return false;
    const double u = std::log(x[i]), v = std::log(loss[i] - c);
    sx += u;
    sy += v;
    sxx += u * u;
    sxy += u * v;
  }
  const double den = double(n) * sxx - sx * sx;
  if (!(den > 0)) return false;
  const double b = (double(n) * sxy - sx * sy) / den, k = (sy - b * sx) / double(n);  // v = b u + k
  if (!(b < 0)) return false;
  PowerLaw f{c, std::exp(-k / b), b, 0};
  for (size_t i = 0; i < n; ++i) f.sse += std::pow(f(x[i]) - loss[i], 2);
  if (!std::isfinite(f.sse)) return false;
  *out = f;
  return true;
}

}  // namespace

PowerLaw fit_power_law(const std::vector<double>& x, const std::vector<double>& loss) {
  if (x.size() != loss.size()) fail("scaling fit: {} compute values but {} losses", x.size(), loss.size());
  if (x.size() < 3) fail("scaling fit: f(x) = c + (x/a)^b has 3 parameters; it needs at least 3 runs, got {}", x.size());
  for (size_t i = 0; i < x.size(); ++i)
    if (!(x[i] > 0) || !std::isfinite(x[i]) || !std::isfinite(loss[i]))
      fail("scaling fit: run {} has compute {} and loss {}; want compute > 0 and a finite loss", i, x[i], loss[i]);
  const double lmin = *std::min_element(loss.begin(), loss.end());
  PowerLaw best;
  best.sse = std::numeric_limits<double>::infinity();
  // c in [0, lmin): a log-spaced grid that reaches close below the smallest loss, then a finer pass around the best.
  auto scan = [&](double lo, double hi, int steps) {
    for (int s = 0; s <= steps; ++s) {
      const double c = lo + (hi - lo) * s / steps;
      PowerLaw f;
      if (c < lmin && fit_at(x, loss, c, &f) && f.sse < best.sse) best = f;
    }
  };
  const double top = lmin * (1 - 1e-9);
  scan(0, top, 2000);
  if (!std::isfinite(best.sse))
    fail("scaling fit: the losses do not fall with compute (no power law with b < 0 fits them)");
  const double step = top / 2000;
  scan(std::max(0.0, best.c - step), std::min(top, best.c + step), 400);
  return best;
}

Band prediction_band(const std::vector<double>& x, const std::vector<double>& loss, const PowerLaw& fit, double at,
                     int draws, uint64_t seed, double lo, double hi) {
  std::vector<double> residual(x.size());
  for (size_t i = 0; i < x.size(); ++i) residual[i] = loss[i] - fit(x[i]);
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<size_t> pick(0, x.size() - 1);
  std::vector<double> predictions;
  for (int d = 0; d < draws; ++d) {
    std::vector<double> y(x.size());
    for (size_t i = 0; i < x.size(); ++i) y[i] = fit(x[i]) + residual[pick(rng)];
    try {
      predictions.push_back(fit_power_law(x, y)(at));
    } catch (const Error&) {
      // a resample that no falling power law fits says nothing about the prediction
    }
  }
  if (predictions.empty()) return {fit(at), fit(at)};
  std::sort(predictions.begin(), predictions.end());
  auto q = [&](double p) { return predictions[size_t(std::lround(p * double(predictions.size() - 1)))]; };
  return {q(lo), q(hi)};
}

}  // namespace gaia::eval
