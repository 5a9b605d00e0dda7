#include "common/keyframes.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"

namespace flagsim {

Vec3 WindSchedule::at(double t) const {
  if (keys.empty()) return Vec3::Zero();
  if (t <= keys.front().time) return keys.front().velocity;
  if (t >= keys.back().time) return keys.back().velocity;
  auto hi = std::upper_bound(keys.begin(), keys.end(), t,
                             [](double x, const WindKey& k) { return x < k.time; });
  auto lo = hi - 1;
  const double s = (t - lo->time) / (hi->time - lo->time);
  return (1 - s) * lo->velocity + s * hi->velocity;
}

bool WindSchedule::constant() const {
  for (const auto& k : keys)
    if (k.velocity != keys.front().velocity) return false;
  return true;
}

double WindSchedule::max_speed() const {
  double m = 0;
  for (const auto& k : keys) m = std::max(m, k.velocity.norm());
  return m;
}

void WindSchedule::validate(const std::string& name) const {
  for (size_t i = 0; i < keys.size(); ++i) {
    check_finite(name + "[" + std::to_string(i) + "].time", keys[i].time);
    check_finite_vec(name + "[" + std::to_string(i) + "].velocity", keys[i].velocity);
    if (i > 0 && !(keys[i].time > keys[i - 1].time))
      fail_param(name + "[" + std::to_string(i) + "].time",
                 "> the previous key's time " + detail::to_text(keys[i - 1].time), keys[i].time);
  }
}

double ScalarSchedule::at(double t, double fallback) const {
  if (keys.empty()) return fallback;
  if (t <= keys.front().first) return keys.front().second;
  if (t >= keys.back().first) return keys.back().second;
  auto hi =
      std::upper_bound(keys.begin(), keys.end(), t,
                       [](double x, const std::pair<double, double>& k) { return x < k.first; });
  auto lo = hi - 1;
  const double s = (t - lo->first) / (hi->first - lo->first);
  return (1 - s) * lo->second + s * hi->second;
}

double ScalarSchedule::integral(double t, double fallback) const {
  if (t < 0) return -integral_from(t, 0.0, fallback);
  return integral_from(0.0, t, fallback);
}

// a <= b: the constant ends outside the keys plus the trapezoids of the pieces overlapping [a, b].
double ScalarSchedule::integral_from(double a, double b, double fallback) const {
  if (keys.empty()) return fallback * (b - a);
  double sum = 0;
  const double t0 = keys.front().first, t1 = keys.back().first;
  if (a < t0) sum += keys.front().second * (std::min(b, t0) - a);
  if (b > t1) sum += keys.back().second * (b - std::max(a, t1));
  for (size_t i = 0; i + 1 < keys.size(); ++i) {
    const double lo = std::max(a, keys[i].first), hi = std::min(b, keys[i + 1].first);
    if (hi > lo) sum += 0.5 * (at(lo) + at(hi)) * (hi - lo);
  }
  return sum;
}

void ScalarSchedule::validate(const std::string& name) const {
  for (size_t i = 0; i < keys.size(); ++i) {
    check_finite(name + "[" + std::to_string(i) + "].time", keys[i].first);
    check_finite(name + "[" + std::to_string(i) + "].value", keys[i].second);
    if (i > 0 && !(keys[i].first > keys[i - 1].first))
      fail_param(name + "[" + std::to_string(i) + "].time",
                 "> the previous key's time " + detail::to_text(keys[i - 1].first), keys[i].first);
  }
}

Pose MotionSchedule::at(double t) const {
  Pose pose;
  if (keys.empty()) return pose;
  const double t0 = keys.front().time, t1 = keys.back().time;
  if (repeat && t1 > t0 && (t < t0 || t > t1))
    t = t0 + (t - t0) - (t1 - t0) * std::floor((t - t0) / (t1 - t0));
  Vec3 move = keys.front().translation, rot = keys.front().rotation;
  if (t >= t1) {
    move = keys.back().translation, rot = keys.back().rotation;
  } else if (t > t0) {
    auto hi = std::upper_bound(keys.begin(), keys.end(), t,
                               [](double x, const MotionKey& k) { return x < k.time; });
    auto lo = hi - 1;
    const double s = (t - lo->time) / (hi->time - lo->time);
    move = (1 - s) * lo->translation + s * hi->translation;
    rot = (1 - s) * lo->rotation + s * hi->rotation;
  }
  const double angle = rot.norm() * (3.14159265358979323846 / 180.0);
  if (angle > 0) pose.R = Eigen::AngleAxisd(angle, rot.normalized()).toRotationMatrix();
  pose.t = pivot + move - pose.R * pivot;
  return pose;
}

CarriedSpeeds carried_speeds(const WindSchedule& wind, const MotionSchedule& motion,
                             const Vec3& p) {
  CarriedSpeeds out;
  std::vector<double> times{0.0};
  bool repeats = false;
  for (const WindKey& k : wind.keys) times.push_back(k.time);
  const double last_wind = wind.keys.empty() ? 0.0 : wind.keys.back().time;
  if (!motion.empty()) {
    const double t0 = motion.keys.front().time, t1 = motion.keys.back().time, period = t1 - t0;
    if (motion.repeat && period > 0) {
      repeats = true;
      const double end = std::max({last_wind, t1, 0.0}) + period;
      const double first = std::floor((0.0 - t0) / period);
      const double periods =
          std::min(std::ceil((end - t0) / period) - first, double(CarriedSpeeds::kMaxPeriods));
      for (double n = first; n <= first + periods; ++n)
        for (const MotionKey& k : motion.keys) times.push_back(k.time + n * period);
    } else {
      for (const MotionKey& k : motion.keys) times.push_back(k.time);
    }
  }
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  times.erase(times.begin(), std::lower_bound(times.begin(), times.end(), 0.0));
  const auto at = [&](double t) { return motion.at(t).apply(p); };
  for (std::size_t k = 0; k + 1 < times.size(); ++k) {
    const double a = times[k], len = (times[k + 1] - a) / CarriedSpeeds::kParts;
    for (int j = 0; j < CarriedSpeeds::kParts; ++j) {
      const double s0 = a + j * len, q0 = s0 + 0.25 * len, q1 = s0 + 0.75 * len;
      const Vec3 v = (at(q1) - at(q0)) / (q1 - q0);
      out.own = std::max(out.own, v.norm());
      out.relative =
          std::max({out.relative, (wind.at(s0) - v).norm(), (wind.at(s0 + len) - v).norm()});
    }
  }
  // After the last time the wind holds, and so does a motion that does not repeat (one that
  // does plays the last period again, against the same wind).
  if (!repeats) out.relative = std::max(out.relative, wind.at(times.back()).norm());
  return out;
}

void MotionSchedule::validate(const std::string& name) const {
  check_position(name + ".pivot", pivot);
  for (size_t i = 0; i < keys.size(); ++i) {
    const std::string k = name + ".keys[" + std::to_string(i) + "]";
    check_finite(k + ".time", keys[i].time);
    check_position(k + ".translation", keys[i].translation);
    check_finite_vec(k + ".rotation", keys[i].rotation);
    if (i > 0 && !(keys[i].time > keys[i - 1].time))
      fail_param(k + ".time", "> the previous key's time " + detail::to_text(keys[i - 1].time),
                 keys[i].time);
  }
}

}  // namespace flagsim
