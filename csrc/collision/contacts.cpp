#include "collision/contacts.h"

#include <algorithm>
#include <array>

namespace flagsim {

bool VertexTriangleContact::closer_than(const PairPoints& x, double gap) {
  const Vec3 &p = x[0], &a = x[1], &b = x[2], &c = x[3];
  if (beyond_reach(p, a, b, c, gap)) return false;
  bool interior;
  const Vec3 bary = closest_point_barycentric(p, a, b, c, interior);
  return (p - (bary[0] * a + bary[1] * b + bary[2] * c)).norm() < gap;
}

namespace {

using Coefficients = std::array<double, 4>;

// A crossing at time t: the unit normal of the plane of two directions at the hit, each moving
// linearly from its start value (u0, w0) to its end value (u1, w1): a triangle's two edges, or
// the two edges. It points to the side the pair started on, as towards(n) says of the normal
// before it is scaled. Parallel directions give no normal: kDegenerate, left to the fallback.
template <class Towards>
void set_crossing(const Vec3& u0, const Vec3& u1, const Vec3& w0, const Vec3& w1, double t,
                  const Towards& towards, const Coefficients& g, Contact& ct) {
  const Vec3 n = ((1 - t) * u0 + t * u1).cross((1 - t) * w0 + t * w1);
  const double len = n.norm();
  if (!(len > 0)) {
    ct.kind = Contact::kDegenerate;
    return;
  }
  ct.n = towards(n) ? Vec3(n / len) : Vec3(-n / len);
  std::copy(g.begin(), g.end(), ct.g);
  ct.kind = Contact::kCrossing;
}

// A proximity at distance d (m) < thickness h (m), pushed apart along the unit direction n.
void set_proximity(const Vec3& n, double d, double h, const Coefficients& g, Contact& ct) {
  ct.n = n;
  std::copy(g.begin(), g.end(), ct.g);
  ct.C = d - h;
  ct.kind = Contact::kProximity;
}

}  // namespace

void VertexTriangleContact::detect(const PairPoints& x0, const PairPoints& x1, double thickness,
                                   Contact& ct) {
  const double h = thickness;
  const Vec3 &p0 = x0[0], &a0 = x0[1], &b0 = x0[2], &c0 = x0[3];
  const Vec3 &p1 = x1[0], &a1 = x1[1], &b1 = x1[2], &c1 = x1[3];
  ct.kind = Contact::kNone;
  double t;
  Vec3 bary;
  if (vertex_triangle_ccd(p0, a0, b0, c0, p1, a1, b1, c1, t, bary)) {
    // towards the side of the triangle's plane the vertex started on (or ended on, from it)
    auto towards = [&](const Vec3&) {
      const double f0 = (b0 - a0).cross(c0 - a0).dot(p0 - a0);
      const double f1 = (b1 - a1).cross(c1 - a1).dot(p1 - a1);
      return f0 > 0 || (f0 == 0 && f1 >= 0);
    };
    set_crossing(b0 - a0, b1 - a1, c0 - a0, c1 - a1, t, towards, {1, -bary[0], -bary[1], -bary[2]},
                 ct);
    return;
  }
  if (beyond_reach(p1, a1, b1, c1, h)) return;
  bool interior;
  bary = closest_point_barycentric(p1, a1, b1, c1, interior);
  const Vec3 r = p1 - (bary[0] * a1 + bary[1] * b1 + bary[2] * c1);
  const double d = r.norm();
  if (d >= h) return;
  Vec3 n;
  if (d > 1e-9 * h) {
    n = r / d;
  } else {  // on the triangle: its normal, towards the side the vertex started on
    const Vec3 m = (b1 - a1).cross(c1 - a1);
    if (!(m.norm() > 0)) {
      ct.kind = Contact::kDegenerate;
      return;
    }
    const double f0 = (b0 - a0).cross(c0 - a0).dot(p0 - a0);
    n = f0 < 0 ? Vec3(-m.normalized()) : Vec3(m.normalized());
  }
  set_proximity(n, d, h, {1, -bary[0], -bary[1], -bary[2]}, ct);
}

void EdgeEdgeContact::detect(const PairPoints& x0, const PairPoints& x1, double thickness,
                             Contact& ct) {
  const double h = thickness;
  // Edges p0a0 -> p1a1 (points 0, 1) and b0c0 -> b1c1 (points 2, 3).
  const Vec3 &p0 = x0[0], &a0 = x0[1], &b0 = x0[2], &c0 = x0[3];
  const Vec3 &p1 = x1[0], &a1 = x1[1], &b1 = x1[2], &c1 = x1[3];
  ct.kind = Contact::kNone;
  double t;
  Vec2 su;
  if (edge_edge_ccd(p0, a0, b0, c0, p1, a1, b1, c1, t, su)) {
    // towards the side the first edge's hit point started on, seen from the second's
    auto towards = [&](const Vec3& n) {
      const Vec3 gap0 = (p0 + su[0] * (a0 - p0)) - (b0 + su[1] * (c0 - b0));
      return gap0.dot(n) >= 0;
    };
    set_crossing(a0 - p0, a1 - p1, c0 - b0, c1 - b1, t, towards,
                 {1 - su[0], su[0], -(1 - su[1]), -su[1]}, ct);
    return;
  }
  // Cheap rejection: the midpoints further apart than the half-lengths plus the thickness.
  const Vec3 mp = 0.5 * (p1 + a1), mq = 0.5 * (b1 + c1);
  if ((mp - mq).norm() > 0.5 * ((a1 - p1).norm() + (c1 - b1).norm()) + h) return;
  const Vec2 su2 = closest_segment_parameters(p1, a1, b1, c1);
  const Vec3 r = (p1 + su2[0] * (a1 - p1)) - (b1 + su2[1] * (c1 - b1));
  const double d = r.norm();
  if (d >= h || !(d > 1e-9 * h)) return;  // touching exactly: left to the crossing test
  set_proximity(r / d, d, h, {1 - su2[0], su2[0], -(1 - su2[1]), -su2[1]}, ct);
}

}  // namespace flagsim
