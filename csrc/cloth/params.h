// Parameters of the mass-spring flag (paper §3), its drag (eq. 3) and its integrator.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "common/enums.h"
#include "common/keyframes.h"
#include "common/types.h"

namespace flagsim {

/// Which vertices `pin` holds: the pole-side column, its two corners, the top row, none.
enum class Pin { kPole, kGrommets, kTop, kNone };
template <>
struct EnumNames<Pin> {
  static constexpr std::array<const char*, 4> names{"pole", "grommets", "top", "none"};
};

enum class DragModel { kPaper, kRelative, kTriangle };
template <>
struct EnumNames<DragModel> {
  static constexpr std::array<const char*, 3> names{"paper", "relative", "triangle"};
};

/// Symplectic Euler (explicit) or backward Euler as Baraff-Witkin (implicit).
enum class Method { kExplicit, kImplicit };
template <>
struct EnumNames<Method> {
  static constexpr std::array<const char*, 2> names{"explicit", "implicit"};
};

enum class Preconditioner { kAuto, kJacobi, kMultigrid, kSsor };
template <>
struct EnumNames<Preconditioner> {
  static constexpr std::array<const char*, 4> names{"auto", "jacobi", "multigrid", "ssor"};
};

/// A rows x cols grid of masses over a width x height rectangle (paper: 8 x 11 masses).
/// Vertex i = r * cols + c; r = 0 is the top row, c = 0 the pole-side column. The rest flag
/// lies in the x-y plane through `origin` (its top pole-side corner), +x away from the pole.
struct FlagParams {
  int rows = 8;
  int cols = 11;
  double width = 0.81;               ///< m, along +x
  double height = 0.54;              ///< m, along -y from origin
  Vec3 origin{0.055, 0.0, 0.0};      ///< m, top pole-side corner
  double areal_density = 0.15;       ///< kg/m^2 (cotton bunting ~0.1-0.2)
  double stretch_stiffness = 100.0;  ///< N/m, structural springs (k_s, eq. 4)
  double shear_stiffness = 20.0;     ///< N/m, diagonal springs
  double bend_stiffness = 5.0;       ///< N/m, skip-one springs
  double damping = 0.02;             ///< N s/m, k_d of eq. 4, every spring
  Pin pin = Pin::kPole;
  std::vector<int> pinned_vertices;  ///< explicit pins; when non-empty, replaces `pin`
  /// m, the largest offset of an unpinned mass out of the flag's plane at the start (seeded,
  /// uniform in [-imperfection, imperfection]; docs/design.md "Still air"). Real cloth is never
  /// flat to the last digit: a flat flag in still air or edge-on wind rests on an unstable
  /// equilibrium (mirror symmetry about its plane) that nothing in the arithmetic breaks.
  /// 0 = perfectly flat. The rest shape (spring lengths) stays flat either way.
  double imperfection = 0.0;
  uint32_t imperfection_seed = 0;  ///< seed of the imperfection's offsets
  /// Keyframed rigid motion of the pinned vertices and the pole together (a flag on a boat, a
  /// banner carried): the pins follow pose(t) of their rest positions exactly, with the velocity
  /// of that motion; the whole flag starts at pose(0). Empty: the pins stay (or follow
  /// Simulation.set_pin_targets). docs/solids.md "Moving pins and solids".
  MotionSchedule pin_motion;
  void validate(const std::string& prefix = "flag") const;
};

/// Air drag on the flag. "paper": eq. 3, D = 1/2 C_D rho S (|u|u - |v|v) per mass;
/// "relative": 1/2 C_D rho S |u-v|(u-v) per mass; "triangle": per triangle, flat-plate
/// pressure C_D on the normal part and skin friction C_T on the tangential part of the relative
/// velocity, two-sided (the normal force's component across the flow is the lift).
struct DragParams {
  DragModel model = DragModel::kPaper;
  double coefficient = 1.0;              ///< C_D
  double tangential_coefficient = 0.05;  ///< C_T, "triangle" only
  void validate(const std::string& prefix = "drag") const;
};

/// Strain a scene with integrator.strain_limit = s promises: s + this. The collision
/// projections run after the last strain-limiting pass and may leave a little more.
constexpr double kStrainLimitSlack = 0.02;

struct IntegratorParams {
  Method method = Method::kImplicit;
  int substeps = 1;            ///< fixed substeps per step (each of dt / substeps)
  bool adaptive = true;        ///< explicit: substep below the stable step estimate
  double safety = 0.9;         ///< fraction of the stable step used when substepping
  int max_substeps = 1000000;  ///< explicit: per step; more is a DivergenceError
  double cg_tolerance = 1e-4;  ///< implicit: relative residual of the CG solve (1e-4 moves
                               ///< the paper flag by 4e-8 m after 1 s vs 1e-10: far below
                               ///< backward Euler's own error of ~3 mm; docs/design.md)
  /// implicit CG: jacobi (3x3 block Jacobi) | multigrid (aggregation K-cycle, grid flags) |
  /// ssor (symmetric block Gauss-Seidel in Eisenstat's form) | auto (multigrid from 500 masses
  /// up, ssor below; docs/design.md)
  Preconditioner preconditioner = Preconditioner::kAuto;
  int cg_max_iterations = 1000;      ///< implicit: per solve; on failure the step is halved
  int max_halvings = 10;             ///< implicit: step halvings before DivergenceError("cg")
  double max_strain = 10.0;          ///< a spring stretched beyond (1 + max_strain) x rest
                                     ///< length raises DivergenceError("strain")
  double strain_limit = 0.1;         ///< > 0: Provot 1995 strain limiting of structural and
                                     ///< shear springs to (1 + strain_limit) x rest; 0 = off
  int strain_limit_iterations = 50;  ///< Gauss-Seidel sweeps at most (stops when satisfied)
  double energy_tolerance = 0.1;     ///< energy a step may make beyond what its stages' work
                                     ///< explains, as a fraction of the flag's energy scale
                                     ///< m |g| H + m U^2 / 2; more raises DivergenceError
                                     ///< ("energy"), and an implicit step is first halved;
                                     ///< 0 = off (docs/energy.md)
  void validate(const std::string& prefix = "integrator") const;
};

}  // namespace flagsim
