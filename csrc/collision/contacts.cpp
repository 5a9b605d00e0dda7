#include "collision/contacts.h"

namespace flagsim {

bool VertexTriangleContact::closer_than(const PairPoints& x, double gap) {
  const Vec3 &p = x[0], &a = x[1], &b = x[2], &c = x[3];
  if (beyond_reach(p, a, b, c, gap)) return false;
  bool interior;
  const Vec3 bary = closest_point_barycentric(p, a, b, c, interior);
  return (p - (bary[0] * a + bary[1] * b + bary[2] * c)).norm() < gap;
}

void VertexTriangleContact::detect(const PairPoints& x0, const PairPoints& x1, double thickness,
                                   Contact& ct) {
  const double h = thickness;
  const Vec3 &p0 = x0[0], &a0 = x0[1], &b0 = x0[2], &c0 = x0[3];
  const Vec3 &p1 = x1[0], &a1 = x1[1], &b1 = x1[2], &c1 = x1[3];
  ct.kind = Contact::kNone;
  double t;
  Vec3 bary;
  if (vertex_triangle_ccd(p0, a0, b0, c0, p1, a1, b1, c1, t, bary)) {
    const Vec3 n = ((1 - t) * (b0 - a0) + t * (b1 - a1)).cross((1 - t) * (c0 - a0) + t * (c1 - a1));
    const double len = n.norm();
    if (!(len > 0)) {  // a degenerate triangle: left to the fallback
      ct.kind = Contact::kDegenerate;
      return;
    }
    const double f0 = (b0 - a0).cross(c0 - a0).dot(p0 - a0);
    const double f1 = (b1 - a1).cross(c1 - a1).dot(p1 - a1);
    ct.n = (f0 > 0 || (f0 == 0 && f1 >= 0)) ? Vec3(n / len) : Vec3(-n / len);
    ct.g[0] = 1, ct.g[1] = -bary[0], ct.g[2] = -bary[1], ct.g[3] = -bary[2];
    ct.kind = Contact::kCrossing;
    return;
  }
  if (beyond_reach(p1, a1, b1, c1, h)) return;
  bool interior;
  bary = closest_point_barycentric(p1, a1, b1, c1, interior);
  const Vec3 r = p1 - (bary[0] * a1 + bary[1] * b1 + bary[2] * c1);
  const double d = r.norm();
  if (d >= h) return;
  if (d > 1e-9 * h) {
    ct.n = r / d;
  } else {  // on the triangle: its normal, towards the side the vertex started on
    const Vec3 n = (b1 - a1).cross(c1 - a1);
    if (!(n.norm() > 0)) {
      ct.kind = Contact::kDegenerate;
      return;
    }
    const double f0 = (b0 - a0).cross(c0 - a0).dot(p0 - a0);
    ct.n = f0 < 0 ? Vec3(-n.normalized()) : Vec3(n.normalized());
  }
  ct.g[0] = 1, ct.g[1] = -bary[0], ct.g[2] = -bary[1], ct.g[3] = -bary[2];
  ct.C = d - h;
  ct.kind = Contact::kProximity;
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
    const Vec3 n = ((1 - t) * (a0 - p0) + t * (a1 - p1)).cross((1 - t) * (c0 - b0) + t * (c1 - b1));
    const double len = n.norm();
    if (!(len > 0)) {
      ct.kind = Contact::kDegenerate;
      return;
    }
    const Vec3 gap0 = (p0 + su[0] * (a0 - p0)) - (b0 + su[1] * (c0 - b0));
    ct.n = gap0.dot(n) >= 0 ? Vec3(n / len) : Vec3(-n / len);
    ct.g[0] = 1 - su[0], ct.g[1] = su[0], ct.g[2] = -(1 - su[1]), ct.g[3] = -su[1];
    ct.kind = Contact::kCrossing;
    return;
  }
  // Cheap rejection: the midpoints further apart than the half-lengths plus the thickness.
  const Vec3 mp = 0.5 * (p1 + a1), mq = 0.5 * (b1 + c1);
  if ((mp - mq).norm() > 0.5 * ((a1 - p1).norm() + (c1 - b1).norm()) + h) return;
  const Vec2 su2 = closest_segment_parameters(p1, a1, b1, c1);
  const Vec3 r = (p1 + su2[0] * (a1 - p1)) - (b1 + su2[1] * (c1 - b1));
  const double d = r.norm();
  if (d >= h || !(d > 1e-9 * h)) return;  // touching exactly: left to the crossing test
  ct.n = r / d;
  ct.g[0] = 1 - su2[0], ct.g[1] = su2[0], ct.g[2] = -(1 - su2[1]), ct.g[3] = -su2[1];
  ct.C = d - h;
  ct.kind = Contact::kProximity;
}

}  // namespace flagsim
