// Piecewise-linear keyframe schedules: wind velocity (time -> m/s vector), scalar strengths, and
// rigid motions (time -> translation and rotation) that move pins, poles and solids.
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

/// A rigid placement: world = R p + t.
struct Pose {
  Mat3 R = Mat3::Identity();
  Vec3 t = Vec3::Zero();
  Vec3 apply(const Vec3& p) const { return R * p + t; }
  Vec3 inverse(const Vec3& q) const { return R.transpose() * (q - t); }
};

/// A pose over a piece of h seconds, from `from` (its start) to `to` (its end): a point fixed in
/// the moving body goes from from.apply(p) to to.apply(p) with the secant velocity.
struct RigidMotion {
  Pose from, to;
  double h = 1.0;  ///< s
  Vec3 velocity_at(const Vec3& local) const { return (to.apply(local) - from.apply(local)) / h; }
};

struct MotionKey {
  double time = 0;            ///< s
  Vec3 translation{0, 0, 0};  ///< m
  Vec3 rotation{0, 0, 0};     ///< degrees: a rotation vector (unit axis x angle) about `pivot`
};

/// Rigid motion keyframes: pose(t) maps a point p of the body at rest to
/// pivot + translation(t) + R(rotation(t)) (p - pivot), translation and rotation vector each
/// interpolated linearly between keys (a rotation about one fixed axis is then exact). Before the
/// first key the first pose holds, after the last key the last (or, with `repeat`, the keys play
/// again from the first with period last time - first time). Empty: no motion (identity).
struct MotionSchedule {
  std::vector<MotionKey> keys;
  Vec3 pivot{0, 0, 0};  ///< m
  bool repeat = false;
  bool empty() const { return keys.empty(); }
  Pose at(double t) const;
  /// Keys strictly increasing in time, finite. (`repeat` with fewer than two keys has no period
  /// and holds the one pose: not an error, so that fields can be set in any order.)
  void validate(const std::string& name) const;
};

/// The largest speeds, m/s, over t >= 0 of a point p (m, in the body at rest) carried by
/// `motion` through `wind`: `relative` = max |wind(t) - v(t)|, `own` = max |v(t)|, v the point's
/// velocity. The pieces between the keys of both schedules are cut in kParts, each with the
/// point's secant velocity (taken between its quarter points, so a repeat's jump back is never
/// straddled) against the wind at its ends: exact for a translation (|w - v| is convex where w
/// is linear and v constant); a rotation is sampled at that resolution. A repeating motion is
/// followed up to one period past the wind's last key (at most kMaxPeriods periods).
struct CarriedSpeeds {
  static constexpr int kParts = 8;
  static constexpr long kMaxPeriods = 1000;
  double relative = 0, own = 0;
};
CarriedSpeeds carried_speeds(const WindSchedule& wind, const MotionSchedule& motion, const Vec3& p);

}  // namespace flagsim
