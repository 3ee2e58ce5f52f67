#include "gaia/core/interpolate.h"

#include <cmath>

#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"

namespace gaia {

namespace {
bool is_float(DType d) { return d == DType::F32 || d == DType::F16 || d == DType::BF16 || d == DType::F64; }
}  // namespace

void interpolate_weights(const fs::path& base, const fs::path& tuned, double alpha, const fs::path& out) {
  if (!std::isfinite(alpha)) fail("interpolate: alpha must be a finite number, got {}", alpha);
  SafetensorsWriter w;
  {
    SafetensorsFile a(base), b(tuned);
    for (const auto& [k, v] : b.metadata()) w.set_metadata(k, v);
    for (const auto& name : a.names())
      if (!b.contains(name)) fail("{}: has tensor '{}' that {} does not", base.string(), name, tuned.string());
    for (const auto& name : b.names()) {
      if (!a.contains(name)) fail("{}: has tensor '{}' that {} does not", tuned.string(), name, base.string());
      const TensorView &ta = a.get(name), &tb = b.get(name);
      if (ta.shape != tb.shape) fail("{}: tensor '{}' has another shape than in {}", tuned.string(), name, base.string());
      if (!is_float(tb.dtype) || !is_float(ta.dtype)) {
        w.add(name, tb.dtype, tb.shape, tb.data, tb.nbytes);
        continue;
      }
      const std::vector<float> va = a.to_float(name), vb = b.to_float(name);
      std::vector<float> v(vb.size());
      for (size_t i = 0; i < v.size(); ++i) {
        v[i] = static_cast<float>(va[i] + alpha * (double(vb[i]) - va[i]));
        if (!std::isfinite(v[i])) fail("{}: tensor '{}' holds a non-finite value", tuned.string(), name);
      }
      w.add_f32(name, tb.shape, v);
    }
  }  // both mappings are closed before the output (possibly an input's path) is renamed into place
  w.write(out);
}

}  // namespace gaia
