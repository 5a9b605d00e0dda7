// Solid shapes shared by the air (cells inside a solid, csrc/fluid/solids.h), the curl noise's
// ramp beside solids (csrc/fluid/turbulence.h) and the cloth's collisions (csrc/collision/
// solids.h): one description, one exact distance.
#pragma once
#include <array>
#include <string>

#include "common/enums.h"
#include "common/types.h"

namespace flagsim {

/// box: centre and half extents along x, y, z; sphere: centre and radius; cylinder: capped, axis
/// through the centre, `length` between its flat caps; capsule: the points within `radius` of the
/// segment of `length` along the axis through the centre (hemispherical ends); mesh: a closed
/// triangle mesh (`vertices`, `faces`, outward winding not required: inside is decided by the
/// winding number), `center` unused.
enum class ObstacleShape { kBox, kSphere, kCylinder, kCapsule, kMesh };
template <>
struct EnumNames<ObstacleShape> {
  static constexpr std::array<const char*, 5> names{"box", "sphere", "cylinder", "capsule", "mesh"};
};

struct SolidGeometry {
  ObstacleShape shape = ObstacleShape::kBox;
  Vec3 center{0, 0, 0};           ///< m
  Vec3 half_size{0.1, 0.1, 0.1};  ///< m, box half extents (shape "box")
  double radius = 0.1;            ///< m (sphere, cylinder, capsule)
  Vec3 axis{0, 0, 1};             ///< cylinder and capsule axis, normalised on use
  double length = 1.0;            ///< m, cylinder length between its caps; capsule segment
  MatX3 vertices;                 ///< (M x 3) m, shape "mesh"
  MatX3i faces;                   ///< (F x 3) indices into vertices, shape "mesh"
  /// True when point x (m) lies inside (closed).
  bool contains(const Vec3& x) const;
  /// The solid's thinnest extent, m: the smallest box edge, the diameter, or the mesh's
  /// smallest bounding-box edge.
  double thickness() const;
  /// Throws InvalidArgument naming "<prefix>.<field>" (e.g. "solids[0].faces[3]"). Field by
  /// field: face indices are checked once vertices are set.
  void validate_geometry(const std::string& prefix) const;
  /// A complete mesh (shape "mesh": >= 4 vertices and faces, indices in range); what the air and
  /// the cloth need before they use the solid (Scene and Fluid validation).
  void validate_mesh(const std::string& prefix) const;
};

/// Signed distance from x to the solid's surface, m (negative inside), exact for every shape
/// (the mesh's by its nearest triangle, signed by the winding number); the unit outward
/// gradient into *gradient if given (from the nearest surface point; +x where it is undefined).
double solid_distance(const SolidGeometry& s, const Vec3& x, Vec3* gradient = nullptr);

/// The generalised winding number of the closed mesh (vertices, faces) at x (Jacobson et al.
/// 2013: the solid angles of the triangles over 4 pi, Van Oosterom-Strackee): ~1 inside, ~0
/// outside, whichever way the faces wind consistently (its sign follows the winding).
double winding_number(const MatX3& vertices, const MatX3i& faces, const Vec3& x);

/// The point of triangle (a, b, c) nearest to p (Ericson, Real-Time Collision Detection §5.1.5).
Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

}  // namespace flagsim
