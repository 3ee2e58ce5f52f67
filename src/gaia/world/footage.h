#pragma once
// Which episodes of a token dataset a measure reads: recorded camera footage, procedural drives (gaia synth), or
// both. A dataset of both measures each apart (gaia world eval --footage, gaia eval --prompt-footage).
#include <cstddef>
#include <string>
#include <vector>

#include "gaia/world/token_dataset.h"

namespace gaia::world {

enum class Footage { kAny, kReal, kProcedural };
Footage parse_footage(const std::string& s);  // "any" | "real" | "procedural"; fails naming the value otherwise
std::string to_string(Footage f);
bool footage_matches(bool procedural, Footage f);  // an episode procedural or recorded
bool footage_matches(const TokenDataset& ds, size_t e, Footage f);
// The episodes of `episodes` that match `f`, in order.
std::vector<size_t> with_footage(const TokenDataset& ds, const std::vector<size_t>& episodes, Footage f);

}  // namespace gaia::world
