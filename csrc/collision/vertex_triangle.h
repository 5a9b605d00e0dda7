// Vertex-triangle geometry for self-collision (paper §1: mass point vs triangle only): the closest
// point of a triangle and the continuous-time (linear motion) crossing test.
#pragma once
#include <Eigen/Geometry>
#include <algorithm>

#include "common/types.h"

namespace flagsim {

/// Barycentric coordinates (of a, b, c) of the point of triangle abc closest to p
/// (Voronoi-region walk, Ericson, Real-Time Collision Detection §5.1.5). `interior` is set to
/// true when the closest point lies strictly inside the face (so p - q is along the normal).
/// A degenerate (zero-area) triangle returns its vertex closest to p.
Vec3 closest_point_barycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                               bool& interior);

/// True when p is provably further than `gap` from triangle abc: outside the sphere around its
/// centroid that holds its corners, grown by gap. A cheap test before closest_point_barycentric.
bool beyond_reach(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, double gap);

/// Barycentric coordinates of the projection of p onto the plane of abc (may be outside [0,1]);
/// zero vector for a degenerate triangle.
Vec3 plane_barycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

/// Coefficients (c0, c1, c2, c3) of the cubic f(t) = ((b - a) x (c - a)) . (p - a) when every
/// point moves linearly from its *0 to its *1 position over t in [0, 1]. f(t) is twice the
/// triangle's area times p's signed distance to its plane: its roots are the coplanarity times.
Eigen::Vector4d coplanarity_cubic(const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0,
                                  const Vec3& p1, const Vec3& a1, const Vec3& b1, const Vec3& c1);

/// The roots in [0, 1] of the cubic k0 + k1 t + k2 t^2 + k3 t^3, ascending, into roots (at most
/// 3): [0, 1] is split where the derivative vanishes, and each monotone piece whose ends differ in
/// sign is refined by the Illinois method to 1e-13 in t. A cubic that is zero on a whole piece
/// (coplanar motion) reports that piece's start only.
int cubic_roots_in_unit_interval(const Eigen::Vector4d& k, double roots[3]);

/// Continuous vertex-triangle test under linear motion over the step (t in [0, 1]): the earliest
/// time at which p lies in the plane of abc and inside the triangle (barycentric coordinates
/// >= -1e-9). Roots of the coplanarity cubic are bracketed between the roots of its derivative
/// and refined by the Illinois method to 1e-13 in t. Returns false when p never meets the triangle.
/// On true, t_hit and bary (at t_hit) are written.
bool vertex_triangle_ccd(const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0,
                         const Vec3& p1, const Vec3& a1, const Vec3& b1, const Vec3& c1,
                         double& t_hit, Vec3& bary);

/// For a vertex that meets triangle abc at t_hit (from vertex_triangle_ccd): the latest time in
/// [0, t_hit] at which p is still min(gap, d(0)) from the triangle's plane on the side it started
/// on, d(t) being that signed distance, found by bisection (1e-9 in t); 0 if it starts on the
/// plane. Moving every point back to that time stops the vertex short of the triangle.
double separation_time(const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0,
                       const Vec3& p1, const Vec3& a1, const Vec3& b1, const Vec3& c1, double t_hit,
                       double gap);

/// The last time in [0, t_hit] at which a signed distance d(t) (d(0) != 0 fixes the side) is still
/// at least min(gap, |d(0)|) on its starting side: bisection to 1e-9, assuming d(t_hit) is past
/// it. Shared by the vertex-triangle and edge-edge responses, which stop a pair short of its hit.
template <class Distance>
double stop_short_time(const Distance& distance, double t_hit, double gap) {
  const double d0 = distance(0.0);
  if (d0 == 0) return 0.0;
  const double side = d0 > 0 ? 1.0 : -1.0;
  const double target = std::min(gap, side * d0);
  double lo = 0, hi = t_hit;  // side * d(lo) >= target > side * d(hi)
  if (side * distance(hi) >= target) return hi;
  while (hi - lo > 1e-9) {
    const double mid = 0.5 * (lo + hi);
    (side * distance(mid) >= target ? lo : hi) = mid;
  }
  return lo;
}

}  // namespace flagsim
