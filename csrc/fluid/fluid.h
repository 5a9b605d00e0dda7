// The air solver: Stable Fluids (Stam 1999) on a staggered MAC grid. Owns the arrays and scratch
// (allocated at construction, never resized) and sequences the kernels of advect.h, forces.h,
// solids.h and pressure.h. One step:
//   advect (semi-Lagrangian | MacCormack; on periodic grids without solids with nu dt / h^2 <=
//   0.01 plus the explicit viscous term of u^n) -> fans -> boundary values (tunnel faces,
//   solids) / mean flow -> diffuse (implicit; explicit substeps beside no-slip walls and solids;
//   skipped when viscosity = 0 or done in the advection) -> project (fft | pcg | multigrid) ->
//   solids' faces held again
// Layout of the component arrays: csrc/fluid/grid.h. Scalar type: params.precision.
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/types.h"
#include "fluid/grid.h"
#include "fluid/params.h"

namespace flagsim {

/// Counters of the last step (and of sampling), for Simulation stats and tests.
struct FluidStats {
  long steps = 0;
  int pressure_iterations = 0;     ///< pcg, multigrid: CG iterations of the last projection; fft: 0
  double pressure_residual = 0;    ///< pcg, multigrid: max|div u| / max|div u*| after the last one
  bool pressure_converged = true;  ///< pcg, multigrid: reached its tolerance in the last projection
  int diffusion_iterations = 0;    ///< iterative diffusion: max CG iterations over components
  long samples_outside = 0;        ///< points sampled outside the domain box, cumulative
  /// Cumulative wall-clock seconds per stage of step().
  double seconds_advect = 0, seconds_forces = 0, seconds_project = 0;
};

/// Impulses a body gives the air over one step (two-way coupling, docs/coupling.md): impulses
/// (M x 3, N s) at points (M x 3, m). The step spreads them onto the faces with the weights
/// sample() reads the faces with at those points (spread_velocity, its transpose), as the
/// velocity change w J / (density h^3), after advection and before the projection.
struct PointImpulses {
  const MatX3* points = nullptr;
  const MatX3* impulses = nullptr;
};

class Fluid {
 public:
  /// Validates `params` (errors name "<prefix>.<field>", or the bare field when prefix is
  /// empty), builds the grid, the FFTW plans (fft) or the MIC(0) preconditioner (pcg), the fan
  /// stencils, and sets the velocity to the wind at t = 0 (tunnel: (wind.x, 0, 0)).
  explicit Fluid(const FluidParams& params, const std::string& prefix = "");
  ~Fluid();
  Fluid(Fluid&&) noexcept;
  Fluid& operator=(Fluid&&) noexcept;
  Fluid(const Fluid&) = delete;
  Fluid& operator=(const Fluid&) = delete;

  /// A hold on a step: wait(arg) is called once inside step(), after the step has copied u^n
  /// for itself and before it first writes the velocity grid, so that another thread may still
  /// read u^n until wait returns (the Simulation's pipeline samples it at the cloth's masses).
  struct WriteGate {
    void (*wait)(const void* arg) = nullptr;
    const void* arg = nullptr;
  };

  /// Advances the air by dt (s, finite and > 0), with the impulses bodies give it over the step
  /// (or none), held at `gate` (or not). No heap allocation.
  void step(double dt, const std::vector<PointImpulses>* impulses = nullptr,
            const WriteGate* gate = nullptr);
  /// Takes back the last step, which returned normally: the field and the time as they were
  /// before it (from the copy of u^n the step keeps anyway) and, after keep_warm_start(), the
  /// iterative pressure solve's warm start too, so that taking the step again gives the same
  /// bits (without it the warm start restarts from zero). Once per step; no heap allocation.
  /// The Simulation's pipeline takes back an air step that ran beside a cloth step which failed
  /// or is redone in pieces.
  void undo_step();
  /// From now on every step keeps the iterative pressure solve's warm start for undo_step (one
  /// cell array, copied per step; fft and air without an iterative solve keep nothing more).
  /// Allocates: call it before stepping.
  void keep_warm_start();
  double time() const;  ///< s
  const FluidParams& params() const;
  const GridGeometry& geometry() const;
  bool is_double() const;  ///< params.precision == Precision::kDouble
  const FluidStats& stats() const;

  /// Shape of component c (0 = u, 1 = v, 2 = w), see grid.h.
  Shape3 component_shape(int c) const;
  /// Raw storage of component c: float* or double* by precision (m/s), component_shape(c).size().
  void* component_data(int c);
  const void* component_data(int c) const;
  /// World positions of the nodes of component c, (size x 3), m, C order of component_shape(c).
  MatX3 face_positions(int c) const;
  /// Copies values (component_shape(c).size(), m/s) into component c. Non-finite ->
  /// InvalidArgument.
  void set_component(int c, const double* values);
  /// Sets every component to a uniform velocity (m/s); tunnel wall normals stay 0.
  void set_uniform(const Vec3& velocity);
  /// The pressure solve's solid cells: mask nx*ny*nz (C order), nonzero = solid. A solid cell is
  /// no unknown of the projection (phi = 0 there) and no flux crosses a face to it (Neumann).
  /// Rebuilds the MIC factor or the multigrid hierarchy (allocates; not during a step).
  /// Low level: the obstacles (which also hold the velocity on solid faces) call it; on its own
  /// it changes only the pressure solve. pressure "fft" takes no solid cell (InvalidArgument).
  void set_solid_cells(const uint8_t* mask);

  /// Trilinear velocity at points (m x 3, m) into out (m x 3, m/s). Points outside the domain get
  /// the nearest boundary value; returns how many were outside (also added to stats). No
  /// allocation.
  long sample(const double* points, long m, double* out) const;
  long sample(const MatX3& points, MatX3& out) const {
    return sample(points.data(), long(points.rows()), out.data());
  }
  /// Per point (m x 3, m), the sum of the squared weights sample() gives the nodes it reads
  /// there, the largest over the components, into out (m): 1/8 at a cell centre, 1 on a node
  /// (sample_weight_squares, fluid/advect.h). No allocation.
  void sample_weight_squares(const double* points, long m, double* out) const;
  /// Adds a static solid (validated; errors name "obstacle.<field>") and rebuilds the solid cells
  /// and the pressure solve's set-up; held faces are zeroed at once. Not during a step.
  void add_obstacle(const ObstacleParams& obstacle);
  /// The force the air exerts on obstacle `index` (N): pressure plus viscous (no-slip), from the
  /// last step's pressure and the current velocity (csrc/fluid/solids.h). Zero before any step.
  Vec3 obstacle_force(int index) const;
  /// Per cell (nx*ny*nz, C order): 0 = air, 1 + index of the obstacle that owns it.
  const std::vector<uint16_t>& solid_owner() const;
  /// What the solids' resolution leaves out (obstacles thinner than the wake needs, or covering
  /// no cell), one sentence each; empty when all is well.
  std::vector<std::string> warnings() const;

  /// Cell divergence of the current field (nx*ny*nz, 1/s, C order) and its max |.|.
  void divergence(double* out) const;
  double max_divergence() const;

  /// Implementation, one per scalar type (opaque to users).
  struct Solver;

 private:
  std::unique_ptr<Solver> s_;
};

}  // namespace flagsim
