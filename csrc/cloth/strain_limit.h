// Strain limiting (Provot 1995, with long-range attachments): the constraint the integrators
// apply after every substep or implicit piece, and the collision stages between their sweeps.
#pragma once
#include "cloth/topology.h"
#include "common/types.h"

namespace flagsim {

/// Strain limiting: each vertex's distance to its nearest pin, and to the two pins farthest apart,
/// is capped at (1 + limit) x its rest distance (long-range attachments, Kim et al. 2012), then
/// (Provot 1995) structural and shear springs longer than (1 + limit) x rest length are shortened
/// by moving their ends (mass-weighted, pinned ends fixed). Velocities: each limited pair loses the
/// relative velocity along it that still stretches it (inelastic, momentum-conserving; never adds
/// kinetic energy).
/// surface, offset: contact planes or none (ForceSet::contacts, contact_offset): per vertex an
/// outward unit normal n (zero rows: none) and x . n >= offset keeps it out (no offset: 0). A move
/// that would take such a vertex through its plane is cut at the plane, and one on the plane loses
/// its component along -n (it slides along the surface, and the surface takes the rest, as a rope
/// over a post); so does a velocity change of a vertex on its plane. Pulled straight along a tether
/// or spring that runs as a chord through the pole, a vertex would go in, the pole would push it
/// out radially, and each round of the two left the springs more energy (docs/energy.md).
/// pin_work: if given, the work of the pins' impulses is added to it, J: a vertex limited
/// against a pinned one (a tether, or a spring with a pinned end) takes its velocity change from
/// the pin, whose work is that impulse times the pin's velocity (0 for pins at rest). Booked
/// with the pins, it leaves the rest of the change of E the same in every frame: a flag carried
/// at U gains U times that impulse on top of what the still one loses (docs/design.md "Moving
/// pins and Galilean invariance"). speed (N, m/s) or none (still): each plane's speed along its
/// normal (ForceSet::contact_speed); a moving plane's impulse m dv on a vertex does the work
/// m dv . n w, added to pin_work too (a box lifting a flag pushes it up against the tethers).
void limit_strain(const ClothTopology& topo, double limit, int iterations, MatX3& x, MatX3& v,
                  const MatX3* surface = nullptr, const VecX* offset = nullptr,
                  double* pin_work = nullptr, const VecX* speed = nullptr);

/// True when limit_strain would move something: a tether or a structural or shear spring longer
/// than (1 + limit) x its rest length.
bool strain_limit_violated(const ClothTopology& topo, double limit, const MatX3& x);

/// limit_strain, returning the change of total_energy it made, J: 0, with neither the
/// projection nor the energy evaluated, when nothing exceeds the limit. With pin_work, the pins'
/// share (limit_strain's pin_work) is added there and left out of the value returned.
double limit_strain_work(const ClothTopology& topo, const Vec3& g, double limit, int iterations,
                         MatX3& x, MatX3& v, const MatX3* surface = nullptr,
                         const VecX* offset = nullptr, double* pin_work = nullptr,
                         const VecX* speed = nullptr);

}  // namespace flagsim
