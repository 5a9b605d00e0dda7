#include "collision/pole.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/parallel.h"

namespace flagsim {

namespace {

// Moved vertices are put this far outside (relative to the radius), so that rounding cannot leave
// them a hair inside.
constexpr double kSkin = 1e-9;

// A segment whose bounding box misses the cylinder's, grown by this (m), neither enters it nor
// ends inside: far_from_pole lets such a vertex skip entry_time's quadratic. The margin is far
// above the rounding of the roots and coordinates (|x| <= 1e6 m: ~1e-10 m), so a segment it
// rejects is one the full test leaves alone too, bit for bit.
constexpr double kFarMargin = 1e-6;

// True when the segment a -> b stays clear of the pole's bounding box (grown by kFarMargin and
// 1e-3 of the radius) on some axis: the cylinder at rest can neither be entered nor contain b.
inline bool far_from_pole(const PoleParams& pole, const Vec3& a, const Vec3& b) {
  const double m = kFarMargin + 1e-3 * pole.radius, R = pole.radius + m;
  const double bx = pole.base.x(), bz = pole.base.z();
  const double y0 = pole.base.y() - m, y1 = pole.base.y() + pole.height + m;
  return std::min(a.x(), b.x()) > bx + R || std::max(a.x(), b.x()) < bx - R ||
         std::min(a.z(), b.z()) > bz + R || std::max(a.z(), b.z()) < bz - R ||
         std::min(a.y(), b.y()) > y1 || std::max(a.y(), b.y()) < y0;
}

// Earliest t in [0, 1] at which the segment a -> b enters the cylinder from outside, and the
// outward normal of the face it enters through; -1 if never.
double entry_time(const PoleParams& pole, const Vec3& a, const Vec3& b, Vec3& normal) {
  const double y0 = pole.base.y(), y1 = pole.base.y() + pole.height, R = pole.radius;
  const Vec3 d = b - a;
  double best = std::numeric_limits<double>::infinity();
  // Side: |(a + t d - base)_xz|^2 = R^2 with y(t) in [y0, y1].
  const double ox = a.x() - pole.base.x(), oz = a.z() - pole.base.z();
  const double A = d.x() * d.x() + d.z() * d.z();
  const double B = 2 * (ox * d.x() + oz * d.z());
  const double C = ox * ox + oz * oz - R * R;
  if (A > 0) {
    const double disc = B * B - 4 * A * C;
    if (disc >= 0) {
      const double t = (-B - std::sqrt(disc)) / (2 * A);  // the entering root
      const double y = a.y() + t * d.y();
      if (t >= 0 && t <= 1 && y >= y0 && y <= y1) {
        best = t;
        normal = Vec3(ox + t * d.x(), 0.0, oz + t * d.z()) / R;
      }
    }
  }
  // Caps: the plane y = y0 or y = y1 crossed inside the disc.
  for (const double yc : {y0, y1}) {
    if (d.y() == 0) break;
    const double t = (yc - a.y()) / d.y();
    if (t < 0 || t > 1 || t >= best) continue;
    const double px = ox + t * d.x(), pz = oz + t * d.z();
    if (px * px + pz * pz <= R * R) {
      best = t;
      normal = Vec3(0.0, yc == y0 ? -1.0 : 1.0, 0.0);
    }
  }
  return std::isfinite(best) ? best : -1.0;
}

// Nearest surface point of the cylinder to p (inside) and the outward normal there; `hint` is the
// radial direction used when p is on the axis.
void project_out(const PoleParams& pole, const Vec3& hint, Vec3& p, Vec3& n) {
  const double y0 = pole.base.y(), y1 = pole.base.y() + pole.height, R = pole.radius;
  Vec3 radial(p.x() - pole.base.x(), 0.0, p.z() - pole.base.z());
  double r = radial.norm();
  if (!(r > 0)) {
    radial = Vec3(hint.x() - pole.base.x(), 0.0, hint.z() - pole.base.z());
    r = radial.norm();
    if (!(r > 0)) radial = Vec3::UnitX(), r = 1.0;
    radial /= r;
    r = 0.0;
  } else {
    radial /= r;
  }
  const double side = R - r, top = y1 - p.y(), bottom = p.y() - y0;
  if (side <= top && side <= bottom) {
    const double target = R * (1 + kSkin);
    p.x() = pole.base.x() + radial.x() * target;
    p.z() = pole.base.z() + radial.z() * target;
    n = radial;
  } else if (top <= bottom) {
    p.y() = y1 + R * kSkin;
    n = Vec3::UnitY();
  } else {
    p.y() = y0 - R * kSkin;
    n = -Vec3::UnitY();
  }
}

}  // namespace

bool inside_pole(const PoleParams& pole, const Vec3& p, double tolerance) {
  const double dx = p.x() - pole.base.x(), dz = p.z() - pole.base.z();
  const double R = pole.radius - tolerance;
  return p.y() > pole.base.y() + tolerance && p.y() < pole.base.y() + pole.height - tolerance &&
         R > 0 && dx * dx + dz * dz < R * R;
}

namespace {

// One vertex from a to p (velocity v) against the pole at rest: how far it was moved, or -1 when
// it was left alone. (Callers skip it when far_from_pole: it would leave such a vertex alone.)
double collide_point(const PoleParams& pole, const Vec3& a, Vec3& p, Vec3& v) {
  Vec3 normal = Vec3::Zero();  // set by entry_time or project_out before any use
  const Vec3 end = p;
  const double t = inside_pole(pole, a) ? -1.0 : entry_time(pole, a, p, normal);
  if (t >= 0) {
    // Entered from outside (possibly right through): stop at the entry point q and keep the
    // rest of the motion's component tangent to the face entered, which stays outside the
    // convex cylinder.
    const Vec3 q = a + t * (p - a);
    const Vec3 rest = p - q;
    p = q + rest - std::min(rest.dot(normal), 0.0) * normal + kSkin * pole.radius * normal;
  } else if (inside_pole(pole, p)) {
    project_out(pole, a, p, normal);  // started inside (or grazing): nearest surface point
  } else {
    return -1;
  }
  const double vn = v.dot(normal);
  if (vn < 0) v -= vn * normal;
  return (p - end).norm();
}

// collide_pole() for vertex i: the pole at rest, or moving (the vertex's path and velocity taken
// into the pole's frame, relative to the pole's surface, and back). x0 is taken into that frame
// by `start` (motion->from, or motion->to when x0 is already carried to the piece's end).
// push: if given, the vertex's velocity change times the moving surface's velocity there is
// added to it (dv . v_surface, m/s squared: the moving pole's work on it per unit mass).
double collide_vertex(const PoleParams& pole, const RigidMotion* motion, const Pose* start,
                      const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass, Index i,
                      double* push = nullptr) {
  if (inv_mass[i] == 0) return -1;
  if (!motion) {
    if (far_from_pole(pole, row(x0, i), row(x, i))) return -1;  // before copying the rows
    Vec3 p = x.row(i).transpose(), vi = v.row(i).transpose();
    const double moved = collide_point(pole, row(x0, i), p, vi);
    if (moved < 0) return -1;
    x.row(i) = p.transpose();
    v.row(i) = vi.transpose();
    return moved;
  }
  const Vec3 a = start->inverse(row(x0, i));
  Vec3 p = motion->to.inverse(row(x, i));
  if (far_from_pole(pole, a, p)) return -1;
  const Vec3 surface = motion->velocity_at(p);
  Vec3 vi = motion->to.R.transpose() * (row(v, i) - surface);
  const double moved = collide_point(pole, a, p, vi);
  if (moved < 0) return -1;
  const Vec3 surface_now = motion->velocity_at(p), after = motion->to.R * vi + surface_now;
  if (push) *push += (after - row(v, i)).dot(surface_now);
  x.row(i) = motion->to.apply(p).transpose();
  v.row(i) = after.transpose();
  return moved;
}

// collide_pole and collide_pole_carried: x0 taken into the pole's frame by `start`.
Index collide_all(const PoleParams& pole, const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass,
                  double* max_move, const RigidMotion* motion, const Pose* start, const VecX* mass,
                  double* wall_work) {
  Index moved = 0;
  double largest = 0;
  const Index n = x.rows();
  const bool book = motion && wall_work;  // serial then: the work summed in vertex order
  // Reductions branch in C++: an omp `if` clause would build a one-thread team (a heap
  // allocation) for every small call.
  if (!book && use_team(n >= kParallelGrain)) {
#pragma omp parallel for schedule(static) reduction(+ : moved) reduction(max : largest)
    for (Index i = 0; i < n; ++i) {
      const double d = collide_vertex(pole, motion, start, x0, x, v, inv_mass, i);
      if (d >= 0) ++moved, largest = std::max(largest, d);
    }
  } else {
    double work = 0;
    for (Index i = 0; i < n; ++i) {
      double push = 0;
      const double d =
          collide_vertex(pole, motion, start, x0, x, v, inv_mass, i, book ? &push : nullptr);
      if (d >= 0) ++moved, largest = std::max(largest, d), work += book ? (*mass)[i] * push : 0.0;
    }
    if (book) *wall_work += work;
  }
  if (max_move) *max_move = largest;
  return moved;
}

}  // namespace

Index collide_pole(const PoleParams& pole, const MatX3& x0, MatX3& x, MatX3& v,
                   const VecX& inv_mass, double* max_move, const RigidMotion* motion,
                   const VecX* mass, double* wall_work) {
  return collide_all(pole, x0, x, v, inv_mass, max_move, motion, motion ? &motion->from : nullptr,
                     mass, wall_work);
}

Index collide_pole_carried(const PoleParams& pole, const RigidMotion& motion, const MatX3& x0,
                           MatX3& x, MatX3& v, const VecX& inv_mass, double* max_move) {
  return collide_all(pole, x0, x, v, inv_mass, max_move, &motion, &motion.to, nullptr, nullptr);
}

}  // namespace flagsim
