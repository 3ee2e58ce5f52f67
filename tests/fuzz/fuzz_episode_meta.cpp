// Fuzz target: an episode's episode.json as Episode and Dataset::meta read it (read_json + EpisodeMeta::from_json),
// then a to_json/from_json round trip. Contract: only gaia::Error may escape; anything else is a bug.
#include <cstdint>

#include "fuzz_util.h"
#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/data/episode.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static gaia_fuzz::TempFile in("episode.json");
  gaia::data::EpisodeMeta m;
  std::string text;
  try {
    const auto& path = in.write(data, size);
    m = gaia::data::EpisodeMeta::from_json(gaia::read_json(path), path.string());
    text = m.to_json().dump(2);  // as EpisodeWriter::commit writes it
  } catch (const gaia::Error&) {
    return 0;
  }
  // Accepted metadata, written back, must read again to the same JSON.
  try {
    const auto again = gaia::data::EpisodeMeta::from_json(nlohmann::json::parse(text), "roundtrip");
    if (again.to_json().dump(2) != text) gaia_fuzz::property_failed("episode meta round trip", "JSON differs");
  } catch (const gaia::Error& e) {
    gaia_fuzz::property_failed("episode meta round trip", e.what());
  }
  return 0;
}
