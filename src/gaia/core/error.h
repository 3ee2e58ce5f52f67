#pragma once
// One exception type for every user-facing failure. The message is a single line that names the file
// (and line / field) at fault; the app prints it as "gaia: error: <message>" and exits non-zero.
#include <stdexcept>
#include <string>

#include <fmt/format.h>

namespace gaia {

struct Error : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// fail("{}: field '{}' must be positive", path, key) -> throws gaia::Error with the formatted line.
template <typename... Args>
[[noreturn]] void fail(fmt::format_string<Args...> f, Args&&... args) {
  throw Error(fmt::format(f, std::forward<Args>(args)...));
}

}  // namespace gaia
