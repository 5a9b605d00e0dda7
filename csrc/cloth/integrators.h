// Time integration of the cloth: symplectic Euler with adaptive substepping, and linearised
// backward Euler (Baraff-Witkin 1998 §4-5) solved by CG preconditioned by block Jacobi or an
// aggregation multigrid cycle (flexible CG then; cloth/multigrid.h).
#pragma once
#include <vector>

#include "cloth/forces.h"
#include "cloth/multigrid.h"
#include "cloth/params.h"
#include "cloth/topology.h"

namespace flagsim {

/// Which force stages a scene built, with their parameters. A stage left out costs nothing.
struct ForceSet {
  bool gravity = false;
  bool drag = false;
  bool springs = false;
  Vec3 g{0, -9.81, 0};  ///< m/s^2
  DragParams drag_params;
  double rho = 1.2;     ///< air density, kg/m^3
};

/// Seconds spent per force stage (accumulated).
struct ForceTimings {
  double gravity = 0, drag = 0, springs = 0;
  double strain_limit = 0;  ///< Provot projection after every substep / implicit piece
};

/// f = sum of the built forces at (x, v) with air velocity u (all N x 3).
void compute_forces(const ClothTopology& topo, const ForceSet& fs, const MatX3& x, const MatX3& v,
                    const MatX3& u, MatX3& f, ForceTimings* timings = nullptr);

/// kUnstableStep: explicit without adaptive substeps was asked for a step above the stable-step
/// estimate. It is refused rather than run, because strain limiting would turn the instability
/// into bounded jitter that no finiteness or strain check can see.
enum class IntegrateStatus { kOk, kTooManySubsteps, kCgFailed, kUnstableStep };

struct IntegratorStats {
  long substeps = 0;       ///< explicit: substeps of the last step
  long cg_iterations = 0;  ///< implicit: CG iterations of the last step (all solves)
  long halvings = 0;       ///< implicit: step halvings of the last step
  double stable_step = 0;  ///< explicit: stable step estimate at the start of the last step, s
};

/// Scratch for both integrators, sized once for a topology (no allocation inside a step).
struct IntegratorScratch {
  MatX3 f, x0, v0, dv, r, z, p, q, b, tmp;
  MatX3 dv_prev;    ///< implicit: the solve's dv one step before dv (for the warm start)
  ClothSystem sys;  ///< the implicit system of the current step
  Multigrid mg;     ///< levels built when the topology is a grid (multigrid_applies)
  double unused_timer = 0;
  explicit IntegratorScratch(const ClothTopology& topo);
};

/// The implicit system of a step of h from (x, v) in air u (all N x 3): A's terms (ClothSystem,
/// sized by IntegratorScratch) and Kv = (d f / d x) v (N x 3, N), for b = h (f + h Kv).
void assemble_implicit_system(const ClothTopology& topo, const ForceSet& fs, double h,
                              const MatX3& x, const MatX3& v, const MatX3& u, ClothSystem& A,
                              MatX3& Kv);

/// Advance (x, v) by h. u (N x 3) is the air velocity at the masses, held over the step.
IntegrateStatus integrate(const ClothTopology& topo, const ForceSet& fs, const IntegratorParams& ip,
                          double h, const MatX3& u, MatX3& x, MatX3& v, IntegratorScratch& s,
                          IntegratorStats& stats, ForceTimings* timings = nullptr);

/// Strain limiting: each vertex's distance to its nearest pin is capped at (1 + limit) x its rest
/// distance (long-range attachments, Kim et al. 2012), then (Provot 1995) structural and shear
/// springs longer than (1 + limit) x rest length are shortened
/// by moving their ends (mass-weighted, pinned ends fixed); velocities take the correction / h.
void limit_strain(const ClothTopology& topo, double limit, int iterations, double h, MatX3& x,
                  MatX3& v);

}  // namespace flagsim
