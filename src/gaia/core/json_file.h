#pragma once
// Reading a JSON file with the error every command promises: one line naming the file, whether it is missing,
// unreadable or not JSON (a bare parse exception would name neither the file nor the field).
#include <filesystem>

#include <nlohmann/json.hpp>

namespace gaia {

// The parsed file; throws gaia::Error "<path>: invalid JSON (...)" or read_file's "<path>: cannot open file".
nlohmann::json read_json(const std::filesystem::path& path);

}  // namespace gaia
