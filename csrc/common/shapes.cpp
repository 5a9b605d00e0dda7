#include "common/shapes.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/errors.h"

namespace flagsim {

namespace {

std::string join(const std::string& prefix, const std::string& field) {
  return prefix.empty() ? field : prefix + "." + field;
}

constexpr double kPi = 3.14159265358979323846;

// Nearest point q of the mesh to x and its squared distance.
double mesh_nearest(const SolidGeometry& s, const Vec3& x, Vec3& q) {
  double best = std::numeric_limits<double>::infinity();
  for (Index f = 0; f < s.faces.rows(); ++f) {
    const Vec3 c =
        closest_point_on_triangle(x, row(s.vertices, s.faces(f, 0)), row(s.vertices, s.faces(f, 1)),
                                  row(s.vertices, s.faces(f, 2)));
    const double d2 = (c - x).squaredNorm();
    if (d2 < best) best = d2, q = c;
  }
  return best;
}

}  // namespace

Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

double winding_number(const MatX3& V, const MatX3i& F, const Vec3& x) {
  double omega = 0;
  for (Index f = 0; f < F.rows(); ++f) {
    const Vec3 a = row(V, F(f, 0)) - x, b = row(V, F(f, 1)) - x, c = row(V, F(f, 2)) - x;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double det = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    omega += 2.0 * std::atan2(det, den);  // the triangle's signed solid angle
  }
  return omega / (4.0 * kPi);
}

bool SolidGeometry::contains(const Vec3& x) const {
  const Vec3 d = x - center;
  switch (shape) {
    case ObstacleShape::kBox: return (d.array().abs() <= half_size.array()).all();
    case ObstacleShape::kSphere: return d.squaredNorm() <= radius * radius;
    case ObstacleShape::kCylinder: {
      const Vec3 a = axis.normalized();
      const double along = d.dot(a);
      return std::fabs(along) <= 0.5 * length && (d - along * a).squaredNorm() <= radius * radius;
    }
    case ObstacleShape::kCapsule: return solid_distance(*this, x) <= 0;
    case ObstacleShape::kMesh: return std::fabs(winding_number(vertices, faces, x)) >= 0.5;
  }
  return false;
}

double SolidGeometry::thickness() const {
  switch (shape) {
    case ObstacleShape::kBox: return 2.0 * half_size.minCoeff();
    case ObstacleShape::kMesh:
      return vertices.rows()
                 ? (vertices.colwise().maxCoeff() - vertices.colwise().minCoeff()).minCoeff()
                 : 0.0;
    default: return 2.0 * radius;
  }
}

void SolidGeometry::validate_geometry(const std::string& prefix) const {
  check_position(join(prefix, "center"), center);
  for (int d = 0; d < 3; ++d)
    if (!(std::isfinite(half_size[d]) && half_size[d] > 0 && half_size[d] <= kMaxCoordinate))
      fail_param(join(prefix, "half_size"), "in (0, 1e6] m in every component",
                 detail::to_text(half_size.transpose()));
  check_length(join(prefix, "radius"), radius);
  check_finite_vec(join(prefix, "axis"), axis);
  if (!(axis.norm() > 0)) fail_param(join(prefix, "axis"), "a non-zero vector", "(0 0 0)");
  check_length(join(prefix, "length"), length);
  for (Index i = 0; i < vertices.rows(); ++i)
    check_position(join(prefix, "vertices") + "[" + std::to_string(i) + "]",
                   Vec3(vertices.row(i).transpose()));
  if (vertices.rows() == 0) return;  // faces are checked against the vertices once both are set
  for (Index f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (faces(f, k) < 0 || faces(f, k) >= vertices.rows())
        fail_param(join(prefix, "faces") + "[" + std::to_string(f) + "]",
                   "vertex indices in [0, " + std::to_string(vertices.rows()) + ")", faces(f, k));
}

void SolidGeometry::validate_mesh(const std::string& prefix) const {
  if (shape != ObstacleShape::kMesh) return;
  if (vertices.rows() < 4)
    fail_param(join(prefix, "vertices"), "at least 4 points of a closed mesh (shape 'mesh')",
               std::to_string(vertices.rows()) + " points");
  if (faces.rows() < 4)
    fail_param(join(prefix, "faces"), "at least 4 triangles of a closed mesh (shape 'mesh')",
               std::to_string(faces.rows()) + " triangles");
  validate_geometry(prefix);
}

// Exact distances: the sphere's and capsule's from the centre or the segment, the capped
// cylinder's from its radial and axial excesses, the box's from the per-axis excesses (inside:
// the nearest face), the mesh's from its nearest triangle.
double solid_distance(const SolidGeometry& o, const Vec3& x, Vec3* gradient) {
  const Vec3 p = x - o.center;
  Vec3 g = Vec3::UnitX();
  double d = 0;
  switch (o.shape) {
    case ObstacleShape::kSphere: {
      const double r = p.norm();
      d = r - o.radius;
      if (r > 0) g = p / r;
      break;
    }
    case ObstacleShape::kCapsule: {
      const Vec3 a = o.axis.normalized();
      const double h = std::clamp(p.dot(a), -0.5 * o.length, 0.5 * o.length);
      const Vec3 off = p - h * a;
      const double r = off.norm();
      d = r - o.radius;
      g = r > 0 ? Vec3(off / r) : a.unitOrthogonal();
      break;
    }
    case ObstacleShape::kCylinder: {
      const Vec3 a = o.axis.normalized();
      const double h = p.dot(a);
      const Vec3 rho = p - h * a;
      const double rr = rho.norm();
      const Vec3 radial = rr > 0 ? Vec3(rho / rr) : a.unitOrthogonal();
      const Vec3 along = h >= 0 ? a : Vec3(-a);
      const double dr = rr - o.radius, dh = std::fabs(h) - 0.5 * o.length;
      if (dr > 0 && dh > 0) {
        d = std::hypot(dr, dh);
        g = (dr * radial + dh * along) / d;
      } else if (dr >= dh) {
        d = dr;
        g = radial;
      } else {
        d = dh;
        g = along;
      }
      break;
    }
    case ObstacleShape::kBox: {
      const Vec3 q = p.cwiseAbs() - o.half_size;
      const Vec3 sign = p.unaryExpr([](double v) { return v < 0 ? -1.0 : 1.0; });
      const Vec3 out = q.cwiseMax(0.0);
      const double outside = out.norm();
      if (outside > 0) {
        d = outside;
        g = out.cwiseProduct(sign) / outside;
      } else {
        int m = 0;
        d = q.maxCoeff(&m);
        g = Vec3::Zero();
        g[m] = sign[m];
      }
      break;
    }
    case ObstacleShape::kMesh: {
      Vec3 q = x;
      const double r = std::sqrt(mesh_nearest(o, x, q));
      const bool inside = std::fabs(winding_number(o.vertices, o.faces, x)) >= 0.5;
      d = inside ? -r : r;
      if (r > 0) g = (inside ? -1.0 : 1.0) * (x - q) / r;
      break;
    }
  }
  if (gradient) *gradient = g;
  return d;
}

}  // namespace flagsim
