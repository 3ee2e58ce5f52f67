#include "gaia/eval/metrics.h"

#include <algorithm>
#include <cmath>

#ifndef GAIA_NO_VIDEO
#include <opencv2/imgproc.hpp>
#endif

#include "gaia/core/error.h"

namespace gaia::eval {

#ifndef GAIA_NO_VIDEO
double psnr(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) fail("psnr: images differ in size or type");
  cv::Mat d;
  cv::absdiff(a, b, d);
  d.convertTo(d, CV_64F);
  double mse = cv::mean(d.mul(d))[0];
  if (a.channels() > 1) {
    cv::Scalar m = cv::mean(d.mul(d));
    mse = 0;
    for (int c = 0; c < a.channels(); ++c) mse += m[c];
    mse /= a.channels();
  }
  return mse <= 1e-10 ? 99.0 : 10.0 * std::log10(255.0 * 255.0 / mse);
}

double ssim(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) fail("ssim: images differ in size or type");
  const double C1 = 6.5025, C2 = 58.5225;  // (0.01 * 255)^2, (0.03 * 255)^2
  cv::Mat x, y;
  a.convertTo(x, CV_64F);
  b.convertTo(y, CV_64F);
  auto blur = [](const cv::Mat& m) {
    cv::Mat o;
    cv::GaussianBlur(m, o, cv::Size(11, 11), 1.5);
    return o;
  };
  cv::Mat mx = blur(x), my = blur(y);
  cv::Mat sxx = blur(x.mul(x)) - mx.mul(mx), syy = blur(y.mul(y)) - my.mul(my), sxy = blur(x.mul(y)) - mx.mul(my);
  // Scalar::all: a bare double added to a multi-channel matrix inside a product reaches only the first channel.
  const cv::Scalar c1 = cv::Scalar::all(C1), c2 = cv::Scalar::all(C2);
  cv::Mat num = (2 * mx.mul(my) + c1).mul(2 * sxy + c2);
  cv::Mat den = (mx.mul(mx) + my.mul(my) + c1).mul(sxx + syy + c2);
  cv::Mat s;
  cv::divide(num, den, s);
  cv::Scalar m = cv::mean(s);
  double total = 0;
  for (int c = 0; c < a.channels(); ++c) total += m[c];
  return total / a.channels();
}
#endif

CodeStats code_stats(const std::vector<int64_t>& counts) {
  CodeStats s;
  for (auto c : counts) { s.total_tokens += c; s.used += c > 0; }
  if (counts.empty() || s.total_tokens == 0) return s;
  double h = 0;
  for (auto c : counts)
    if (c > 0) {
      double p = double(c) / double(s.total_tokens);
      h -= p * std::log(p);
    }
  s.usage = double(s.used) / double(counts.size());
  s.perplexity = std::exp(h);
  return s;
}

double bit_compression(int height, int width, int tokens, int codebook_size) {
  return double(height) * width * 3 * 8 / (double(tokens) * std::log2(double(codebook_size)));
}

namespace {
std::vector<double> ranks(const std::vector<double>& v) {
  std::vector<size_t> idx(v.size());
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = i;
  std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return v[a] < v[b]; });
  std::vector<double> r(v.size());
  for (size_t i = 0; i < idx.size();) {
    size_t j = i;
    while (j + 1 < idx.size() && v[idx[j + 1]] == v[idx[i]]) ++j;
    for (size_t k = i; k <= j; ++k) r[idx[k]] = 0.5 * double(i + j);  // average rank of a run of ties
    i = j + 1;
  }
  return r;
}
}  // namespace

double spearman(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size()) fail("spearman: {} vs {} values", a.size(), b.size());
  if (a.size() < 2) return 0.0;
  auto ra = ranks(a), rb = ranks(b);
  const double n = double(a.size());
  double ma = 0, mb = 0;
  for (size_t i = 0; i < ra.size(); ++i) ma += ra[i] / n, mb += rb[i] / n;
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < ra.size(); ++i) {
    sab += (ra[i] - ma) * (rb[i] - mb);
    saa += (ra[i] - ma) * (ra[i] - ma);
    sbb += (rb[i] - mb) * (rb[i] - mb);
  }
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : 0.0;
}

}  // namespace gaia::eval
