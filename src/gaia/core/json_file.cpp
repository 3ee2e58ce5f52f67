#include "gaia/core/json_file.h"

#include "gaia/core/error.h"
#include "gaia/core/fs.h"

namespace gaia {

nlohmann::json read_json(const fs::path& path) {
  const std::string text = read_file(path);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    fail("{}: invalid JSON ({})", path.string(), e.what());
  }
}

}  // namespace gaia
