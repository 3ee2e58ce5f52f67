#pragma once
// Token arrays made by other tokenizers (docs/formats.md, "Token files from other tokenizers"): a .npy or a
// .safetensors file of any integer dtype, shaped [frames, h, w], or [frames, h*w] with the grid stated.
// e.g. commaVQ: [1200, 128] int16 or int64, an 8x16 grid, K = 1024, 20 fps.
//
//   TokenFormat      what the file cannot say itself: grid, codebook size K, frame rate
//   read_token_file  the checked ids, subsampled from the file's rate to the world model's (§2.3: 6.25 Hz)
#include <cstdint>
#include <string>
#include <vector>

#include "gaia/core/fs.h"
#include "gaia/data/episode.h"

namespace gaia::world {

struct TokenFormat {
  int64_t grid_h = 0, grid_w = 0;  // --grid HxW: needed for a 2-D array, checked against a 3-D one; 0 = unstated
  int64_t codebook_size = 0;       // K: ids outside [0, K) fail naming the file and the first bad index; 0 = unstated
  double rate_hz = 0;              // --token-fps: the file's frame rate; 0 = already at the world model's rate
  double world_rate_hz = 6.25;     // §2.3: the world model's rate, the one rate_hz is subsampled to
  bool keep_rate = false;          // --keep-rate: train at the file's own rate instead
  double val_fraction = 0.1;       // a single file: the last tenth of its steps is held out for validation

  bool stated() const { return grid_h > 0 || codebook_size > 0 || rate_hz > 0 || keep_rate; }
  // "8x16" -> grid; fails naming `flag` on anything else.
  void set_grid(const std::string& text, const std::string& flag = "--grid");
  // The steps this format keeps of `frames` at rate_hz: every (rate_hz / world_rate_hz)-th, rounded to the
  // nearest frame. Fails naming `file` when the file's rate is below the world model's (unless keep_rate).
  std::vector<int64_t> kept_frames(int64_t frames, const fs::path& file) const;
  double dataset_rate_hz() const;  // the rate of the steps kept
  // The format for training on `tokens` with a config whose codebook holds `config_K` codes: gaia tokenize's datasets
  // state K in dataset.json; other tokenizers' files take it from this format or the config, never from their
  // largest id.
  TokenFormat for_training(const fs::path& tokens, int64_t config_K) const;
};

struct TokenArray {
  int64_t steps = 0, h = 0, w = 0;
  std::vector<int32_t> ids;  // [steps, h, w] row-major, each in [0, K)
};

bool is_token_file(const fs::path& p);  // a .npy or .safetensors file

// What a token file cannot say about its drive, from an optional sidecar X.json beside X.npy: "latitude" and
// "longitude" (for the geofenced split and balancing), "weather", "time_of_day", and "fps", the file's frame rate.
// Any other key is an error naming the sidecar. No sidecar: an empty record.
struct TokenSidecar {
  data::EpisodeMeta meta;  // id = the file's stem; the fields above where given
  double fps = 0;          // 0 = not given
};
TokenSidecar read_token_sidecar(const fs::path& token_file);
// `f` for one file: its sidecar's fps becomes the rate (--token-fps need not be given); a stated --token-fps that
// disagrees with the sidecar by more than 1% is an error naming both.
TokenFormat file_format(const TokenFormat& f, const TokenSidecar& s, const fs::path& token_file);

// Reads, reshapes, subsamples and checks one file (ids >= 0 always; < K when K is stated). A safetensors file
// holds one integer tensor, or one named "tokens".
TokenArray read_token_file(const fs::path& file, const TokenFormat& f);

}  // namespace gaia::world
