// The flapping stage of a Simulation step (paper eq. 5), in the three ways a scene can use it:
// "displace" (the paper: the wave moves the cloth, as a drift of the positions the integrator
// carries), "force" (the force that would move a free mass along the wave) and "visual" (the
// exported geometry only). It owns eq. 5's per-vertex inputs and the wave already applied; the
// Simulation gives it the air speed at the pole (u_p) and the normals, and times it.
#pragma once
#include "cloth/topology.h"
#include "common/types.h"
#include "flapping/flapping.h"
#include "flapping/params.h"
#include "flapping/perlin.h"

namespace flagsim {

class FlapStage {
 public:
  FlapStage() = default;
  /// Eq. 5's inputs for this flag: x, y = the rest uv; L = the rest distance to the nearest pin
  /// (the topology's tether length; 0 at a pin, infinite without pins).
  FlapStage(const ClothTopology& topo, const FlappingParams& p);

  /// "displace": eq. 5 at t1, and the drift (dz / h) n that moves each free vertex from the wave
  /// applied so far to it over a piece of h (pinned vertices stay put).
  void drift(const ClothTopology& topo, const MatX3& n, double u_p, double t1, double h,
             MatX3& drift);
  /// "force": F = m d2z/dt2 n (the central difference over h around t1), none on pinned vertices.
  void force(const ClothTopology& topo, const MatX3& n, double u_p, double t1, double h,
             MatX3& force);
  /// "visual": eq. 5 at t applied to x along n, into render_x (N x 3).
  void displace(const MatX3& x, const MatX3& n, double u_p, double t, MatX3& render_x);

  /// The piece passed: its wave is now on the cloth ("displace").
  void commit() { applied_ = z_; }
  /// Rollback: the wave applied at the start of the step.
  void save_step_start() { start_ = applied_; }
  void restore_step_start() { applied_ = start_; }

  /// (N) m, eq. 5's z at the last evaluation (zeros before any).
  const VecX& z() const { return z_; }

  /// Where u_p is sampled: the flag's pole-side edge (column 0) at rest, (rows x 3).
  static MatX3 pole_edge_points(const ClothTopology& topo);

 private:
  FlappingParams p_;
  Perlin1D noise_{0};
  MatX2 xy_;             // (N x 2) eq. 5's normalised (x, y)
  VecX L_;               // (N) m
  VecX z_;               // (N) m, z at the last evaluation
  VecX applied_;         // (N) m, "displace": z already on the cloth
  VecX start_;           // (N) m, applied_ at the start of the step
  VecX before_, after_;  // (N) m, "force": z at t1 - h and t1 + h
};

}  // namespace flagsim
