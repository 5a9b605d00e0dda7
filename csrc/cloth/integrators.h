// Time integration of the cloth: symplectic Euler with adaptive substepping, and linearised
// backward Euler (Baraff-Witkin 1998 §4-5) solved by CG preconditioned by block Jacobi, symmetric
// block Gauss-Seidel in Eisenstat's form, or an aggregation multigrid cycle (flexible CG then;
// cloth/multigrid.h).
#pragma once
#include <limits>
#include <vector>

#include "cloth/forces.h"
#include "cloth/multigrid.h"
#include "cloth/params.h"
#include "cloth/strain_limit.h"
#include "cloth/topology.h"
#include "common/stage_clock.h"

namespace flagsim {

/// A free vertex held on a solid (or the pole) by the implicit solve: the surface's outward unit
/// normal at it, and the velocity along it the vertex ends the piece with: the plane's own speed
/// w (ForceSet::contact_speed; 0 at rest), less gap / h when it starts gap short of the plane,
/// so that it ends there (a speculative contact).
struct RestingContact {
  int32_t vertex = -1;
  Vec3 normal = Vec3::Zero();
  double approach = 0;  ///< m/s, <= w
  double w = 0;         ///< m/s, the plane's speed along the normal
  double bn = 0;        ///< N s, the right-hand side along the normal when it was held
};

/// Which force stages a scene built, with their parameters. A stage left out costs nothing.
struct ForceSet {
  bool gravity = false;
  bool drag = false;
  bool springs = false;
  Vec3 g{0, -9.81, 0};  ///< m/s^2
  DragParams drag_params;
  double rho = 1.2;  ///< air density, kg/m^3
  /// J. Implicit: a piece of a step whose energy gain beyond the work of the forces (the
  /// positive parts of its remainder and of its strain-limit work, StepWork) exceeds this is
  /// redone as two pieces of half the length (as a failed CG solve is); 0 = off. The Simulation
  /// sets integrator.energy_tolerance x its energy scale.
  double energy_guard = 0;
  /// Explicit adaptive: substeps are at most refine x safety x the stable step estimate. A
  /// step redone in 2^k pieces after an implausible one runs at refine = 2^-k: shorter pieces
  /// alone would not shorten substeps that the stable step sets.
  double refine = 1.0;
  /// (N x 3) N, a force held over the step on top of the built ones (eq. 5 "force"), or none.
  const MatX3* external = nullptr;
  /// (N x 3) m/s, a prescribed velocity the positions follow on top of v over the step, or
  /// none: x' = x + h (v' + drift). Springs answer it inside the solve; damping and drag do not
  /// see it (eq. 5 "displace": dz n / h). Zero rows where pinned.
  const MatX3* drift = nullptr;
  /// (N x 3) N s, or none: the drag impulse each mass received, as the integrator applied the
  /// drag (StepWork::drag's force times each piece's length), is added here. Pinned masses
  /// included (the pins take theirs). Two-way coupling gives it back to the air; the pole force
  /// is read from it (Simulation).
  MatX3* drag_impulse = nullptr;
  /// (N) or none: each mass's drag, force and velocity Jacobian, times this factor (two-way
  /// coupling's implicit air response, 1 / (1 + kappa_i); docs/coupling.md). A triangle's
  /// Jacobian block ("triangle" drag) takes the mean of its vertices' factors (kept symmetric).
  const VecX* drag_scale = nullptr;
  /// Contact planes of the free vertices near a solid or the pole, or none: per vertex the
  /// outward unit normal n of the surface (a zero row: no contact) and an offset o at the piece's
  /// end, so that x . n >= o keeps the vertex out (o is the surface, a little outside it: gap =
  /// x . n - o <= 0 means touching); a moving surface's plane moves along n at contact_speed w.
  /// Implicit: each touching one whose forces at the piece's start push it in (f . n < 0) and
  /// whose velocity does not leave it (v . n <= w + 1e-9 m/s) ends the piece moving with the
  /// plane (v . n = w), its other two directions solved as usual (Baraff-Witkin 1998 §5.3, the
  /// filter S = I - n n^T inside CG); any other that the solve's answer carries through its plane
  /// is held too, ending the piece on the plane (speed w - gap / h along n), and the solve is
  /// finished with it. The plane's impulse goes to StepWork::contact_impulse, the work of a moving
  /// one (impulse . w n) to StepWork::pins. Without this the springs pull a draped flag into its
  /// solid, or a flag wrapped round its pole into the pole, in every solve and the projection
  /// pushes it back: energy the check cannot explain. Strain limiting keeps these vertices on their
  /// side of the plane too (limit_strain's `surface`).
  const MatX3* contacts = nullptr;
  const VecX* contact_offset = nullptr;  ///< (N) m, the planes' offsets o at the piece's end
  /// (N) m/s or none (still): each plane's speed w along its normal over the piece (a moving
  /// pole or solid), so that it is at o - w h at the piece's start; a held vertex ends moving
  /// with it.
  const VecX* contact_speed = nullptr;
};

/// Seconds spent per force stage (accumulated).

/// f = sum of the built forces at (x, v) with air velocity u (all N x 3); drag (N x 3) gets the
/// drag alone when it is built (for the energy bookkeeping), and is left as it was otherwise.
void compute_forces(const ClothTopology& topo, const ForceSet& fs, const MatX3& x, const MatX3& v,
                    const MatX3& u, MatX3& f, MatX3& drag, StageClock* clock = nullptr);

/// kUnstableStep: explicit without adaptive substeps was asked for a step above the stable-step
/// estimate. It is refused rather than run, because strain limiting would turn the instability
/// into bounded jitter that no finiteness or strain check can see.
/// kEnergyGain: an implicit step still made energy beyond ForceSet::energy_guard after
/// max_halvings halvings.
enum class IntegrateStatus { kOk, kTooManySubsteps, kCgFailed, kUnstableStep, kEnergyGain };

/// Energy bookkeeping of one integrate() call, J. The work of each force is the force as the
/// integrator applied it times the displacement it made, W = sum_i f_i . dx_i: explicit, f at the
/// substep's start; implicit, the linearised end-of-step force f0 + K dx + D dv of Baraff-Witkin
/// eq. 16 (damping is linear, so there it is exactly k_d (v'_j - v'_i)). Gravity is not listed:
/// its work is the change of the gravity term of total_energy. `drift` is the work of the drift's
/// share h r of the displacement against springs and gravity, -f_c . h r, with f_c as applied
/// (first order; splitting x' at x' - h r instead is arbitrary once the springs answer the
/// drift, and put +-1e4 J in each of drift and remainder). `pins` is the work of the pins
/// holding pinned vertices that move (-f . dx over pinned vertices, f at the start of the piece).
/// `remainder` closes the balance
///   E_after - E_before = drag + external + drift + damping + pins + strain_limit + remainder,
/// E = total_energy. For linear springs it is, per piece, -1/2 |dv|^2_M - 1/2 dx^T H dx <= 0
/// implicit (backward Euler dissipates) and -1/2 |dv|^2_M + 1/2 dx^T H dx explicit (symplectic
/// Euler: bounded, oscillating); docs/energy.md derives both.
struct StepWork {
  double drag = 0;          ///< air drag (wind, fans and the grid all act through it)
  double external = 0;      ///< ForceSet::external
  double drift = 0;         ///< ForceSet::drift against springs and gravity
  double damping = 0;       ///< spring damping, eq. 4 (<= 0)
  double pins = 0;          ///< pins that move, and moving contact planes
  double strain_limit = 0;  ///< energy change made by strain limiting inside the step
  double remainder = 0;     ///< the integrator's own (numerical) energy change
  /// N s, not energy: the impulse the contact planes (ForceSet::contacts: the solids' and the
  /// pole's) gave the flag, so that the pins' impulse leaves it out.
  Vec3 contact_impulse = Vec3::Zero();
  /// The energy the booked stages account for (everything but the remainder), J.
  double booked() const { return drag + external + drift + damping + pins + strain_limit; }
  StepWork& operator+=(const StepWork& o) {
    drag += o.drag, external += o.external, drift += o.drift, damping += o.damping;
    pins += o.pins;
    strain_limit += o.strain_limit;
    remainder += o.remainder;
    contact_impulse += o.contact_impulse;
    return *this;
  }
};

struct IntegratorStats {
  long substeps = 0;         ///< explicit: substeps of the last step
  long cg_iterations = 0;    ///< implicit: CG iterations of the last step (all solves)
  long halvings = 0;         ///< implicit: step halvings of the last step
  double stable_step = 0;    ///< explicit: stable step estimate at the start of the last step, s
  long energy_halvings = 0;  ///< implicit: halvings of the last step caused by energy gain
  StepWork work;             ///< the last step's energy bookkeeping
  double energy_before = 0;  ///< J, total_energy at the start of the last step
  double energy_after = 0;   ///< J, total_energy at its end
};

/// Scratch for both integrators, sized once for a topology (no allocation inside a step).
struct IntegratorScratch {
  MatX3 f, fd, x0, v0, dv, r, z, p, q, b, tmp;  // fd: the drag part of f
  MatX3 t, u, Dw;  ///< implicit, ssor: eisenstat_product's t, scratch and D w
  MatX3 impulse0;  ///< implicit: ForceSet::drag_impulse at the start of a halving level
  MatX3 dv_prev;   ///< implicit: the solve's dv one step before dv (for the warm start)
  std::vector<RestingContact> held;  ///< implicit: the contacts the current solve holds
  std::vector<uint8_t> is_held;      ///< implicit: per vertex, 1 when in `held`
  ClothSystem sys;                   ///< the implicit system of the current step
  Multigrid mg;  ///< levels built when the topology is a grid (multigrid_applies)
  /// E = total_energy of (x, v) as integrate() is next called, when the caller knows it (J;
  /// NaN: not known). integrate() reads it once, in place of computing E, and resets it to NaN.
  double energy_known = std::numeric_limits<double>::quiet_NaN();
  explicit IntegratorScratch(const ClothTopology& topo);
};

/// The implicit system of a step of h from (x, v) in air u (all N x 3): A's terms (ClothSystem,
/// sized by IntegratorScratch) and Kv = (d f / d x) w (N x 3, N), for b = h (f + h Kv), with w
/// the velocity the positions move with: `moving_velocity` (N x 3; v + drift) if given, else v.
void assemble_implicit_system(const ClothTopology& topo, const ForceSet& fs, double h,
                              const MatX3& x, const MatX3& v, const MatX3& u, ClothSystem& A,
                              MatX3& Kv, const MatX3* moving_velocity = nullptr);

/// Advance (x, v) by h. u (N x 3) is the air velocity at the masses, held over the step.
IntegrateStatus integrate(const ClothTopology& topo, const ForceSet& fs, const IntegratorParams& ip,
                          double h, const MatX3& u, MatX3& x, MatX3& v, IntegratorScratch& s,
                          IntegratorStats& stats, StageClock* clock = nullptr);

}  // namespace flagsim
