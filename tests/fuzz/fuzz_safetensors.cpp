// Fuzz target: SafetensorsFile on arbitrary bytes, every accessor on what it accepts, and a write/read round trip.
// Contract: only gaia::Error may escape the parser; a crash, sanitizer report or other exception is a bug.
#include <cstdint>

#include "fuzz_util.h"
#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static gaia_fuzz::TempFile in("in.safetensors"), again("again.safetensors");
  std::vector<std::string> names;
  std::string bytes;
  try {
    gaia::SafetensorsFile f(in.write(data, size));
    names = f.names();
    volatile uint64_t sink = 0;
    gaia::SafetensorsWriter w;
    for (const auto& [k, v] : f.metadata()) w.set_metadata(k, v);
    for (const auto& name : names) {
      const gaia::TensorView& t = f.get(name);
      if (t.nbytes) sink = sink + t.data[0] + t.data[t.nbytes - 1];  // the view must lie inside the mapping
      const bool is_float = t.dtype == gaia::DType::F32 || t.dtype == gaia::DType::F64 ||
                            t.dtype == gaia::DType::F16 || t.dtype == gaia::DType::BF16;
      if (is_float) sink = sink + f.to_float(name).size();
      w.add(name, t.dtype, t.shape, t.data, t.nbytes);
    }
    bytes = w.serialize();
  } catch (const gaia::Error&) {
    return 0;
  }
  // What the reader accepted, written back, must read again with the same tensors.
  try {
    if (gaia::SafetensorsFile(again.write(bytes.data(), bytes.size())).names() != names)
      gaia_fuzz::property_failed("safetensors round trip", "tensor names differ");
  } catch (const gaia::Error& e) {
    gaia_fuzz::property_failed("safetensors round trip", e.what());
  }
  return 0;
}
