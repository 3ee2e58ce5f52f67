#include "gaia/tokenizer/evaluate.h"

#include <algorithm>

#include "gaia/core/error.h"
#include "gaia/eval/metrics.h"
#include "gaia/tokenizer/io.h"

namespace gaia::tokenizer {

namespace {
struct Sum {
  int64_t n = 0;
  double psnr = 0, ssim = 0;
  nlohmann::json mean() const { return {{"frames", n}, {"psnr", psnr / double(n)}, {"ssim", ssim / double(n)}}; }
};
}  // namespace

nlohmann::json evaluate_reconstruction(ImageTokenizer& t, const Config& c, const std::vector<cv::Mat>& frames,
                                       const std::vector<FrameTags>& tags, const torch::Device& device,
                                       const std::function<void(int64_t)>& progress) {
  if (frames.empty()) fail("tokenizer eval: no frames to score");
  if (!tags.empty() && tags.size() != frames.size())
    fail("tokenizer eval: {} frames but {} sets of tags", frames.size(), tags.size());
  Sum all;
  std::map<std::string, std::map<std::string, Sum>> groups;  // tag -> value -> sums
  std::vector<int64_t> counts(static_cast<size_t>(c.tokenizer.codebook_size), 0);
  constexpr size_t kBatch = 16;
  for (size_t b = 0; b < frames.size(); b += kBatch) {
    const size_t e = std::min(frames.size(), b + kBatch);
    std::vector<cv::Mat> chunk(frames.begin() + long(b), frames.begin() + long(e));
    auto tokens = encode_frames(t, chunk, device);
    auto rec = decode_tokens(t, tokens, device);
    auto flat = tokens.reshape({-1}).to(torch::kCPU, torch::kLong).contiguous();
    const int64_t* ids = flat.data_ptr<int64_t>();
    for (int64_t i = 0; i < flat.numel(); ++i) counts[static_cast<size_t>(ids[i])]++;
    for (size_t i = 0; i < chunk.size(); ++i) {
      const double p = eval::psnr(chunk[i], rec[i]), s = eval::ssim(chunk[i], rec[i]);
      all.n++, all.psnr += p, all.ssim += s;
      if (tags.empty()) continue;
      for (const auto& [key, value] : tags[b + i]) {
        if (value.empty()) continue;
        Sum& g = groups[key][value];
        g.n++, g.psnr += p, g.ssim += s;
      }
    }
    if (progress) progress(int64_t(e));
  }
  auto cs = eval::code_stats(counts);
  nlohmann::json j = all.mean();
  j["code_usage"] = cs.usage;
  j["code_perplexity"] = cs.perplexity;
  j["bit_compression"] = eval::bit_compression(c.data.height, c.data.width, c.image_tokens(), c.tokenizer.codebook_size);
  for (const auto& [key, values] : groups) {
    nlohmann::json g = nlohmann::json::object();
    for (const auto& [value, sum] : values) g[value] = sum.mean();
    j["by_" + key] = g;
  }
  // Per clip: the median and the worst episode's PSNR, for real footage and procedural drives apart (an average
  // over frames lets long drives outvote short clips).
  if (groups.count("episode") && !tags.empty()) {
    std::map<std::string, std::string> kind_of;  // episode -> footage
    for (const auto& t : tags)
      if (t.count("episode")) kind_of[t.at("episode")] = t.count("footage") ? t.at("footage") : "all";
    std::map<std::string, std::vector<std::pair<double, std::string>>> per_kind;
    for (const auto& [ep, sum] : groups.at("episode")) per_kind[kind_of[ep]].push_back({sum.psnr / double(sum.n), ep});
    nlohmann::json clips = nlohmann::json::object();
    for (auto& [kind, v] : per_kind) {
      std::sort(v.begin(), v.end());
      const size_t n = v.size();
      const double median = n % 2 ? v[n / 2].first : 0.5 * (v[n / 2 - 1].first + v[n / 2].first);
      clips[kind] = {{"episodes", n}, {"median_psnr", median}, {"worst_psnr", v.front().first}, {"worst_episode", v.front().second}};
    }
    j["by_clip"] = clips;
  }
  return j;
}

}  // namespace gaia::tokenizer
