// Independent checks for self-collision tests, written without the library's collision code:
// crossings found by sampling the linear motion of each (vertex, non-incident triangle) pair, and
// brute-force vertex-triangle distances by projection and edge distances.
#pragma once
#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>

#include "common/types.h"

namespace flagsim::test_support {

inline Vec3 at(const MatX3& x0, const MatX3& x1, Index i, double t) {
  return (1 - t) * x0.row(i).transpose() + t * x1.row(i).transpose();
}

// Signed distance of p to the plane of abc, or NaN for a degenerate triangle.
inline double plane_distance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double len = n.norm();
  return len > 0 ? n.dot(p - a) / len : std::numeric_limits<double>::quiet_NaN();
}

// True when p's projection lies inside abc (inclusive, with a relative tolerance).
inline bool projects_inside(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                            double tol = 1e-9) {
  const Vec3 n = (b - a).cross(c - a);
  const double nn = n.squaredNorm();
  if (!(nn > 0)) return false;
  const double wa = (b - p).cross(c - p).dot(n) / nn;
  const double wb = (c - p).cross(a - p).dot(n) / nn;
  const double wc = 1 - wa - wb;
  return wa >= -tol && wb >= -tol && wc >= -tol;
}

// Number of (vertex, triangle) pairs, the vertex not in the triangle, where the vertex passes
// through the triangle while all points move linearly from x0 to x1. Sign changes of the plane
// distance are found on `samples` sub-intervals and located by bisection.
inline long count_crossings(const MatX3& x0, const MatX3& x1, const MatX3i& tris,
                            int samples = 32) {
  const Index N = x0.rows();
  long crossings = 0;
  for (Index t = 0; t < tris.rows(); ++t) {
    const Index a = tris(t, 0), b = tris(t, 1), c = tris(t, 2);
    Vec3 lo = x0.row(a).transpose(), hi = lo;
    for (Index k : {a, b, c})
      for (const MatX3* x : {&x0, &x1}) {
        lo = lo.cwiseMin(x->row(k).transpose());
        hi = hi.cwiseMax(x->row(k).transpose());
      }
    for (Index v = 0; v < N; ++v) {
      if (v == a || v == b || v == c) continue;
      const Vec3 p0 = x0.row(v).transpose(), p1 = x1.row(v).transpose();
      if ((p0.cwiseMax(p1).array() < lo.array()).any() ||
          (p0.cwiseMin(p1).array() > hi.array()).any())
        continue;
      auto dist = [&](double s) {
        return plane_distance(at(x0, x1, v, s), at(x0, x1, a, s), at(x0, x1, b, s),
                              at(x0, x1, c, s));
      };
      double s0 = 0, d0 = dist(0);
      for (int k = 1; k <= samples; ++k) {
        const double s1 = double(k) / samples, d1 = dist(s1);
        if (std::isfinite(d0) && std::isfinite(d1) && ((d0 < 0) != (d1 < 0) || d1 == 0)) {
          double lo_t = s0, hi_t = s1, dlo = d0;
          for (int it = 0; it < 60; ++it) {
            const double mid = 0.5 * (lo_t + hi_t), dm = dist(mid);
            if ((dm < 0) == (dlo < 0)) {
              lo_t = mid;
              dlo = dm;
            } else {
              hi_t = mid;
            }
          }
          const double tc = 0.5 * (lo_t + hi_t);
          if (projects_inside(at(x0, x1, v, tc), at(x0, x1, a, tc), at(x0, x1, b, tc),
                              at(x0, x1, c, tc))) {
            ++crossings;
            break;
          }
        }
        s0 = s1;
        d0 = d1;
      }
    }
  }
  return crossings;
}

inline double segment_distance(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double len2 = ab.squaredNorm();
  const double s = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (p - (a + s * ab)).norm();
}

inline double point_triangle_distance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  if (projects_inside(p, a, b, c, 0.0)) return std::abs(plane_distance(p, a, b, c));
  return std::min(
      {segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)});
}

// Smallest distance from a vertex to a triangle it does not belong to.
inline double min_distance_nonadjacent(const MatX3& x, const MatX3i& tris) {
  double best = std::numeric_limits<double>::infinity();
  for (Index t = 0; t < tris.rows(); ++t)
    for (Index v = 0; v < x.rows(); ++v) {
      if (v == tris(t, 0) || v == tris(t, 1) || v == tris(t, 2)) continue;
      best = std::min(best, point_triangle_distance(
                                x.row(v).transpose(), x.row(tris(t, 0)).transpose(),
                                x.row(tris(t, 1)).transpose(), x.row(tris(t, 2)).transpose()));
    }
  return best;
}

// A rows x cols grid in the plane through `origin` spanned by `du` (columns) and `dv` (rows),
// appended to x and tris (vertex x.rows() + r * cols + c), two triangles per cell.
inline void make_grid(int rows, int cols, const Vec3& origin, const Vec3& du, const Vec3& dv,
                      MatX3& x, MatX3i& tris) {
  const Index n0 = x.rows(), t0 = tris.rows();
  x.conservativeResize(n0 + rows * cols, 3);
  tris.conservativeResize(t0 + 2 * (rows - 1) * (cols - 1), 3);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c)
      x.row(n0 + r * cols + c) = (origin + c * du + r * dv).transpose();
  Index t = t0;
  for (int r = 0; r + 1 < rows; ++r)
    for (int c = 0; c + 1 < cols; ++c) {
      const auto i = static_cast<int32_t>(n0 + r * cols + c);
      const auto j = static_cast<int32_t>(i + cols);
      tris.row(t++) << i, i + 1, j + 1;
      tris.row(t++) << i, j + 1, j;
    }
}

}  // namespace flagsim::test_support
