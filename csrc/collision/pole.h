// The pole: a vertical (+y) cylinder of PoleParams::radius from base.y to base.y + height, around
// the axis through base. Vertices collide with it so that a flag blown back wraps around it.
#pragma once
#include "collision/params.h"
#include "common/keyframes.h"
#include "common/types.h"

namespace flagsim {

/// True when p is strictly inside the cylinder shrunk by `tolerance` (m) on every face.
bool inside_pole(const PoleParams& pole, const Vec3& p, double tolerance = 0.0);

/// Keeps every free vertex (inv_mass > 0) out of the pole.
/// x0  N x 3 positions at the start of the step, m (outside the pole)
/// x   N x 3 positions at the end of the step, m (in/out)
/// v   N x 3 velocities, m/s (in/out)
/// A vertex ending inside is moved to the nearest point of the surface (side or a cap; sliding
/// is kept); one whose path x0 -> x passed through the pole and out again is stopped where it
/// entered. The velocity's component into the surface (outward normal n, v . n < 0) is removed.
/// Returns the number of vertices moved (and the largest move, m, in *max_move if given).
/// Vertices inside the pole at x0 are projected to its surface like the rest.
/// motion: the pole moving rigidly over the piece (PoleParams describe it at rest; it is at
/// motion->from at x0's time and at motion->to at x's): the test runs in the pole's frame on the
/// path from.inverse(x0) -> to.inverse(x), and the velocity's component into the surface is
/// removed relative to the surface's own velocity there. nullptr: the pole at rest.
/// mass, wall_work: with a moving pole, the pole's work on the vertices it stops, the sum of
/// m dv . v_surface (J, as collide_solid's), is added to *wall_work (mass required then).
Index collide_pole(const PoleParams& pole, const MatX3& x0, MatX3& x, MatX3& v,
                   const VecX& inv_mass, double* max_move = nullptr,
                   const RigidMotion* motion = nullptr, const VecX* mass = nullptr,
                   double* wall_work = nullptr);

/// collide_pole in the frame a moving pole is at rest in, as a sweep that runs there sees it
/// (self-collision in the pins' frame): x0 already carried by `motion` to the piece's end, so the
/// pole is at motion.to at both ends of the path x0 -> x; velocities are taken relative to its
/// surface's, motion.velocity_at. Its work is the frame's (the caller books V . dP).
Index collide_pole_carried(const PoleParams& pole, const RigidMotion& motion, const MatX3& x0,
                           MatX3& x, MatX3& v, const VecX& inv_mass, double* max_move = nullptr);

/// inside_pole for the pole where motion->to puts it (nullptr: at rest); x in the world, m.
inline bool inside_moved_pole(const PoleParams& pole, const RigidMotion* motion, const Vec3& x,
                              double tolerance = 0.0) {
  return inside_pole(pole, motion ? motion->to.inverse(x) : x, tolerance);
}

}  // namespace flagsim
