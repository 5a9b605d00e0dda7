#include "collision/solids.h"

#include <algorithm>
#include <cmath>

namespace flagsim {

namespace {

// Sphere tracing stops when the path is this close to the grown surface (relative to the
// thickness) or after kTraceSteps steps (a path grazing the surface); the vertex then ends where
// the projection puts it.
constexpr double kTraceTolerance = 1e-3;
constexpr int kTraceSteps = 64;

// Earliest t in [0, 1] at which a -> b comes within `thickness` of the solid (a outside that),
// or -1. Each step advances by the distance to the grown surface, which the path cannot cross
// within that step: no tunnelling whatever the speed.
double trace(const ClothSolid& s, const Vec3& a, const Vec3& b) {
  const Vec3 d = b - a;
  const double len = d.norm();
  if (!(len > 0)) return -1;
  double t = 0;
  for (int k = 0; k < kTraceSteps; ++k) {
    const double gap = solid_distance(s.geometry, a + t * d) - s.thickness;
    if (gap <= kTraceTolerance * s.thickness) return t;
    t += gap / len;
    if (t > 1) return -1;
  }
  return -1;
}

bool path_near(const ClothSolid& s, const Vec3& a, const Vec3& b) {
  return !((a.cwiseMax(b).array() < s.lo.array()).any() ||
           (a.cwiseMin(b).array() > s.hi.array()).any());
}

// One vertex in the solid's frame: path a -> p, velocity v relative to the surface. Returns
// whether it was moved.
bool collide_point(const ClothSolid& s, const Vec3& a, Vec3& p, Vec3& v) {
  if (!path_near(s, a, p)) return false;
  Vec3 n;
  bool hit = false;
  if (solid_distance(s.geometry, a) > s.thickness) {
    const double t = trace(s, a, p);
    if (t >= 0) {
      // Stop where the path met the grown surface; keep the rest of the motion tangent to it.
      const Vec3 q = a + t * (p - a);
      solid_distance(s.geometry, q, &n);
      const Vec3 rest = p - q;
      p = q + rest - std::min(rest.dot(n), 0.0) * n;
      hit = true;
    }
  }
  const double d = solid_distance(s.geometry, p, hit ? nullptr : &n);
  if (d < s.thickness) {
    Vec3 g;
    solid_distance(s.geometry, p, &g);
    p += (s.thickness - d) * g;  // along the exact distance's gradient: out to the thickness
    if (!hit) n = g;
    hit = true;
  }
  if (!hit) return false;
  const double vn = v.dot(n);
  if (vn < 0) {
    Vec3 vt = v - vn * n;
    const double vt_norm = vt.norm();
    if (vt_norm > 0) vt *= std::max(0.0, 1.0 - s.friction * (-vn) / vt_norm);
    v = vt;
  }
  return true;
}

}  // namespace

ClothSolid::ClothSolid(SolidGeometry g, double thick, double mu)
    : geometry(std::move(g)), thickness(thick), friction(mu) {
  const SolidGeometry& s = geometry;
  Vec3 ext = Vec3::Zero();  // a mesh takes its box from its vertices
  switch (s.shape) {
    case ObstacleShape::kBox: ext = s.half_size; break;
    case ObstacleShape::kSphere: ext.setConstant(s.radius); break;
    case ObstacleShape::kCylinder:
    case ObstacleShape::kCapsule: ext.setConstant(s.radius + 0.5 * s.length); break;
    case ObstacleShape::kMesh: break;
  }
  if (s.shape == ObstacleShape::kMesh) {
    lo = s.vertices.colwise().minCoeff().transpose();
    hi = s.vertices.colwise().maxCoeff().transpose();
  } else {
    lo = s.center - ext;
    hi = s.center + ext;
  }
  lo.array() -= thickness;
  hi.array() += thickness;
}

SolidContacts collide_solid(const ClothSolid& s, const RigidMotion* motion, const MatX3& x0,
                            MatX3& x, MatX3& v, const VecX& inv_mass, const VecX& mass) {
  SolidContacts out;
  for (Index i = 0; i < x.rows(); ++i) {
    if (inv_mass[i] == 0) continue;
    if (!motion) {
      Vec3 p = row(x, i), vi = row(v, i);
      if (!collide_point(s, row(x0, i), p, vi)) continue;
      x.row(i) = p.transpose();
      v.row(i) = vi.transpose();
      ++out.moved;
      continue;
    }
    const Vec3 a = motion->from.inverse(row(x0, i));
    Vec3 p = motion->to.inverse(row(x, i));
    const Vec3 before = row(v, i);
    Vec3 vi = motion->to.R.transpose() * (before - motion->velocity_at(p));
    if (!collide_point(s, a, p, vi)) continue;
    const Vec3 surface = motion->velocity_at(p);
    const Vec3 after = motion->to.R * vi + surface;
    x.row(i) = motion->to.apply(p).transpose();
    v.row(i) = after.transpose();
    out.wall_work += mass[i] * (after - before).dot(surface);
    ++out.moved;
  }
  return out;
}

}  // namespace flagsim
