#include "gaia/tokenizer/tokenize.h"

#include <cmath>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/core/npy.h"
#include "gaia/data/clip_sampler.h"
#include "gaia/data/episode.h"
#include "gaia/data/geofence.h"
#include "gaia/data/mirror.h"
#include "gaia/tokenizer/io.h"

namespace gaia::tokenizer {

using nlohmann::json;

namespace {
float nan_mean(const std::vector<float>& v, int64_t a, int64_t b) {
  double s = 0;
  int n = 0;
  for (int64_t i = a; i < b; ++i)
    if (!std::isnan(v[static_cast<size_t>(i)])) { s += v[static_cast<size_t>(i)]; ++n; }
  return n ? static_cast<float>(s / n) : std::numeric_limits<float>::quiet_NaN();
}
}  // namespace

TokenizeResult tokenize_dataset(const fs::path& dataset, const fs::path& weights, const fs::path& out, double rate,
                                const torch::Device& device, const std::function<void(int64_t, int64_t)>& progress,
                                bool mirror) {
  data::Dataset ds(dataset);
  Config c;
  auto t = load_tokenizer(weights, device, &c);
  json header = {{"format", "gaia-tokens"}, {"schema_version", 1}, {"rate_hz", rate},
                 {"grid", {c.tokens_h(), c.tokens_w()}}, {"codebook_size", c.tokenizer.codebook_size},
                 {"tokenizer", weights.filename().string()}, {"source", dataset.string()}, {"mirror", mirror}};
  fs::path hf = out / "dataset.json";
  if (fs::exists(hf)) {
    json old = read_json(hf);
    if (old.value("grid", json()) != header["grid"] || old.value("codebook_size", 0) != c.tokenizer.codebook_size ||
        old.value("rate_hz", 0.0) != rate || old.value("mirror", false) != mirror)
      fail("{}: exists with a different tokenizer grid, codebook, rate or --mirror; use a new --out", hf.string());
  } else {
    fs::create_directories(out / "episodes");
    write_file_atomic(hf, header.dump(2) + "\n");
  }
  // The source's split (geofenced validation, §3) travels with its tokens, so the world model is validated on the
  // same held-out roads as the tokenizer. Checked, and copied on every run: a resumed run follows a re-split source.
  // Mirror images join their source's list (data/mirror.h).
  if (fs::exists(dataset / "split.json")) {
    data::Split sp = data::read_split(dataset / "split.json");
    if (mirror)
      for (auto* ids : {&sp.train, &sp.val_geofence, &sp.val_random, &sp.val_named})
        for (size_t i = 0, n = ids->size(); i < n; ++i) ids->push_back(data::mirrored_id((*ids)[i]));
    write_file_atomic(out / "split.json", sp.to_json().dump(2) + "\n");
  }
  TokenizeResult r;
  for (size_t e = 0; e < ds.size(); ++e) {
    const std::string id = ds.ids()[e];
    std::vector<std::pair<std::string, bool>> todo;  // (output id, mirrored)
    for (bool m : {false, true}) {
      if (m && !mirror) continue;
      const std::string oid = m ? data::mirrored_id(id) : id;
      if (fs::exists(out / "episodes" / oid / "episode.json")) ++r.episodes_skipped;
      else todo.emplace_back(oid, m);
    }
    if (todo.empty()) {
      if (progress) progress(static_cast<int64_t>(e + 1), static_cast<int64_t>(ds.size()));
      continue;
    }
    data::Episode ep = ds.episode(e);
    const auto& times = ep.times();
    int T = static_cast<int>(std::floor((times.back() - times.front()) * rate + 1e-6)) + 1;
    auto idx = data::clip_indices(times, times.front(), T, rate);
    if (idx.empty()) continue;
    std::vector<cv::Mat> frames;
    for (auto i : idx) {
      cv::Mat f = ep.frame_bgr(i);
      if (f.rows != c.data.height || f.cols != c.data.width)
        fail("{}: frames are {}x{}, the tokenizer wants {}x{}", ep.dir().string(), f.rows, f.cols, c.data.height, c.data.width);
      frames.push_back(f);
    }
    for (const auto& [oid, mirrored] : todo) {
      std::vector<cv::Mat> shown = frames;  // headers only; the mirror gets fresh buffers, the source stays intact
      if (mirrored)
        for (size_t i = 0; i < frames.size(); ++i) {
          shown[i] = cv::Mat();
          cv::flip(frames[i], shown[i], 1);
        }
      torch::Tensor tokens = encode_frames(t, shown, device).to(torch::kInt16).contiguous();
      const float side = mirrored ? -1.f : 1.f;  // curvature changes sign in the mirror
      std::vector<float> actions;
      std::vector<double> ts;
      std::string caps, labels;
      for (size_t k = 0; k < idx.size(); ++k) {
        int64_t a = idx[k], b = k + 1 < idx.size() ? idx[k + 1] : idx[k] + 1;  // the step's source frames [a, b)
        actions.push_back(nan_mean(ep.speeds(), a, b));
        actions.push_back(side * nan_mean(ep.curvatures(), a, b));
        ts.push_back(times[static_cast<size_t>(a)]);
        const std::string cap = ep.caption(a);
        caps += json(mirrored ? data::mirror_words(cap) : cap).dump() + "\n";
        if (ep.has_labels()) labels += (mirrored ? data::mirror_labels(ep.labels(a)) : ep.labels(a)).dump() + "\n";
      }
      StagingDir stage(out / "episodes" / oid);
      NpyArray tok;
      tok.dtype = DType::I16;
      tok.shape = tokens.sizes().vec();
      tok.bytes.resize(static_cast<size_t>(tokens.numel()) * 2);
      std::memcpy(tok.bytes.data(), tokens.data_ptr(), tok.bytes.size());
      npy_write(stage.path() / "tokens.npy", tok);
      const int64_t n = static_cast<int64_t>(idx.size());
      npy_write(stage.path() / "actions.npy", npy_make(DType::F32, {n, 2}, actions));
      npy_write(stage.path() / "time_s.npy", npy_make(DType::F64, {n}, ts));
      write_file_atomic(stage.path() / "captions.jsonl", caps);
      if (!labels.empty()) write_file_atomic(stage.path() / "labels.jsonl", labels);
      json meta = ep.meta().to_json();
      if (mirrored) {
        meta["id"] = oid;
        meta["mirror_of"] = id;
      }
      meta["frames"] = idx;
      meta["steps"] = n;
      write_file_atomic(stage.path() / "episode.json", meta.dump(2) + "\n");
      stage.commit(true);
      ++r.episodes_written;
      r.steps += n;
    }
    if (progress) progress(static_cast<int64_t>(e + 1), static_cast<int64_t>(ds.size()));
  }
  return r;
}

cv::Mat pca_sheet(ImageTokenizer& t, const std::vector<cv::Mat>& frames, const torch::Device& device) {
  if (frames.empty()) fail("tokenizer pca: no frames");
  torch::NoGradGuard ng;
  std::vector<torch::Tensor> xs;
  for (auto& f : frames) xs.push_back(image_to_tensor(f.data, f.rows, f.cols));
  auto q = t->encode(torch::stack(xs).to(device));
  auto codes = q.codes.to(torch::kCPU);                        // [N, cd, h, w]
  const auto N = codes.size(0), cd = codes.size(1), h = codes.size(2), w = codes.size(3);
  auto flat = codes.permute({0, 2, 3, 1}).reshape({-1, cd});   // [N h w, cd]
  auto centred = flat - flat.mean(0, true);
  auto cov = torch::matmul(centred.t(), centred) / double(flat.size(0));
  auto eig = torch::linalg::eigh(cov, "L");                    // ascending eigenvalues
  auto top = std::get<1>(eig).slice(1, cd - 3, cd).flip({1});  // [cd, 3]
  auto proj = torch::matmul(centred, top);                     // [N h w, 3]
  auto lo = std::get<0>(proj.min(0, true)), hi = std::get<0>(proj.max(0, true));
  auto rgb = ((proj - lo) / (hi - lo + 1e-8) * 255).round().clamp(0, 255).to(torch::kUInt8).reshape({N, h, w, 3}).contiguous();
  std::vector<cv::Mat> rows;
  for (int64_t i = 0; i < N; ++i) {
    cv::Mat small(static_cast<int>(h), static_cast<int>(w), CV_8UC3, rgb[i].data_ptr()), big, row;
    cv::resize(small, big, frames[static_cast<size_t>(i)].size(), 0, 0, cv::INTER_NEAREST);
    cv::cvtColor(big, big, cv::COLOR_RGB2BGR);
    cv::hconcat(frames[static_cast<size_t>(i)], big, row);
    rows.push_back(row);
  }
  cv::Mat sheet;
  cv::vconcat(rows, sheet);
  return sheet;
}

}  // namespace gaia::tokenizer
