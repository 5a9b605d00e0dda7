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
#include "collision/self_collision.h"
#include "flapping/perlin.h"
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
  /// (N x 3) geometry to export and render: with flapping.mode "visual" the positions displaced
  /// by eq. 5 along the normals (physics untouched), otherwise the positions themselves.
  const MatX3& render_positions() const { return visual_ ? render_x_ : x_; }
  /// (N x 3) unit vertex normals of render_positions().
  const MatX3& render_normals() const { return visual_ ? render_n_ : n_; }
  /// (N) eq. 5 displacement z of each vertex at the current time, m (zero with flapping off).
  const VecX& flap_displacement() const { return flap_z_; }
  /// u_p of eq. 5: mean air speed along the pole-side edge at the last flap stage, m/s.
  double pole_air_speed() const { return u_p_; }
  /// Statistics of the last self-collision stage; nullptr when the stage is not built.
  const SelfCollisionStats* self_collision_stats() const {
    return self_collision_ ? &self_collision_->stats() : nullptr;
  }

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
  enum Stage {
    kWind, kFluid, kGravity, kDrag, kSprings, kIntegrate, kStrainLimit,
    kFlap,           // "displace" / "force": before the collisions, which then see its motion
    kPole, kSelfCollision, kCheck,
    kFlapVisual,     // "visual": after the step, on the exported geometry only
    kNumStages
  };
  static const char* stage_name(Stage s);

  void step_once();
  void stage_air();
  void advance_fluid();
  void build_fluid();
  void stage_integrate();
  void stage_check();
  void setup_flapping();
  double sample_pole_air_speed();
  void stage_flap();
  void stage_collide();
  void limit_cloth_strain(MatX3& x, MatX3& v);
  void stage_flap_visual();
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

  // Flapping (paper eq. 5), set up only when flapping.mode != "off".
  Perlin1D noise_{0};
  MatX2 flap_xy_;              // (N x 2) eq. 5's normalised (x, y): the rest uv
  VecX flap_L_;                // (N) m, rest distance to the nearest pinned vertex
  VecX flap_z_;                // (N) m, z at the current time
  VecX flap_applied_;          // (N) m, "displace": z already applied to the cloth
  VecX flap_before_, flap_after_;  // (N) m, "force": z at t - dt and t + dt
  MatX3 edge_points_, edge_air_;   // (P x 3) where u_p is sampled, and the air there
  double u_p_ = 0;
  bool visual_ = false;
  MatX3 render_x_, render_n_;  // (N x 3) "visual" geometry

  std::unique_ptr<SelfCollision> self_collision_;
  SelfCollision::Projector strain_projector_;  // built once: no allocation per step
  long air_outside_last_ = 0, air_outside_total_ = 0;
};

}  // namespace flagsim
