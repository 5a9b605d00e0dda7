// Solids the cloth collides with: boxes, spheres, capped cylinders, capsules and closed triangle
// meshes (common/shapes.h, the description the air's obstacles share), at rest or moving
// rigidly, each with a contact thickness and Coulomb friction.
//
// Continuous: a vertex's path over the piece is swept against the solid grown by the thickness
// (sphere tracing on the exact distance, which never steps past the surface), so a vertex cannot
// pass through a wall thinner than its step; a vertex that ends within the thickness is pushed
// out along the distance's gradient. Response: the vertex stops where its path met the grown
// surface and keeps the rest of its motion tangent to it; its velocity relative to the surface
// loses its inward normal part (inelastic) and, by Coulomb friction, up to friction x that much
// of its tangential part.
#pragma once
#include "common/keyframes.h"
#include "common/shapes.h"
#include "common/types.h"

namespace flagsim {

/// A solid as the cloth sees it, set up once: its geometry at rest, thickness, friction and the
/// bounding box of the geometry grown by the thickness (a vertex path outside it is skipped).
struct ClothSolid {
  SolidGeometry geometry;
  double thickness = 0.005;  ///< m, the distance the cloth's vertices keep from the surface
  double friction = 0.0;     ///< Coulomb coefficient
  Vec3 lo, hi;               ///< m, bounding box of the geometry grown by the thickness
  ClothSolid() = default;
  ClothSolid(SolidGeometry g, double thickness, double friction);
};

struct SolidContacts {
  Index moved = 0;       ///< vertices moved out of the solid (or stopped on it)
  double wall_work = 0;  ///< J, sum of m dv . (surface velocity): the work a moving solid did
};

/// Keeps every free vertex (inv_mass > 0) at least s.thickness outside the solid.
/// x0 (N x 3) m, positions at the piece's start; x, v (N x 3) m, m/s, at its end (in/out);
/// mass (N) kg; motion: the solid moving rigidly over the piece (its geometry is at rest; it is
/// at motion->from at x0's time and at motion->to at x's), or nullptr for a solid at rest.
SolidContacts collide_solid(const ClothSolid& s, const RigidMotion* motion, const MatX3& x0,
                            MatX3& x, MatX3& v, const VecX& inv_mass, const VecX& mass);

}  // namespace flagsim
