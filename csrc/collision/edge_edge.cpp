#include "collision/edge_edge.h"

#include <algorithm>
#include <cmath>

#include "collision/vertex_triangle.h"

namespace flagsim {

Vec2 closest_segment_parameters(const Vec3& p1, const Vec3& p2, const Vec3& q1, const Vec3& q2) {
  const Vec3 d1 = p2 - p1, d2 = q2 - q1, r = p1 - q1;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  if (!(a > 0) && !(e > 0)) return {0, 0};
  if (!(a > 0)) return {0, std::clamp(f / e, 0.0, 1.0)};
  const double c = d1.dot(r);
  if (!(e > 0)) return {std::clamp(-c / a, 0.0, 1.0), 0};
  const double b = d1.dot(d2), denom = a * e - b * b;
  // Closest point on the infinite lines, clamped to the first segment (any s if parallel)...
  double s = denom > 0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
  // ...then the second segment's point for it, re-clamping s when u leaves [0, 1].
  double u = (b * s + f) / e;
  if (u < 0) {
    u = 0;
    s = std::clamp(-c / a, 0.0, 1.0);
  } else if (u > 1) {
    u = 1;
    s = std::clamp((b - c) / a, 0.0, 1.0);
  }
  return {s, u};
}

bool edge_edge_ccd(const Vec3& p1_0, const Vec3& p2_0, const Vec3& q1_0, const Vec3& q2_0,
                   const Vec3& p1_1, const Vec3& p2_1, const Vec3& q1_1, const Vec3& q2_1,
                   double& t_hit, Vec2& su) {
  // Quick rejection: the edges' midpoints never come within the sum of their half-lengths
  // (half-lengths are convex in t, so bounded by their values at the ends).
  {
    const Vec3 m0 = 0.5 * (p1_0 + p2_0) - 0.5 * (q1_0 + q2_0);
    const Vec3 dm = 0.5 * (p1_1 + p2_1) - 0.5 * (q1_1 + q2_1) - m0;
    const double reach = 0.5 * std::max((p2_0 - p1_0).norm(), (p2_1 - p1_1).norm()) +
                         0.5 * std::max((q2_0 - q1_0).norm(), (q2_1 - q1_1).norm());
    const double dd = dm.squaredNorm();
    const double s = dd > 0 ? std::clamp(-m0.dot(dm) / dd, 0.0, 1.0) : 0.0;
    if ((m0 + s * dm).squaredNorm() > reach * reach * (1 + 1e-9)) return false;
  }
  // ((p2 - p1) x (q2 - q1)) . (q1 - p1) is the coplanarity cubic of "vertex" q1 against the
  // "triangle" (p1, p2, p1 + q2 - q1), every point moving linearly.
  const Eigen::Vector4d k =
      coplanarity_cubic(q1_0, p1_0, p2_0, p1_0 + q2_0 - q1_0, q1_1, p1_1, p2_1, p1_1 + q2_1 - q1_1);
  double roots[3];
  const int n = cubic_roots_in_unit_interval(k, roots);
  for (int i = 0; i < n; ++i) {
    const double t = roots[i];
    const Vec3 p1 = p1_0 + t * (p1_1 - p1_0), p2 = p2_0 + t * (p2_1 - p2_0);
    const Vec3 q1 = q1_0 + t * (q1_1 - q1_0), q2 = q2_0 + t * (q2_1 - q2_0);
    const Vec3 d1 = p2 - p1, d2 = q2 - q1;
    const double scale = d1.norm() + d2.norm();
    if (!(d1.cross(d2).norm() > 1e-9 * scale * scale)) continue;  // parallel: no crossing
    const Vec2 w = closest_segment_parameters(p1, p2, q1, q2);
    const double gap = ((p1 + w[0] * d1) - (q1 + w[1] * d2)).norm();
    if (gap <= 1e-9 * scale && w.minCoeff() > 0 && w.maxCoeff() < 1) {  // ends: vertex-triangle
      t_hit = t;
      su = w;
      return true;
    }
  }
  return false;
}

double edge_separation_time(const Vec3& p1_0, const Vec3& p2_0, const Vec3& q1_0, const Vec3& q2_0,
                            const Vec3& p1_1, const Vec3& p2_1, const Vec3& q1_1, const Vec3& q2_1,
                            double t_hit, double gap) {
  auto distance = [&](double t) {  // signed distance between the two lines at time t
    const Vec3 p1 = p1_0 + t * (p1_1 - p1_0), q1 = q1_0 + t * (q1_1 - q1_0);
    const Vec3 n = (p2_0 + t * (p2_1 - p2_0) - p1).cross(q2_0 + t * (q2_1 - q2_0) - q1);
    const double len = n.norm();
    return len > 0 ? n.dot(q1 - p1) / len : 0.0;
  };
  return stop_short_time(distance, t_hit, gap);
}

}  // namespace flagsim
