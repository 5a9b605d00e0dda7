#include "collision/vertex_triangle.h"

#include <algorithm>
#include <cmath>

namespace flagsim {

Vec3 closest_point_barycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                               bool& interior) {
  interior = false;
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double s = d1 / (d1 - d3);
    return {1 - s, s, 0};
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double s = d2 / (d2 - d6);
    return {1 - s, 0, s};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double s = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - s, s};
  }
  const double sum = va + vb + vc;  // = |ab x ac|^2 > 0 for a proper triangle
  if (!(sum > 0)) {
    const double da = (p - a).squaredNorm(), db = (p - b).squaredNorm(), dc = (p - c).squaredNorm();
    if (da <= db && da <= dc) return {1, 0, 0};
    return db <= dc ? Vec3(0, 1, 0) : Vec3(0, 0, 1);
  }
  interior = true;
  const double v = vb / sum, w = vc / sum;
  return {1 - v - w, v, w};
}

bool beyond_reach(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, double gap) {
  const Vec3 m = (a + b + c) / 3;
  const double r =
      std::sqrt(std::max({(a - m).squaredNorm(), (b - m).squaredNorm(), (c - m).squaredNorm()}));
  return (p - m).norm() > r + gap;
}

Vec3 plane_barycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double nn = n.squaredNorm();
  if (!(nn > 0)) return Vec3::Zero();
  // Signed sub-triangle areas over the full area (each area vector projected on n).
  const double u = (c - b).cross(p - b).dot(n) / nn;
  const double v = (a - c).cross(p - c).dot(n) / nn;
  return {u, v, 1 - u - v};
}

Eigen::Vector4d coplanarity_cubic(const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0,
                                  const Vec3& p1, const Vec3& a1, const Vec3& b1, const Vec3& c1) {
  // e1(t) = e1 + t d1, e2(t) = e2 + t d2, q(t) = q + t dq (all relative to a(t)):
  // e1 x e2 = N0 + t N1 + t^2 N2, f = (N0 + t N1 + t^2 N2) . (q + t dq).
  const Vec3 e1 = b0 - a0, e2 = c0 - a0, q = p0 - a0;
  const Vec3 d1 = (b1 - a1) - e1, d2 = (c1 - a1) - e2, dq = (p1 - a1) - q;
  const Vec3 N0 = e1.cross(e2), N1 = e1.cross(d2) + d1.cross(e2), N2 = d1.cross(d2);
  return {N0.dot(q), N1.dot(q) + N0.dot(dq), N2.dot(q) + N1.dot(dq), N2.dot(dq)};
}

namespace {

double eval_cubic(const Eigen::Vector4d& k, double t) {
  return k[0] + t * (k[1] + t * (k[2] + t * k[3]));
}

// Root of f on [lo, hi] where f(lo) and f(hi) have opposite signs: regula falsi with the
// Illinois modification (Dowell & Jarratt 1971), superlinear, bracketing kept, to 1e-13 in t.
double bracketed_root(const Eigen::Vector4d& k, double lo, double hi, double flo, double fhi) {
  int side = 0;
  for (int it = 0; it < 100 && hi - lo > 1e-13; ++it) {
    double mid = (lo * fhi - hi * flo) / (fhi - flo);
    if (!(mid > lo && mid < hi)) mid = 0.5 * (lo + hi);
    const double fm = eval_cubic(k, mid);
    if (fm == 0) return mid;
    if ((fm < 0) == (flo < 0)) {
      lo = mid;
      flo = fm;
      if (side == -1) fhi *= 0.5;
      side = -1;
    } else {
      hi = mid;
      fhi = fm;
      if (side == 1) flo *= 0.5;
      side = 1;
    }
  }
  return 0.5 * (lo + hi);
}

bool inside_at(double t, const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0,
               const Vec3& p1, const Vec3& a1, const Vec3& b1, const Vec3& c1, Vec3& bary) {
  const Vec3 p = p0 + t * (p1 - p0), a = a0 + t * (a1 - a0), b = b0 + t * (b1 - b0),
             c = c0 + t * (c1 - c0);
  bary = plane_barycentric(p, a, b, c);
  constexpr double kEps = 1e-9;
  if (bary.isZero(0)) return false;  // degenerate triangle: no face to cross
  return bary.minCoeff() >= -kEps;
}

}  // namespace

bool vertex_triangle_ccd(const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0,
                         const Vec3& p1, const Vec3& a1, const Vec3& b1, const Vec3& c1,
                         double& t_hit, Vec3& bary) {
  // Quick rejection: p never enters the sphere around the triangle's centroid m that holds its
  // corners. |corner - m| is convex in t (linear motion), so its maximum over the step is at an
  // end; p - m moves linearly, so its closest approach has a closed form.
  {
    const Vec3 m0 = (a0 + b0 + c0) / 3, m1 = (a1 + b1 + c1) / 3;
    const double r2 =
        std::max({(a0 - m0).squaredNorm(), (b0 - m0).squaredNorm(), (c0 - m0).squaredNorm(),
                  (a1 - m1).squaredNorm(), (b1 - m1).squaredNorm(), (c1 - m1).squaredNorm()});
    const Vec3 q0 = p0 - m0, dq = (p1 - m1) - q0;
    const double dd = dq.squaredNorm();
    const double s = dd > 0 ? std::clamp(-q0.dot(dq) / dd, 0.0, 1.0) : 0.0;
    if ((q0 + s * dq).squaredNorm() > r2 * (1 + 1e-9)) return false;
  }
  const Eigen::Vector4d k = coplanarity_cubic(p0, a0, b0, c0, p1, a1, b1, c1);
  double roots[3];
  const int n = cubic_roots_in_unit_interval(k, roots);
  for (int i = 0; i < n; ++i)
    if (inside_at(roots[i], p0, a0, b0, c0, p1, a1, b1, c1, bary)) {
      t_hit = roots[i];
      return true;
    }
  return false;
}

int cubic_roots_in_unit_interval(const Eigen::Vector4d& k, double roots[3]) {
  // Split [0, 1] where f' = k1 + 2 k2 t + 3 k3 t^2 vanishes: f is monotone on each piece, so a
  // piece holds a root iff f changes sign over it.
  double cuts[4] = {0.0, 0.0, 0.0, 1.0};
  int n = 1;
  const double qa = 3 * k[3], qb = 2 * k[2], qc = k[1];
  auto add_cut = [&](double t) {
    if (t > 0 && t < 1) cuts[n++] = t;
  };
  if (qa != 0) {
    const double disc = qb * qb - 4 * qa * qc;
    if (disc >= 0) {
      // Numerically stable quadratic roots (Numerical Recipes §5.6).
      const double sq = std::sqrt(disc);
      const double qq = -0.5 * (qb + (qb >= 0 ? sq : -sq));
      if (qq != 0) {
        add_cut(qq / qa);
        add_cut(qc / qq);
      } else {
        add_cut(0.0);
      }
    }
  } else if (qb != 0) {
    add_cut(-qc / qb);
  }
  if (n == 3 && cuts[2] < cuts[1]) std::swap(cuts[1], cuts[2]);  // the interior cuts in order
  cuts[n++] = 1.0;
  int found = 0;
  double f_lo = eval_cubic(k, cuts[0]);
  for (int i = 0; i + 1 < n; ++i) {
    const double lo = cuts[i], hi = cuts[i + 1];
    const double f_hi = eval_cubic(k, hi);
    if (f_lo == 0) {
      if (found == 0 || roots[found - 1] != lo) roots[found++] = lo;
    } else if (f_hi == 0 || (f_lo < 0) != (f_hi < 0)) {
      roots[found++] = f_hi == 0 ? hi : bracketed_root(k, lo, hi, f_lo, f_hi);
    }
    f_lo = f_hi;
  }
  return found;
}

double separation_time(const Vec3& p0, const Vec3& a0, const Vec3& b0, const Vec3& c0,
                       const Vec3& p1, const Vec3& a1, const Vec3& b1, const Vec3& c1, double t_hit,
                       double gap) {
  auto distance = [&](double t) {  // signed distance of p(t) to the plane of abc(t)
    const Vec3 a = a0 + t * (a1 - a0);
    const Vec3 n = (b0 + t * (b1 - b0) - a).cross(c0 + t * (c1 - c0) - a);
    const double len = n.norm();
    return len > 0 ? n.dot(p0 + t * (p1 - p0) - a) / len : 0.0;
  };
  return stop_short_time(distance, t_hit, gap);
}

}  // namespace flagsim
