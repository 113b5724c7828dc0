// The fitter's NaN (a quantity not computed) and its short numbers in messages and warnings.
#pragma once
#include <limits>
#include <sstream>
#include <string>

namespace demfit {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// v with `digits` significant digits, as a stream writes it ("0.123", "1.5e-07"): for messages
/// and the warnings the fit tables carry.
inline std::string fmt(double v, int digits = 3) {
  std::ostringstream o;
  o.precision(digits);
  o << v;
  return o.str();
}

}  // namespace demfit
