#pragma once
// Constants that many files need, defined once (a unity build compiles several files as one).
#include <limits>

namespace gaia {

inline constexpr double kPi = 3.14159265358979323846;
// A value that was not measured (signals, tracks and poses store NaN where a sample is missing).
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace gaia
