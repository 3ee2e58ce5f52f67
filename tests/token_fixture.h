#pragma once
// Token datasets written by hand in the layout `gaia tokenize` writes (docs/formats.md, "Token dataset"), with
// tokens, actions and captions a test can recompute for any step.
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "gaia/core/fs.h"
#include "gaia/core/npy.h"
#include "gaia/data/episode.h"

namespace gaia::test::token_fixture {

using nlohmann::json;

constexpr int64_t kH = 2, kW = 3, kN = kH * kW, kK = 16;
inline const float kNaN = std::numeric_limits<float>::quiet_NaN();

// The token at step t, position i of an episode with this offset; lets a test recompute any window's tokens.
inline int64_t token_at(int offset, int64_t t, int64_t i) { return (offset + t * kN + i) % kK; }

inline std::string caption_at(const std::string& weather, int64_t t) { return fmt::format("A {} road, step {}", weather, t); }

inline void write_header(const fs::path& root, int64_t K = kK) {
  fs::create_directories(root / "episodes");
  json h = {{"format", "gaia-tokens"}, {"schema_version", 1}, {"rate_hz", 6.25}, {"grid", {kH, kW}},
            {"codebook_size", K}, {"tokenizer", "test"}, {"source", "test"}};
  write_file_atomic(root / "dataset.json", h.dump(2));
}

struct EpisodeSpec {
  std::string id;
  int64_t steps = 8;
  std::string weather = "clear";
  int offset = 0;
  // speed (m/s) and curvature (1/m) of step t
  std::function<std::pair<float, float>(int64_t)> action = [](int64_t t) { return std::make_pair(float(t), 0.0f); };
  std::map<std::string, std::string> extra = {};  // metadata, e.g. replay_of
};

// One token episode in the layout `gaia tokenize` writes (docs/formats.md, "Token dataset").
inline void write_episode(const fs::path& root, const EpisodeSpec& s) {
  fs::path dir = root / "episodes" / s.id;
  fs::create_directories(dir);
  std::vector<int16_t> tokens;
  std::vector<float> actions;
  std::string captions;
  for (int64_t t = 0; t < s.steps; ++t) {
    for (int64_t i = 0; i < kN; ++i) tokens.push_back(static_cast<int16_t>(token_at(s.offset, t, i)));
    auto [v, k] = s.action(t);
    actions.push_back(v);
    actions.push_back(k);
    captions += json(caption_at(s.weather, t)).dump() + "\n";
  }
  npy_write(dir / "tokens.npy", npy_make(DType::I16, {s.steps, kH, kW}, tokens));
  npy_write(dir / "actions.npy", npy_make(DType::F32, {s.steps, 2}, actions));
  write_file_atomic(dir / "captions.jsonl", captions);
  data::EpisodeMeta m;
  m.id = s.id;
  m.height = 16;
  m.width = 24;
  m.num_frames = 4 * s.steps;
  m.weather = s.weather;
  m.time_of_day = "day";
  m.latitude = 51.5;
  m.longitude = -0.1;
  m.extra = s.extra;
  json j = m.to_json();
  j["steps"] = s.steps;
  write_file_atomic(dir / "episode.json", j.dump(2));
}

}  // namespace gaia::test::token_fixture
