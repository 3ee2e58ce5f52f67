#include "gaia/world/token_file.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"

namespace gaia::world {

void TokenFormat::set_grid(const std::string& text, const std::string& flag) {
  const auto x = text.find('x');
  long long h = 0, w = 0;
  size_t a = 0, b = 0;
  try {
    if (x == std::string::npos) throw std::invalid_argument("no x");
    h = std::stoll(text.substr(0, x), &a);
    w = std::stoll(text.substr(x + 1), &b);
  } catch (const std::exception&) {
    a = 0;
  }
  if (a != x || b != text.size() - x - 1 || a == 0 || b == 0 || h < 1 || w < 1 || h > 4096 || w > 4096)
    fail("{} must be HxW with 1 <= H, W <= 4096 (e.g. 8x16), got '{}'", flag, text);
  grid_h = h;
  grid_w = w;
}

double TokenFormat::dataset_rate_hz() const { return rate_hz > 0 && keep_rate ? rate_hz : world_rate_hz; }

std::vector<int64_t> TokenFormat::kept_frames(int64_t frames, const fs::path& file) const {
  std::vector<int64_t> out;
  if (rate_hz <= 0 || keep_rate || std::abs(rate_hz - world_rate_hz) < 1e-9) {
    for (int64_t i = 0; i < frames; ++i) out.push_back(i);
    return out;
  }
  if (!std::isfinite(rate_hz) || rate_hz < world_rate_hz)
    fail("{}: tokens at {} Hz (--token-fps) are slower than the world model's {} Hz; pass --keep-rate to train at the "
         "file's own rate", file.string(), rate_hz, world_rate_hz);
  const double step = rate_hz / world_rate_hz;
  for (int64_t k = 0;; ++k) {
    const auto i = static_cast<int64_t>(std::llround(double(k) * step));
    if (i >= frames) break;
    out.push_back(i);
  }
  return out;
}

TokenSidecar read_token_sidecar(const fs::path& token_file) {
  TokenSidecar s;
  s.meta.id = token_file.stem().string();
  const fs::path side = fs::path(token_file).replace_extension(".json");
  if (!fs::exists(side)) return s;
  const nlohmann::json j = read_json(side);
  if (!j.is_object()) fail("{}: a token file's sidecar must be a JSON object", side.string());
  static const std::vector<std::string> known{"latitude", "longitude", "weather", "time_of_day", "fps"};
  for (auto it = j.begin(); it != j.end(); ++it)
    if (std::find(known.begin(), known.end(), it.key()) == known.end())
      fail("{}: unknown key '{}' (a token file's sidecar knows: latitude, longitude, weather, time_of_day, fps)",
           side.string(), it.key());
  auto number = [&](const char* key, double lo, double hi) {
    if (!j.contains(key) || j.at(key).is_null()) return std::numeric_limits<double>::quiet_NaN();
    if (!j.at(key).is_number() || !(j.at(key).get<double>() >= lo && j.at(key).get<double>() <= hi))
      fail("{}: '{}' must be a number in [{}, {}]", side.string(), key, lo, hi);
    return j.at(key).get<double>();
  };
  auto text = [&](const char* key) {
    if (!j.contains(key)) return std::string();
    if (!j.at(key).is_string()) fail("{}: '{}' must be a string", side.string(), key);
    return j.at(key).get<std::string>();
  };
  s.meta.latitude = number("latitude", -90, 90);
  s.meta.longitude = number("longitude", -180, 180);
  if (std::isnan(s.meta.latitude) != std::isnan(s.meta.longitude))
    fail("{}: give latitude and longitude together", side.string());
  s.meta.weather = text("weather");
  s.meta.time_of_day = text("time_of_day");
  const double fps = number("fps", 0, 1000);
  if (fps == 0) fail("{}: 'fps' must be above 0", side.string());
  s.fps = std::isnan(fps) ? 0 : fps;
  return s;
}

TokenFormat file_format(const TokenFormat& f, const TokenSidecar& s, const fs::path& token_file) {
  TokenFormat out = f;
  if (s.fps <= 0) return out;
  if (f.rate_hz > 0 && std::abs(f.rate_hz - s.fps) > 0.01 * s.fps)
    fail("{}: --token-fps {} does not match the {} fps its sidecar {} states", token_file.string(), f.rate_hz, s.fps,
         fs::path(token_file).replace_extension(".json").filename().string());
  out.rate_hz = s.fps;
  return out;
}

bool is_token_file(const fs::path& p) {
  const auto ext = p.extension().string();
  return (ext == ".npy" || ext == ".safetensors") && fs::is_regular_file(p);
}

namespace {

struct Raw {
  std::vector<int64_t> shape, values;
};

Raw read_raw(const fs::path& file) {
  Raw r;
  if (file.extension() == ".safetensors") {
    SafetensorsFile st(file);
    std::vector<std::string> ints;
    for (auto& n : st.names())
      if (is_integer(st.get(n).dtype)) ints.push_back(n);
    std::string name = st.contains("tokens") ? "tokens" : ints.size() == 1 ? ints[0] : "";
    if (name.empty())
      fail("{}: holds {} integer tensors and none is named 'tokens'; want one token tensor", file.string(), ints.size());
    const TensorView& v = st.get(name);
    if (!is_integer(v.dtype))
      fail("{}: tensor 'tokens' has dtype {}; token ids must be integers", file.string(), safetensors_name(v.dtype));
    r.shape = v.shape;
    r.values = integer_values(v.dtype, v.data, size_t(numel(v.shape)));
    return r;
  }
  NpyArray a = npy_read(file);
  if (!is_integer(a.dtype) || a.dtype == DType::BOOL)
    fail("{}: token array has dtype {}; token ids must be integers", file.string(), safetensors_name(a.dtype));
  r.shape = a.shape;
  r.values = a.to_int64();
  return r;
}

}  // namespace

TokenArray read_token_file(const fs::path& file, const TokenFormat& f) {
  if (!fs::exists(file)) fail("{}: no such token file", file.string());
  Raw r = read_raw(file);
  TokenArray t;
  if (r.shape.size() == 3) {
    t.h = r.shape[1];
    t.w = r.shape[2];
    if (f.grid_h > 0 && (f.grid_h != t.h || f.grid_w != t.w))
      fail("{}: a {}x{} token grid, but --grid says {}x{}", file.string(), t.h, t.w, f.grid_h, f.grid_w);
  } else if (r.shape.size() == 2) {
    if (f.grid_h < 1)
      fail("{}: a 2-D token array {} needs its grid stated (--grid HxW, e.g. 8x16 for 128 tokens a frame)", file.string(),
           shape_str(r.shape));
    if (f.grid_h * f.grid_w != r.shape[1])
      fail("{}: {} tokens a frame, but --grid {}x{} makes {}", file.string(), r.shape[1], f.grid_h, f.grid_w,
           f.grid_h * f.grid_w);
    t.h = f.grid_h;
    t.w = f.grid_w;
  } else {
    fail("{}: a token array must be [frames, h, w], or [frames, h*w] with --grid; got {}", file.string(),
         shape_str(r.shape));
  }
  const int64_t frames = r.shape[0], n = t.h * t.w;
  if (frames < 1 || n < 1) fail("{}: an empty token array {}", file.string(), shape_str(r.shape));
  // Ids are checked over the whole file, so the index named is the file's own, before any subsampling.
  const int64_t K = f.codebook_size > 0 ? f.codebook_size : std::numeric_limits<int32_t>::max();
  for (size_t i = 0; i < r.values.size(); ++i)
    if (r.values[i] < 0 || r.values[i] >= K) {
      const int64_t fr = int64_t(i) / n, pos = int64_t(i) % n;
      if (f.codebook_size > 0)
        fail("{}: token {} at frame {}, position {} (flat index {}) is outside [0, {}) (codebook size K = {})",
             file.string(), r.values[i], fr, pos, i, K, K);
      fail("{}: token {} at frame {}, position {} (flat index {}) is not a codebook index", file.string(), r.values[i],
           fr, pos, i);
    }
  const auto kept = f.kept_frames(frames, file);
  t.steps = int64_t(kept.size());
  t.ids.reserve(size_t(t.steps * n));
  for (int64_t i : kept)
    for (int64_t j = 0; j < n; ++j) t.ids.push_back(static_cast<int32_t>(r.values[size_t(i * n + j)]));
  return t;
}

TokenFormat TokenFormat::for_training(const fs::path& tokens, int64_t config_K) const {
  TokenFormat f = *this;
  if (f.codebook_size == 0 && !fs::exists(tokens / "dataset.json")) f.codebook_size = config_K;
  return f;
}

}  // namespace gaia::world
