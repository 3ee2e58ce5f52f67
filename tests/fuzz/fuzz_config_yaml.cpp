// Fuzz target: Config::apply_yaml then validate() on arbitrary text, and a to_yaml/apply_yaml round trip.
// Contract: only gaia::Error may escape the parser; a crash, sanitizer report or other exception is a bug.
#include <cstdint>
#include <string>

#include "fuzz_util.h"
#include "gaia/config.h"
#include "gaia/core/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::string yaml;
  try {
    gaia::Config c;
    c.apply_yaml(text, "fuzz.yaml");
    c.validate();
    yaml = c.to_yaml();
  } catch (const gaia::Error&) {
    return 0;
  }
  // A config that validated, saved and loaded again, must validate and save to the same text.
  try {
    gaia::Config d;
    d.apply_yaml(yaml, "roundtrip.yaml");
    d.validate();
    if (d.to_yaml() != yaml) gaia_fuzz::property_failed("config round trip", "to_yaml differs after reload");
  } catch (const gaia::Error& e) {
    gaia_fuzz::property_failed("config round trip", e.what());
  }
  return 0;
}
