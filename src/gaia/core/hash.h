#pragma once
// FNV-1a 64 over a string: stable across platforms and runs, unlike std::hash (seeded splits, caption wording).
#include <cstdint>
#include <string_view>

namespace gaia {

inline constexpr uint64_t kFnvBasis = 1469598103934665603ull;

inline uint64_t fnv1a(std::string_view s, uint64_t h = kFnvBasis) {
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
  return h;
}

}  // namespace gaia
