// Error types and boundary validation helpers. Validate at the boundary, trust inside.
#pragma once
#include <charconv>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "common/types.h"

namespace flagsim {

/// Invalid input (a parameter out of range, not finite, an unknown name). Python: ValueError.
class InvalidArgument : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/// A required optional component (e.g. FFTW) was not compiled in. Python: ValueError.
class MissingFeature : public InvalidArgument {
 public:
  using InvalidArgument::InvalidArgument;
};

/// A step produced a non-finite state or an unbounded strain. The state is rolled back to the
/// start of the failed step before this is thrown. Python: flagsim.DivergenceError.
class DivergenceError : public std::runtime_error {
 public:
  DivergenceError(const std::string& what, long step, double time, long vertex, std::string cause)
      : std::runtime_error(what), step(step), time(time), vertex(vertex), cause(std::move(cause)) {}
  long step;          ///< step_count at the start of the failed step
  double time;        ///< simulated time at the start of the failed step, s
  long vertex;        ///< worst vertex, or -1
  std::string cause;  ///< "non-finite", "strain", "cg", ...
};

namespace detail {
/// The value as text; floating-point values in their shortest form that reads back exactly.
template <class T>
std::string to_text(const T& v) {
  if constexpr (std::is_floating_point_v<T>) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
  } else {
    std::ostringstream s;
    s.precision(17);
    s << v;
    return s.str();
  }
}
}  // namespace detail

/// Throws InvalidArgument "<name> should be <expected>, got <value>".
template <class T>
[[noreturn]] void fail_param(const std::string& name, const std::string& expected, const T& got) {
  throw InvalidArgument(name + " should be " + expected + ", got " + detail::to_text(got));
}

inline void check_finite(const std::string& name, double v) {
  if (!std::isfinite(v)) fail_param(name, "a finite number", v);
}
inline void check_positive(const std::string& name, double v) {
  if (!(std::isfinite(v) && v > 0)) fail_param(name, "finite and > 0", v);
}
inline void check_nonnegative(const std::string& name, double v) {
  if (!(std::isfinite(v) && v >= 0)) fail_param(name, "finite and >= 0", v);
}
inline void check_range(const std::string& name, double v, double lo, double hi) {
  if (!(std::isfinite(v) && v >= lo && v <= hi))
    fail_param(name, "in [" + detail::to_text(lo) + ", " + detail::to_text(hi) + "]", v);
}
/// "(a, b, c)" with each component in its shortest exact form.
template <class V>
std::string vec_text(const V& v) {
  std::string s = "(";
  for (Eigen::Index i = 0; i < v.size(); ++i) s += (i ? ", " : "") + detail::to_text(double(v[i]));
  return s + ")";
}

template <class V>
void check_finite_vec(const std::string& name, const V& v) {
  for (Eigen::Index i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) fail_param(name, "finite", vec_text(v));
}

/// Positions and lengths in a scene, m: a 2,000 km cube about the origin. Far beyond any flag,
/// and it keeps coordinates, their squares and the exported text well inside double range.
constexpr double kMaxCoordinate = 1e6;

/// A length: finite, > 0 and at most kMaxCoordinate.
inline void check_length(const std::string& name, double v) {
  if (!(std::isfinite(v) && v > 0 && v <= kMaxCoordinate))
    fail_param(name, "in (0, " + detail::to_text(kMaxCoordinate) + "] m", v);
}
/// A position: every component finite and within +-kMaxCoordinate.
template <class V>
void check_position(const std::string& name, const V& v) {
  check_finite_vec(name, v);
  for (Eigen::Index i = 0; i < v.size(); ++i)
    if (std::fabs(v[i]) > kMaxCoordinate) {
      std::ostringstream s;
      s << "(" << v.transpose() << ")";
      fail_param(name,
                 "within " + detail::to_text(kMaxCoordinate) + " m of the origin in each component",
                 s.str());
    }
}

}  // namespace flagsim
