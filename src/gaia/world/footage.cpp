#include "gaia/world/footage.h"

#include "gaia/core/error.h"

namespace gaia::world {

Footage parse_footage(const std::string& s) {
  if (s == "any") return Footage::kAny;
  if (s == "real") return Footage::kReal;
  if (s == "procedural") return Footage::kProcedural;
  fail("footage '{}': expected any, real or procedural", s);
}

std::string to_string(Footage f) {
  return f == Footage::kReal ? "real" : f == Footage::kProcedural ? "procedural" : "any";
}

bool footage_matches(bool procedural, Footage f) {
  return f == Footage::kAny || procedural == (f == Footage::kProcedural);
}

bool footage_matches(const TokenDataset& ds, size_t e, Footage f) {
  return footage_matches(ds.meta(e).is_procedural(), f);
}

std::vector<size_t> with_footage(const TokenDataset& ds, const std::vector<size_t>& episodes, Footage f) {
  std::vector<size_t> out;
  for (size_t e : episodes)
    if (footage_matches(ds, e, f)) out.push_back(e);
  return out;
}

}  // namespace gaia::world
