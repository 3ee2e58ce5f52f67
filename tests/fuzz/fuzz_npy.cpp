// Fuzz target: npy_read on arbitrary bytes, the value conversions, and a write/read round trip.
// Contract: only gaia::Error may escape the parser; a crash, sanitizer report or other exception is a bug.
#include <cstdint>

#include "fuzz_util.h"
#include "gaia/core/error.h"
#include "gaia/core/npy.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static gaia_fuzz::TempFile in("in.npy"), again("again.npy");
  gaia::NpyArray a;
  try {
    a = gaia::npy_read(in.write(data, size));
    volatile size_t sink = a.to_double().size();  // integer dtypes go through to_int64
    (void)sink;
  } catch (const gaia::Error&) {
    return 0;
  }
  // An accepted array, written back, must read again with the same dtype, shape and bytes.
  try {
    gaia::npy_write(again.path(), a);
    const gaia::NpyArray b = gaia::npy_read(again.path());
    if (b.dtype != a.dtype || b.shape != a.shape || b.bytes != a.bytes)
      gaia_fuzz::property_failed("npy round trip", "array differs");
  } catch (const gaia::Error& e) {
    gaia_fuzz::property_failed("npy round trip", e.what());
  }
  return 0;
}
