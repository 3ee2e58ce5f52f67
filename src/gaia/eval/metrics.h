#pragma once
// Image and token metrics used across evaluation: PSNR, SSIM (Wang et al. 2004), code usage and perplexity,
// bit compression of a tokenizer.
#include <cstdint>
#include <vector>

#ifndef GAIA_NO_VIDEO
#include <opencv2/core.hpp>
#endif

namespace gaia::eval {

#ifndef GAIA_NO_VIDEO  // a build without video has no images (data/episode.h)
double psnr(const cv::Mat& a, const cv::Mat& b);  // 8-bit images of the same size; 99 dB when identical
double ssim(const cv::Mat& a, const cv::Mat& b);  // mean SSIM over channels, Gaussian window 11 / sigma 1.5
#endif

struct CodeStats {
  double usage = 0;       // fraction of the K codes used at least once
  double perplexity = 0;  // exp(entropy) of the code histogram
  int64_t used = 0, total_tokens = 0;
};
CodeStats code_stats(const std::vector<int64_t>& counts);  // counts[k] = occurrences of code k

// Spearman rank correlation (ties get their average rank); 0 when either side is constant.
double spearman(const std::vector<double>& a, const std::vector<double>& b);

// H W 3 8 / (n log2 K): the paper's bit compression of a tokenizer (§4.1: ~470).
double bit_compression(int height, int width, int tokens, int codebook_size);

}  // namespace gaia::eval
