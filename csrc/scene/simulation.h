// The pipeline: a Scene built into the stages it needs, stepped as the paper's method reads.
#pragma once
#include <array>
#include <atomic>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "cloth/forces.h"
#include "cloth/integrators.h"
#include "cloth/topology.h"
#include "collision/self_collision.h"
#include "collision/solids.h"
#include "common/parallel.h"
#include "flapping/flap_stage.h"
#include "fluid/fluid.h"
#include "fluid/turbulence.h"
#include "scene/scene.h"

namespace flagsim {

/// The halvings of one step, by the check that refused (docs/energy.md "The plausibility
/// check"). A step's redo in 2^k pieces counts k, one per level, under the cause that refused the
/// level before it; a piece the implicit integrator halved counts once per halving, in every
/// piece of every level tried. Plain counts: a run's halvings by cause are their sums.
struct StepHalvings {
  long energy = 0;        ///< step redone: energy no stage explains (the check's "energy")
  long strain = 0;        ///< step redone: strain beyond integrator.strain_limit's promise
  long piece_energy = 0;  ///< implicit piece halved: its remainder or strain limiting's work
                          ///< above the guard (ForceSet::energy_guard)
  long cg = 0;            ///< implicit piece halved: CG did not reach integrator.cg_tolerance
  long total() const { return energy + strain + piece_energy + cg; }
};

/// Energy the flag took from or gave to each stage since the Simulation was built, J
/// (docs/energy.md). Balance, with E_mech = kinetic + spring and E = E_mech + gravity potential
/// (the three terms of energy()):
///   E_mech(t) - E_mech(0) = sum of every entry,   E(t) - E(0) = the same sum without `gravity`.
/// Forces count as the integrator applied them (StepWork); a projection or a displacement counts
/// as the change of E it made. `integrator` is what is left: backward Euler's numerical
/// dissipation (<= 0 for linear springs), symplectic Euler's bounded oscillation.
struct EnergyLedger {
  double gravity = 0;         ///< work of gravity, minus the change of its potential
  double drag = 0;            ///< air drag: wind, fans and the grid push the flag through it
  double damping = 0;         ///< spring damping, eq. 4 (<= 0)
  double flap = 0;            ///< eq. 5 flapping, "displace" or "force"
  double strain_limit = 0;    ///< strain limiting, in the integrator and between pole passes
  double pole = 0;            ///< the pole's collision projection
  double self_collision = 0;  ///< the self-collision response, with the strain limiting and
                              ///< pole passes inside its sweeps
  double pins = 0;            ///< prescribed motion: pinned vertices that move (the pins'
                              ///< reaction force . their velocity, and the kinetic energy they
                              ///< give the pinned masses), and moving solids' pushes
  double solids = 0;          ///< the solids' collision projection (less a moving solid's push)
  double edits = 0;           ///< the state written from outside between steps
  double integrator = 0;      ///< remainder: the integrator's numerical energy change
  /// The part no physical stage explains, from the ledger at `before` to this one: the positive
  /// part of the change of the integrator remainder plus that of the projections together
  /// (strain limiting, pole, self-collision, which alternate within a step). Backward Euler and
  /// the projections should only take energy out; counted apart, neither can hide the other's
  /// gain (a projection pumping the springs that the next solve damps).
  double unexplained_since(const EnergyLedger& before) const;
  /// Net since construction: integrator + strain limiting + pole + solids + self-collision, J. What
  /// the flag still holds of the energy no stage explains (dissipation counts back).
  double unexplained_net() const;
};

/// The ledger's entries by name, in the order energy_ledger() reports them (Python dict keys).
inline constexpr std::array<std::pair<const char*, double EnergyLedger::*>, 11> kLedgerEntries{{
    {"gravity", &EnergyLedger::gravity},
    {"drag", &EnergyLedger::drag},
    {"damping", &EnergyLedger::damping},
    {"flap", &EnergyLedger::flap},
    {"strain_limit", &EnergyLedger::strain_limit},
    {"pole", &EnergyLedger::pole},
    {"solids", &EnergyLedger::solids},
    {"self_collision", &EnergyLedger::self_collision},
    {"pins", &EnergyLedger::pins},
    {"edits", &EnergyLedger::edits},
    {"integrator", &EnergyLedger::integrator},
}};

/// A scene of one or several flags. Flag 0's state and topology are this object's own (so a
/// one-flag scene reads as it always did); flags 1, 2, ... are Simulations of their own that
/// this one owns and steps (flag(i)), each with its topology, state, stages, energy ledger and
/// checks, sampling the one air grid, which this Simulation steps once per step. Contacts
/// between flags: one self-collision pass over the union of the flags after they all stepped
/// (stage_between_flags; docs/multiflag.md).
class Simulation {
 public:
  /// Validates the scene (InvalidArgument on a bad parameter) and builds only the needed stages.
  explicit Simulation(const Scene& scene);
  ~Simulation();

  /// Advance n steps of scene.dt. On divergence throws DivergenceError with the state restored
  /// to the start of the failed step (earlier steps of this call are kept). One thread at a
  /// time: a call while another thread is stepping this Simulation throws std::runtime_error.
  void step(long n = 1);

  /// Flags in the scene (scene.num_flags()).
  int num_flags() const { return 1 + int(others_.size()); }
  /// Flag i (0 <= i < num_flags()): this Simulation for i = 0, else the one that holds flag i;
  /// its positions(), velocities(), normals(), topology(), energy... are that flag's. Only the
  /// Simulation that owns it steps it (its own step() throws).
  Simulation& flag(int i);
  const Simulation& flag(int i) const { return const_cast<Simulation*>(this)->flag(i); }
  /// Statistics of the last pass between flags; nullptr with one flag or self-collision off
  /// (all zeros after a step in which no two flags' swept boxes came within the thickness).
  const SelfCollisionStats* between_flags_stats() const {
    return between_ ? &between_stats_ : nullptr;
  }

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
  const MatX3& render_positions() const { return built(Stage::kFlapVisual) ? render_x_ : x_; }
  /// (N x 3) unit vertex normals of render_positions().
  const MatX3& render_normals() const { return built(Stage::kFlapVisual) ? render_n_ : n_; }
  /// (N) eq. 5 displacement z of each vertex at the current time, m (zero with flapping off).
  const VecX& flap_displacement() const {
    return built(Stage::kFlap) || built(Stage::kFlapVisual) ? flap_.z() : flap_off_z_;
  }
  /// u_p of eq. 5: mean air speed along the pole-side edge at the last flap stage, m/s.
  double pole_air_speed() const { return u_p_; }
  /// Statistics of the last self-collision stage; nullptr when the stage is not built.
  const SelfCollisionStats* self_collision_stats() const {
    return self_collision_ ? &self_collision_->stats() : nullptr;
  }

  /// Names of the stages this scene runs (any of its flags), in step order.
  const std::vector<std::string>& stages() const { return stage_names_; }
  /// Seconds spent per built stage since construction, summed over the flags. Pipelined, the
  /// fluid stage's air step runs beside the other stages, so the seconds add up to more than the
  /// wall time.
  std::vector<std::pair<std::string, double>> timings() const;
  ClothEnergy energy() const;
  /// Work by stage since construction (EnergyLedger; `gravity` from the current positions).
  EnergyLedger energy_ledger() const;
  /// J, the flag's energy scale m |g| H + m U^2 / 2 (m its mass, H = max(width, height), U the
  /// largest wind or fan speed of the scene); m (1 m/s)^2 / 2 when both are zero. A step whose
  /// unexplained energy gain exceeds integrator.energy_tolerance x this raises
  /// DivergenceError(cause "energy").
  double energy_scale() const { return energy_scale_; }
  /// J: the most unexplained energy the check counts the flag as holding now (docs/energy.md):
  /// kinetic + spring energy + rise since construction, relative to the pins once they move.
  double holdable_energy() const;
  /// Largest spring strain (l - L) / L of the current positions.
  double max_strain() const { return flagsim::max_strain(topo_, x_); }
  /// The integrator's statistics of the last step's last piece (IntegratorStats; energy_halvings
  /// also counts the step's redos in shorter pieces, whatever refused it).
  const IntegratorStats& last_step_stats() const { return stats_; }
  /// Every halving of the last step, by the check that refused (summed over its pieces and redos).
  const StepHalvings& last_step_halvings() const { return halvings_; }

  /// N, the force the flag exerted on its pins in the last step (the reaction of the pins,
  /// pole and tethers to it; contact with the pole cylinder not included): from the flag's
  /// momentum over the integrate stage, F = sum m g + (drag impulse + flap force impulse -
  /// change of momentum) / dt. Zero before the first step (docs/coupling.md).
  const Vec3& pole_force() const { return pole_force_; }
  /// N, pole_force() averaged over the time since construction or the last
  /// reset_pole_force_mean() (impulse over time, so steps of any length weigh by their length);
  /// the last step's force when no time has passed since.
  Vec3 pole_force_mean() const;
  /// Starts the average of pole_force_mean() afresh from now (e.g. after a transient).
  void reset_pole_force_mean();
  /// N s, the pins' impulse since construction (the integral of pole_force()); never reset.
  const Vec3& pole_impulse() const { return pole_impulse_; }

  /// Air velocity at world points (M x 3) at the current time into out (M x 3).
  void air_velocity(const MatX3& points, MatX3& out) const;

  /// The air grid (air.model "grid" with drag built), or nullptr: the air is analytic or absent.
  Fluid* fluid() { return air_grid_; }
  const Fluid* fluid() const { return air_grid_; }
  /// Masses that sampled the air grid from outside its domain (nearest boundary value used):
  /// in the last step, and since construction.
  long air_outside_last_step() const { return air_outside_last_; }
  long air_outside_total() const { return air_outside_total_; }

  /// Recompute normals after positions were edited from outside.
  void update_normals();
  /// n_ = the vertex normals of x_; a no-op when x_ holds the same bits as when n_ was last
  /// computed (a step's first piece starts from the positions the step before ended at).
  void normals_for_x();

  /// True when a step takes the air's step together with the cloth's first piece (air.pipeline,
  /// a grid, and air.coupling "one_way" or "two_way_lagged"): side by side on two threads when
  /// flagsim has two or more (num_threads()), one after the other on one. Same bits as the serial
  /// order of the same scheme either way (docs/design.md "Air and cloth side by side").
  bool pipelined() const;
  /// The pinned vertices, in the order set_pin_targets takes them.
  const std::vector<Index>& pinned_vertices() const { return pin_index_; }
  /// Where the pinned vertices are at the end of the next step (P x 3, m, in pinned_vertices()
  /// order): they move there in a straight line at constant velocity over the step, and stay
  /// there after it unless set again. The pole stays. InvalidArgument when flag.pin_motion is
  /// keyframed (the keys drive the pins) or a target is not finite.
  void set_pin_targets(const MatX3& targets);
  /// The pins and the pole together at rigid pose (translation m, rotation vector in degrees
  /// about flag.pin_motion.pivot, as a MotionKey) at the end of the next step, reached by a
  /// linear translation and a slerp of the rotation over the step.
  void set_pin_pose(const Vec3& translation, const Vec3& rotation_degrees);
  /// The pole's rigid pose now (identity: where scene.pole puts it).
  const Pose& pole_pose() const { return pose_now_; }

 private:
  static constexpr int kNumStages = int(Stage::kCount);

  Simulation(const Scene& scene, Simulation* host);  // host: the Simulation of flag 0, or null
  void step_once();
  // A flag's part of a step: its pieces (halvings, checks), then, after the air, its end.
  void step_pieces();
  void hand_reactions();  // every flag's stage_coupling: its drag's reaction for the air
  void finish_step();
  void undo_step();     // back to the start of the step, normals too
  struct Implausible {  // a piece that failed a plausibility test; empty cause: it passed
    std::string cause;
    long vertex = -1;
    std::string why;
  };
  void begin_step();                             // the state the step may go back to
  Implausible pieces(int level);                 // this flag's step as 2^level pieces
  void halve_until_plausible(Implausible bad);   // redo in shorter pieces while a piece fails
  void count_halving(const std::string& cause);  // halvings_ by the check's cause
  void sample_air_ahead();                       // the first piece's air, before the air steps
  bool steps_beside_air(int& done);  // every flag's first piece while the air steps beside
  Implausible step_piece();
  void restore_step_start();
  // Set-up (the constructor, in this order).
  void choose_stages();
  void name_stages();
  void build_fluid();
  void check_inside_grid() const;
  void build_self_collision();
  void build_between_flags();
  void setup_flapping();
  void setup_energy();
  void setup_pins();
  Pose pin_pose(double t) const;
  void pin_targets(double t, MatX3& out) const;
  void check_explicit_step() const;
  // The stages of a piece (step_piece), each timed by its own StageClock scope.
  void stage_air();
  void stage_coupling();
  bool lagged() const { return scene_.air.coupling == Coupling::kTwoWayLagged; }
  void scale_drag_for_air_response();
  void stage_flap();
  void stage_integrate();
  void stage_pins();
  void place_pins();
  void stage_pole();
  void find_resting_contacts();
  void stage_solids();
  void stage_self_collision();
  Implausible stage_check();
  // After every flag's pieces: contacts between flags (several flags, self_collision enabled).
  void stage_between_flags();
  bool common_pin_frame(RigidMotion& frame) const;  // every flag's pins' pose, if they share it
  bool flags_may_touch() const;
  // After the step: the air grid advances, the "visual" flap displaces the exported geometry.
  void advance_fluid();
  [[noreturn]] void air_diverged(const DivergenceError& e);  // the cloth restored, e raised
  void stage_flap_visual();
  // Helpers of the stages.
  double sample_pole_air_speed(double t, double h);  // u_p at t, the pins' motion over [t, t + h]
  // The change of E it made less the pins' share, J (that share booked to ledger_.pins).
  double limit_cloth_strain(MatX3& x, MatX3& v);
  void book_integrator_work();
  void book_energy_change(double& entry, double booked_elsewhere);
  void offer_known_energy();  // scratch_.energy_known = energy_run_ where it is still E(x_, v_)
  void book_energy(double& entry, double booked_elsewhere, double e);
  [[noreturn]] void integrate_failed(IntegrateStatus status);
  void check_finite();
  Implausible check_strain(double strain, Index worst_spring);  // max_strain of x_
  Implausible check_energy() const;
  // the pinned rows' centre of mass of a: N x 3, or P x 3 in pin order when pins_only
  Vec3 pins_centre(const MatX3& a, bool pins_only = false) const;
  double energy_now() const;  // total_energy of (x_, v_)
  Vec3 momentum() const;      // sum of m v over every mass, N s
  Vec3 momentum(const MatX3& v) const;
  [[noreturn]] void diverge(const std::string& cause, long vertex, const std::string& detail);

  Scene scene_;
  ClothTopology topo_;
  ForceSet forces_;
  IntegratorScratch scratch_;
  IntegratorStats stats_;
  StepHalvings halvings_;  // of the step being stepped, reset by begin_step
  MatX3 x_, v_, n_, u_;    // (N x 3) positions, velocities, normals, air at masses
  MatX3 x_of_n_;           // (N x 3) the positions n_ was computed from (normals_for_x)
  // The state energy_run_ was last computed at (N x 3 each; book_energy_change): the next
  // step's integrate() starts from those bits unless something moved them in between.
  MatX3 x_of_e_, v_of_e_;
  MatX3 x_start_, v_start_;     // (N x 3) state at the start of the step (rollback)
  MatX3 x_piece_;               // (N x 3) positions at the start of the piece (swept collisions)
  double h_ = 0, t_piece_ = 0;  // s, length and start time of the piece being stepped
  double time_ = 0;
  long step_count_ = 0;
  std::array<bool, kNumStages> built_{};  // the stages this scene runs
  bool& built(Stage s) { return built_[std::size_t(s)]; }
  bool built(Stage s) const { return built_[std::size_t(s)]; }
  StageClock clock_;      // seconds per stage (Simulation.timings)
  StageClock air_clock_;  // the air's step when it runs beside the cloth (its own thread)
  // The pipeline (steps_beside_air): the air at the masses and u_p sampled before the air starts
  // its step, for the step's first piece.
  bool air_sampled_ = false, pole_air_sampled_ = false;
  std::vector<std::string> stage_names_;
  std::unique_ptr<Fluid> fluid_;             // the air grid, when the scene needs one
  std::unique_ptr<SideBySide> beside_;       // the air's thread when pipelined
  CurlNoise noise_{TurbulenceParams{}, {}};  // curl noise on the analytic wind (air "uniform")

  // Flapping (paper eq. 5), set up only when flapping.mode is not "off".
  FlapStage flap_;
  VecX flap_off_z_;  // (N) zeros: flap_displacement() with flapping off
  // (P x 3, P = flag rows) where u_p is sampled (the pole-side edge at rest; edge_at_: where the
  // pins' pose carries it), and the air there
  MatX3 edge_points_, edge_at_, edge_air_;
  double u_p_ = 0;
  MatX3 render_x_, render_n_;  // (N x 3) "visual" geometry

  // Energy bookkeeping (docs/energy.md): the ledger (gravity filled in on demand), its value at
  // the start of the step (rollback), E at the end of the last step (edits show as a change
  // before the next), E running through the stages of a step, the gravity potential at the
  // start, and the scale of the plausibility check.
  EnergyLedger ledger_, ledger_start_;
  double energy_end_start_ = 0;
  double energy_end_ = 0, energy_run_ = 0, gravity_potential_0_ = 0, energy_scale_ = 0;
  // J: moving pins' and contact planes' work in the strain limiting inside self-collision's
  // sweeps (booked to pins, not self_collision), summed over one response
  double sweep_pin_work_ = 0;
  Vec3 sweep_strain_momentum_ = Vec3::Zero();  // N s: that strain limiting's momentum change
  Vec3 between_p0_ = Vec3::Zero();             // N s: momentum before the pass between flags
  Vec3 pins_centre_0_ = Vec3::Zero();          // m: the pins' centre of mass at construction
  MatX3 flap_drift_;  // (N x 3) m/s, "displace": dz n / h, the integrator's drift
  MatX3 flap_force_;  // (N x 3) N, "force": held over the piece by the integrator

  // Moving pins (flag.pin_motion or set_pin_targets / set_pin_pose): the pinned vertices, their
  // rest positions (P x 3) and where they are held when nothing drives them (P x 3); the pose of
  // the pins and pole now and, for a pose set from Python, the one asked for the end of the next
  // step. kNone: the pins move with whatever velocity they have (as before moving pins).
  enum class PinDriver { kNone, kKeyframes, kHold, kTargets, kPose };
  PinDriver pin_driver_ = PinDriver::kNone;
  std::vector<Index> pin_index_;
  MatX3 pin_rest_, pin_hold_, pin_goal_, pin_at_, pin_start_;  // (P x 3) m
  Pose pose_now_, pose_goal_;
  RigidMotion pole_motion_;  // the pole over the piece being stepped
  RigidMotion pins_frame_;   // the pins' pose over the piece being stepped (moving pins)
  MatX3 x0_carried_;         // (N x 3) m: the piece's start carried by pins_frame_ (self-collision)
  bool pole_moves_ = false;
  // The scene's solids the flag collides with (cloth = true), and their motions (empty: at rest).
  std::vector<ClothSolid> cloth_solids_;
  std::vector<MotionSchedule> solid_motions_;
  std::vector<RigidMotion> solid_piece_;  // each moving solid over the piece being stepped
  // Contact planes of the free vertices near a solid or the pole at the piece's start
  // (ForceSet::contacts, contact_offset, contact_speed; find_resting_contacts): normals (N x 3,
  // zero rows: none), offsets at the piece's end and speeds along n (a moving solid's or pole's
  // surface). A vertex within
  // (1 + kRestingSlack) x the thickness of a solid (the radius of the pole) touches.
  static constexpr double kRestingSlack = 0.002;
  MatX3 resting_;
  VecX resting_offset_, resting_speed_;  // (N) m at the piece's end; m/s along n

  std::unique_ptr<SelfCollision> self_collision_;
  std::atomic<bool> stepping_{false};          // a step() is running (one thread at a time)
  SelfCollision::Projector strain_projector_;  // built once: no allocation per step
  long air_outside_last_ = 0, air_outside_total_ = 0;

  // Drag impulse of the step per mass (N x 3, N s; the integrator adds to it), the reaction the
  // air takes in two-way coupling (its negative) and the points it is spread at (the step's
  // start positions, where the first piece sampled the air). "two_way_lagged": the reaction and
  // its points wait there for the next step's air (in flight), which may read them on the
  // helper thread while this step's cloth writes drag_impulse_ and x_start_.
  MatX3 drag_impulse_, reaction_, reaction_at_;
  // Two-way: each mass's drag factor 1 / (1 + kappa) (ForceSet::drag_scale) and the sum of the
  // squared sampling weights at it (N).
  VecX drag_scale_, weight_sq_;
  // The pins' impulse in this step (N s), the last step's force, the impulse since
  // construction and where the mean restarts (impulse and time at the last reset).
  Vec3 step_pin_impulse_{0, 0, 0}, pole_force_{0, 0, 0}, pole_impulse_{0, 0, 0};
  Vec3 pole_impulse_mark_{0, 0, 0};
  double pole_time_mark_ = 0;
  std::vector<PointImpulses> reactions_;  // flag 0: every two-way flag's reaction, for the grid
  // Several flags (docs/multiflag.md). host_: the Simulation stepping this flag (null for flag
  // 0); others_: flags 1, 2, ...; air_grid_: the grid this flag samples (its own fluid_ or the
  // host's). Between flags: one SelfCollision over the union of every flag's vertices (flag i's
  // rows from between_offset_[i]) and triangles, gathered into the b*_ buffers around its pass.
  Simulation* host_ = nullptr;
  int flag_index_ = 0;
  std::vector<std::unique_ptr<Simulation>> others_;
  Fluid* air_grid_ = nullptr;
  std::unique_ptr<SelfCollision> between_;
  SelfCollisionStats between_stats_;
  std::vector<Index> between_offset_;
  bool between_frame_ = false;  // this step's pass runs in the pins' common frame
  MatX3 bx0_, bx_, bv_;  // (sum N x 3) union of the flags' step-start positions, positions, v
  VecX binv_mass_;       // (sum N) union of the inverse masses
  SelfCollision::Projector between_projector_;  // every flag's strain limit on its rows
};

}  // namespace flagsim
