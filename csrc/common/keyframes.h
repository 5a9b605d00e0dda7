// Piecewise-linear keyframe schedules: wind velocity (time -> m/s vector) and scalar strengths.
// Before the first key the first value holds, after the last key the last value holds.
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "common/types.h"

namespace flagsim {

struct WindKey {
  double time = 0;         ///< s
  Vec3 velocity{0, 0, 0};  ///< m/s
};

/// Velocity schedule; empty means zero. Keys must have strictly increasing times.
struct WindSchedule {
  std::vector<WindKey> keys;

  WindSchedule() = default;
  explicit WindSchedule(const Vec3& constant) : keys{{0.0, constant}} {}
  Vec3 at(double t) const;
  bool constant() const;     ///< true when every key has the same velocity (or there are none)
  double max_speed() const;  ///< max |velocity| over keys, m/s
  void validate(const std::string& name) const;
};

/// Scalar schedule (time, value); empty means `fallback`.
struct ScalarSchedule {
  std::vector<std::pair<double, double>> keys;
  double at(double t, double fallback = 1.0) const;
  /// Integral of at(., fallback) from 0 to t (exact for the piecewise-linear schedule; negative
  /// for t < 0).
  double integral(double t, double fallback = 1.0) const;
  void validate(const std::string& name) const;

 private:
  double integral_from(double a, double b, double fallback) const;
};

}  // namespace flagsim
