// The pipeline: a Scene built into the stages it needs, stepped as the paper's method reads.
#pragma once
#include <array>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "cloth/forces.h"
#include "cloth/integrators.h"
#include "cloth/topology.h"
#include "fluid/fluid.h"
#include "scene/scene.h"

namespace flagsim {

class Simulation {
 public:
  /// Validates the scene (InvalidArgument on a bad parameter) and builds only the needed stages.
  explicit Simulation(const Scene& scene);

  /// Advance n steps of scene.dt. On divergence throws DivergenceError with the state restored
  /// to the start of the failed step (earlier steps of this call are kept).
  void step(long n = 1);

  const Scene& scene() const { return scene_; }
  const ClothTopology& topology() const { return topo_; }
  double time() const { return time_; }
  long step_count() const { return step_count_; }

  /// (N x 3) state; writable in place (keep the shape), e.g. to set an initial condition.
  MatX3& positions() { return x_; }
  MatX3& velocities() { return v_; }
  const MatX3& positions() const { return x_; }
  const MatX3& velocities() const { return v_; }
  /// (N x 3) unit vertex normals of the current positions, updated after every step.
  const MatX3& normals() const { return n_; }
  /// (N x 3) air velocity at each mass used by the last step, m/s.
  const MatX3& air_at_masses() const { return u_; }

  /// Names of the stages this scene runs, in step order.
  const std::vector<std::string>& stages() const { return stage_names_; }
  /// Seconds spent per built stage since construction.
  std::vector<std::pair<std::string, double>> timings() const;
  ClothEnergy energy() const;
  /// Largest spring strain (l - L) / L of the current positions.
  double max_strain() const { return flagsim::max_strain(topo_, x_); }
  const IntegratorStats& last_step_stats() const { return stats_; }

  /// Air velocity at world points (M x 3) at the current time into out (M x 3).
  void air_velocity(const MatX3& points, MatX3& out) const;

  /// The air grid (air.model "grid" with drag built), or nullptr: the air is analytic or absent.
  Fluid* fluid() { return fluid_.get(); }
  const Fluid* fluid() const { return fluid_.get(); }
  /// Masses that sampled the air grid from outside its domain (nearest boundary value used):
  /// in the last step, and since construction.
  long air_outside_last_step() const { return air_outside_last_; }
  long air_outside_total() const { return air_outside_total_; }

  /// Recompute normals after positions were edited from outside.
  void update_normals();

 private:
  enum Stage { kWind, kFluid, kGravity, kDrag, kSprings, kIntegrate, kStrainLimit, kCheck, kNumStages };
  static const char* stage_name(Stage s);

  void step_once();
  void stage_air();
  void advance_fluid();
  void build_fluid();
  void stage_integrate();
  void stage_check();
  [[noreturn]] void diverge(const std::string& cause, long vertex, const std::string& detail);

  Scene scene_;
  ClothTopology topo_;
  ForceSet forces_;
  IntegratorScratch scratch_;
  IntegratorStats stats_;
  MatX3 x_, v_, n_, u_;    // (N x 3) positions, velocities, normals, air at masses
  MatX3 x_start_, v_start_;  // (N x 3) state at the start of the step (rollback)
  double time_ = 0;
  long step_count_ = 0;
  std::array<bool, kNumStages> built_{};
  std::array<double, kNumStages> seconds_{};
  ForceTimings force_seconds_;
  std::vector<std::string> stage_names_;
  std::unique_ptr<Fluid> fluid_;  // the air grid, when the scene needs one
  long air_outside_last_ = 0, air_outside_total_ = 0;
};

}  // namespace flagsim
