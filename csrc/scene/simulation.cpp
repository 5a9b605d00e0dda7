#include "scene/simulation.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "collision/pole.h"
#include "common/errors.h"
#include "common/memory.h"
#include "common/parallel.h"
#include "common/timer.h"
#include "flapping/flapping.h"

namespace flagsim {

double EnergyLedger::unexplained_net() const {
  return integrator + strain_limit + pole + solids + self_collision;
}

double EnergyLedger::unexplained_since(const EnergyLedger& b) const {
  const double projections = (strain_limit - b.strain_limit) + (pole - b.pole) +
                             (solids - b.solids) + (self_collision - b.self_collision);
  return std::max(integrator - b.integrator, 0.0) + std::max(projections, 0.0);
}

namespace {
// a and b hold the same bits (and shape), so a value computed from one holds for the other.
bool same_bits(const MatX3& a, const MatX3& b) {
  return a.rows() == b.rows() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * std::size_t(a.size())) == 0;
}

// Valid, and small enough to build in the memory this machine has (checked before any of it is
// allocated: a flag or grid too large fails here in one line, not in std::bad_alloc).
Scene validated(const Scene& s) {
  s.validate();
  const bool grid = s.air.model == AirModel::kGrid;
  const double cells = grid ? s.air.cells() : 0.0;
  double vertices = 0;
  for (const FlagSpec& f : s.flags()) vertices += double(f.flag.rows) * double(f.flag.cols);
  const double bytes = vertices * kBytesPerVertex + (grid ? s.air.memory_bytes() : 0.0);
  check_memory("this scene (" +
                   (s.more_flags.empty() ? "a " + std::to_string(s.flag.rows) + " x " +
                                               std::to_string(s.flag.cols) + " flag"
                                         : std::to_string(s.num_flags()) + " flags of " +
                                               detail::to_text(vertices) + " masses") +
                   (cells > 0 ? ", " + detail::to_text(cells) + " air cells" : std::string()) + ")",
               bytes, "use fewer flag.rows / flag.cols or a coarser air.resolution");
  return s;
}

// Every enabled pole of the scene's flags, as solids of the air.
// The poles at rest (a keyframed pin motion moves its pole: not a solid of the air).
std::vector<ObstacleParams> pole_solids(const Scene& s) {
  std::vector<ObstacleParams> out;
  for (const FlagSpec& f : s.flags())
    if (f.pole.enabled && f.flag.pin_motion.empty()) out.push_back(AirParams::pole_solid(f.pole));
  return out;
}
}  // namespace

Simulation::Simulation(const Scene& scene) : Simulation(validated(scene), nullptr) {}

Simulation::~Simulation() = default;

// Flag 0 (host null, `scene` the whole scene) or flag i of `host` (`scene` = flag_scene(i)).
Simulation::Simulation(const Scene& scene, Simulation* host)
    : scene_(scene), topo_(build_flag_topology(scene_.flag)), scratch_(topo_) {
  host_ = host;
  flag_index_ = host ? host->num_flags() : 0;
  const Scene& whole = host ? host->scene_ : scene_;
  const Index N = topo_.num_vertices();
  x_ = initial_positions(topo_, scene_.flag);
  v_.setZero(N, 3);
  setup_pins();
  u_.setZero(N, 3);
  x_start_ = x_;
  v_start_ = v_;
  choose_stages();
  drag_impulse_.setZero(forces_.drag ? N : 0, 3);
  if (forces_.drag) forces_.drag_impulse = &drag_impulse_;
  if (built(Stage::kSolids) || built(Stage::kPole)) {  // explicit: strain limiting reads them
    resting_.setZero(N, 3);
    resting_offset_.setZero(N);
    resting_speed_.setZero(N);
    forces_.contacts = &resting_;
    forces_.contact_offset = &resting_offset_;
    forces_.contact_speed = &resting_speed_;
  }
  if (built(Stage::kCoupling)) {
    reaction_.setZero(N, 3);
    reaction_at_ = x_;
    drag_scale_.setOnes(N);
    weight_sq_.setZero(N);
    forces_.drag_scale = &drag_scale_;
  }
  if (built(Stage::kFluid)) {
    if (host) {
      air_grid_ = host->air_grid_;
      check_inside_grid();
    } else {
      build_fluid();
    }
  }
  if (scene_.air.model == AirModel::kUniform && scene_.air.turbulence.enabled()) {
    // No air flows into a pole at rest or a solid of the air.
    std::vector<ObstacleParams> solids = pole_solids(whole);
    for (const SolidParams& solid : whole.solids)
      if (solid.air) solids.push_back(solid);
    noise_ = CurlNoise(scene_.air.turbulence, std::move(solids));
  }
  if (built(Stage::kSelfCollision)) build_self_collision();
  n_.resize(N, 3);
  x_of_n_.resize(N, 3);
  // Not any state's bits (positions are finite), so no energy is known before the first booking.
  x_of_e_.setConstant(N, 3, std::numeric_limits<double>::quiet_NaN());
  v_of_e_.setConstant(N, 3, std::numeric_limits<double>::quiet_NaN());
  update_normals();
  setup_flapping();
  setup_energy();
  check_explicit_step();
  if (host) return;
  for (int i = 1; i < scene_.num_flags(); ++i)
    others_.push_back(std::unique_ptr<Simulation>(new Simulation(scene_.flag_scene(i), this)));
  if (built(Stage::kSelfCollision) && !others_.empty()) build_between_flags();
  for (int i = 0; i < num_flags(); ++i)  // two-way: every flag's reaction goes into the grid
    if (flag(i).built(Stage::kCoupling))
      reactions_.push_back({&flag(i).reaction_at_, &flag(i).reaction_});
  name_stages();
}

Simulation& Simulation::flag(int i) {
  if (i < 0 || i >= num_flags())
    fail_param("flag", "an index in [0, " + std::to_string(num_flags()) + ")", i);
  return i == 0 ? *this : *others_[std::size_t(i) - 1];
}

// The stage table: only what the scene needs is built, and a stage left out is never called and
// costs nothing.
void Simulation::choose_stages() {
  const bool air = scene_.air.model != AirModel::kNone && scene_.air.density > 0;
  forces_.gravity = scene_.gravity.squaredNorm() > 0;
  forces_.drag =
      air && (scene_.drag.coefficient > 0 || (scene_.drag.model == DragModel::kTriangle &&
                                              scene_.drag.tangential_coefficient > 0));
  forces_.springs = topo_.stiffness.maxCoeff() > 0 || topo_.damping.maxCoeff() > 0;
  forces_.g = scene_.gravity;
  forces_.drag_params = scene_.drag;
  forces_.rho = scene_.air.density;
  built(Stage::kWind) = forces_.drag && scene_.air.model == AirModel::kUniform;
  built(Stage::kFluid) = forces_.drag && scene_.air.model == AirModel::kGrid;
  if (!host_ && scene_.air.model == AirModel::kGrid)  // flag 0 steps the scene's grid for all
    for (const FlagSpec& f : scene_.more_flags)
      built(Stage::kFluid) = built(Stage::kFluid) || (air && f.drag.coefficient > 0);
  built(Stage::kCoupling) =
      forces_.drag && scene_.air.model == AirModel::kGrid && scene_.air.two_way();
  built(Stage::kGravity) = forces_.gravity;
  built(Stage::kDrag) = forces_.drag;
  built(Stage::kSprings) = forces_.springs;
  built(Stage::kIntegrate) = true;
  built(Stage::kStrainLimit) = scene_.integrator.strain_limit > 0;
  const FlapMode flap = scene_.flapping.mode;
  built(Stage::kFlap) = flap == FlapMode::kDisplace || flap == FlapMode::kForce;
  built(Stage::kFlapVisual) = flap == FlapMode::kVisual;
  built(Stage::kPins) = pin_driver_ == PinDriver::kKeyframes;
  built(Stage::kPole) = scene_.pole.enabled;
  built(Stage::kSolids) = !cloth_solids_.empty();
  built(Stage::kSelfCollision) = scene_.self_collision.enabled;
  built(Stage::kCheck) = true;
}

// The pinned vertices and their rest positions; with keyframes, the whole flag starts at pose(0).
// The scene's solids the cloth collides with.
void Simulation::setup_pins() {
  for (Index i = 0; i < topo_.num_vertices(); ++i)
    if (topo_.pinned(i)) pin_index_.push_back(i);
  const Index P = Index(pin_index_.size());
  pin_rest_.resize(P, 3);
  for (Index k = 0; k < P; ++k) pin_rest_.row(k) = x_.row(pin_index_[k]);
  if (!scene_.flag.pin_motion.empty()) {
    pin_driver_ = PinDriver::kKeyframes;
    pose_now_ = scene_.flag.pin_motion.at(0.0);
    for (Index i = 0; i < x_.rows(); ++i) x_.row(i) = pose_now_.apply(row(x_, i)).transpose();
  }
  pin_hold_.resize(P, 3);
  for (Index k = 0; k < P; ++k) pin_hold_.row(k) = x_.row(pin_index_[k]);
  pin_goal_ = pin_at_ = pin_start_ = pin_hold_;
  for (const SolidParams& s : scene_.solids)
    if (s.cloth) {
      cloth_solids_.emplace_back(s, s.thickness, s.friction);
      solid_motions_.push_back(s.motion);
    }
  solid_piece_.resize(cloth_solids_.size());
}

void Simulation::build_self_collision() {
  self_collision_ =
      std::make_unique<SelfCollision>(topo_.triangles, topo_.num_vertices(), scene_.self_collision);
  x0_carried_.resize(topo_.num_vertices(), 3);
  // Strain limiting inside the collision sweeps: contacts alone would hold a stretch.
  // Its energy is booked with the self-collision response's (one evaluation around it), but for
  // the work of moving pins and contact planes in it, which is the pins' (sweep_pin_work_), as
  // in the stage-level strain limiting (limit_cloth_strain).
  strain_projector_ = [this](MatX3& x, MatX3& v) {
    const bool frame = built(Stage::kPins);
    if (frame) sweep_strain_momentum_ -= momentum(v);
    limit_strain(topo_, scene_.integrator.strain_limit, scene_.integrator.strain_limit_iterations,
                 x, v, forces_.contacts, forces_.contact_offset, &sweep_pin_work_,
                 forces_.contact_speed);
    if (frame) sweep_strain_momentum_ += momentum(v);
  };
}

// Explicit without adaptive substeps refuses a step above the stable-step estimate (strain
// limiting would otherwise hide the instability as bounded jitter). When dt / substeps is above
// the estimate for the scene at rest, no step can run: say so now, naming the fix.
void Simulation::check_explicit_step() const {
  const IntegratorParams& ip = scene_.integrator;
  if (ip.method != Method::kExplicit || ip.adaptive) return;
  MatX3 u0;
  air_velocity(x_, u0);
  const double stable =
      stable_step_estimate(topo_, scene_.drag, forces_.rho, forces_.drag, x_, v_, u0);
  const double h = scene_.dt / double(ip.substeps);
  if (!(h > stable)) return;
  std::ostringstream s;
  s << ">= " << std::ceil(scene_.dt / stable) << " (dt / substeps at most the stable step "
    << stable << " s of this scene at rest, for explicit steps without integrator.adaptive; or "
    << "set integrator.adaptive = true or integrator.method = 'implicit')";
  fail_param("integrator.substeps", s.str(), ip.substeps);
}

// The plausibility check's scale m |g| H + m U^2 / 2 (docs/energy.md), and the energy and the
// piece's start positions at construction. U is the air's largest speed relative to the pins:
// keyframed pins carry their frame (the pins' centre of mass) through the wind, so a flag carried
// with its air is checked as the still one; a fan (fixed in the grid) at most adds the pins'
// own speed. Pins driven from Python later are not known here: the lab's speeds.
void Simulation::setup_energy() {
  const FlagParams& f = scene_.flag;
  const bool air = scene_.air.model != AirModel::kNone;
  double U = 0, carried = 0;
  if (air && pin_driver_ == PinDriver::kKeyframes) {
    const CarriedSpeeds c =
        carried_speeds(scene_.air.wind, f.pin_motion, pins_centre(pin_rest_, true));
    U = c.relative;
    carried = c.own;
  } else if (air) {
    U = scene_.air.wind.max_speed();
  }
  if (scene_.air.model == AirModel::kGrid)
    for (const FanParams& fan : scene_.air.fans) U = std::max(U, fan.max_speed + carried);
  // Curl noise adds its intensity on top of the mean flow (air.turbulence, either model).
  if (scene_.air.model != AirModel::kNone) {
    double gust = 0;
    for (const auto& [t, intensity] : scene_.air.turbulence.intensity.keys)
      gust = std::max(gust, std::fabs(intensity));
    U += gust;
  }
  const double m = topo_.mass.sum(), H = std::max(f.width, f.height);
  energy_scale_ = m * scene_.gravity.norm() * H + 0.5 * m * U * U;
  if (!(energy_scale_ > 0)) energy_scale_ = 0.5 * m;  // m (1 m/s)^2 / 2
  forces_.energy_guard = scene_.integrator.energy_tolerance * energy_scale_;
  energy_end_ = energy_now();
  gravity_potential_0_ = energy().gravity;
  pins_centre_0_ = pins_centre(x_);
  x_piece_ = x_;
}

double Simulation::energy_now() const { return total_energy(topo_, scene_.gravity, x_, v_); }

void Simulation::setup_flapping() {
  const Index N = topo_.num_vertices();
  flap_off_z_.setZero(N);
  if (!built(Stage::kFlap) && !built(Stage::kFlapVisual)) return;
  const FlappingParams& fp = scene_.flapping;
  flap_ = FlapStage(topo_, fp);
  // The integrator carries the stage: "displace" as a drift of the positions, "force" as an
  // external force, each held over a piece.
  if (fp.mode == FlapMode::kDisplace) {
    flap_drift_.setZero(N, 3);
    forces_.drift = &flap_drift_;
  } else if (fp.mode == FlapMode::kForce) {
    flap_force_.setZero(N, 3);
    forces_.external = &flap_force_;
  }
  edge_points_ = FlapStage::pole_edge_points(topo_);  // u_p is sampled there, beside the pole
  edge_air_.resize(topo_.rows, 3);
  edge_at_.resize(topo_.rows, 3);
  if (built(Stage::kFlapVisual)) {
    u_p_ = sample_pole_air_speed(time_, scene_.dt);
    render_x_.resize(N, 3);
    flap_.displace(x_, n_, u_p_, time_, render_x_);
    render_n_.resize(N, 3);
    compute_vertex_normals(topo_, render_x_, render_n_);
  }
}

// The air grid (paper §2): it only needs the flags to start inside it. Pipelined (air.pipeline,
// coupling one-way or lagged two-way), the air steps on a thread of its own with its loops on
// that thread, so its FFTs are planned for one thread, and it keeps its warm start so that a
// step the pipeline takes back is taken again to the same bits.
void Simulation::build_fluid() {
  check_inside_grid();
  FluidParams fp = scene_.air;
  if (scene_.air.pole_obstacle)
    for (const ObstacleParams& o : pole_solids(scene_)) fp.obstacles.push_back(o);
  for (const SolidParams& solid : scene_.solids)
    if (solid.air) fp.obstacles.push_back(solid);
  struct Threads {  // the thread count the FFTW plans are made for, restored however we leave
    int before = num_threads();
    ~Threads() { set_num_threads(before); }
  } restore;
  // "two_way": the air's step takes this step's drag reaction, so it cannot start before the
  // cloth's step, and runs after it. "two_way_lagged" takes the step before's, which is ready.
  const bool pipeline = scene_.air.pipeline && scene_.air.coupling != Coupling::kTwoWay;
  if (pipeline) set_num_threads(1);
  fluid_ = std::make_unique<Fluid>(fp, "air");
  air_grid_ = fluid_.get();
  if (pipeline) {
    fluid_->keep_warm_start();
    beside_ = std::make_unique<SideBySide>();
  }
}

void Simulation::check_inside_grid() const {
  const AirParams& a = scene_.air;
  const std::string origin =
      host_ ? "flags[" + std::to_string(flag_index_) + "].origin" : std::string("flag.origin");
  const Vec3 lo = a.origin,
             hi = a.origin + a.cell_size * Vec3(a.resolution[0], a.resolution[1], a.resolution[2]);
  for (Index i = 0; i < x_.rows(); ++i) {
    const Vec3 p = x_.row(i).transpose();
    if ((p.array() < lo.array()).any() || (p.array() > hi.array()).any()) {
      std::ostringstream s;
      s << origin << " should place the flag inside the air grid [" << lo.x() << ", " << hi.x()
        << "] x [" << lo.y() << ", " << hi.y() << "] x [" << lo.z() << ", " << hi.z()
        << "] m (air.origin, air.resolution, "
        << "air.cell_size), got vertex " << i << " at (" << p.x() << ", " << p.y() << ", " << p.z()
        << ")";
      throw InvalidArgument(s.str());
    }
  }
}

// One-way or lagged two-way coupling: an air step that takes this step's drag reaction
// ("two_way", issue 24) cannot start before the cloth's step; "two_way_lagged" takes the step
// before's.
bool Simulation::pipelined() const { return beside_ != nullptr; }

void Simulation::update_normals() {
  compute_vertex_normals(topo_, x_, n_);
  x_of_n_ = x_;
}

// Bits, not values: the normals are a function of x_'s bits, so equal bits give the same n_.
// x_ may be written from outside between steps (Python's positions view), hence the comparison
// rather than a flag.
void Simulation::normals_for_x() {
  if (!same_bits(x_of_n_, x_)) update_normals();
}

// The stages any flag runs (a flag that starts moving its pins adds "pins" to its host's list).
void Simulation::name_stages() {
  if (host_) {
    host_->name_stages();
    return;
  }
  stage_names_.clear();
  for (int s = 0; s < kNumStages; ++s) {
    bool any = false;
    for (int i = 0; i < num_flags(); ++i) any = any || flag(i).built_[s];
    if (any) stage_names_.emplace_back(name_of(Stage(s)));
  }
}

void Simulation::set_pin_targets(const MatX3& targets) {
  if (pin_driver_ == PinDriver::kKeyframes)
    throw InvalidArgument(
        "set_pin_targets: flag.pin_motion is keyframed, and the keys drive the pins; set targets "
        "on a scene without flag.pin_motion");
  const Index P = Index(pin_index_.size());
  if (targets.rows() != P)
    fail_param("targets",
               "an array of shape (" + std::to_string(P) + ", 3), one row per pinned vertex",
               "(" + std::to_string(targets.rows()) + ", 3)");
  for (Index k = 0; k < P; ++k)
    check_position("targets[" + std::to_string(k) + "]", Vec3(targets.row(k).transpose()));
  pin_goal_ = targets;
  pin_driver_ = PinDriver::kTargets;
  built(Stage::kPins) = true;
  name_stages();
}

void Simulation::set_pin_pose(const Vec3& translation, const Vec3& rotation_degrees) {
  if (pin_driver_ == PinDriver::kKeyframes)
    throw InvalidArgument(
        "set_pin_pose: flag.pin_motion is keyframed, and the keys drive the pins; set a pose on a "
        "scene without flag.pin_motion");
  check_position("translation", translation);
  check_finite_vec("rotation", rotation_degrees);
  MotionSchedule one;
  one.pivot = scene_.flag.pin_motion.pivot;
  one.keys.push_back({0.0, translation, rotation_degrees});
  pose_goal_ = one.at(0.0);
  pin_driver_ = PinDriver::kPose;
  built(Stage::kPins) = true;
  name_stages();
}

// The pose of the pins and the pole at time t within the step being stepped.
Pose Simulation::pin_pose(double t) const {
  switch (pin_driver_) {
    case PinDriver::kKeyframes: return scene_.flag.pin_motion.at(t);
    case PinDriver::kPose: {
      const double s = std::clamp((t - time_) / scene_.dt, 0.0, 1.0);
      Pose p;
      p.R = Eigen::Quaterniond(pose_now_.R)
                .slerp(s, Eigen::Quaterniond(pose_goal_.R))
                .toRotationMatrix();
      p.t = (1 - s) * pose_now_.t + s * pose_goal_.t;
      return p;
    }
    default: return pose_now_;
  }
}

// Where the pinned vertices are at time t within the step (P x 3).
void Simulation::pin_targets(double t, MatX3& out) const {
  switch (pin_driver_) {
    case PinDriver::kKeyframes:
    case PinDriver::kPose: {
      const Pose p = pin_pose(t);
      for (Index k = 0; k < out.rows(); ++k) out.row(k) = p.apply(row(pin_rest_, k)).transpose();
      return;
    }
    case PinDriver::kTargets: {
      const double s = std::clamp((t - time_) / scene_.dt, 0.0, 1.0);
      out = (1 - s) * pin_start_ + s * pin_goal_;
      return;
    }
    default: out = pin_hold_;
  }
}

// One SelfCollision over the union of the flags (flag i's vertices from between_offset_[i]):
// pairs within a flag come again, so a response between flags cannot leave a flag crossing
// itself; scratch for every buffer allocated here, none in the step.
void Simulation::build_between_flags() {
  Index n = 0, t = 0;
  for (int i = 0; i < num_flags(); ++i) {
    between_offset_.push_back(n);
    n += flag(i).topo_.num_vertices();
    t += flag(i).topo_.triangles.rows();
  }
  MatX3i tri(t, 3);
  binv_mass_.resize(n);
  for (int i = 0, row = 0; i < num_flags(); ++i) {
    const ClothTopology& topo = flag(i).topo_;
    const int o = int(between_offset_[std::size_t(i)]);
    tri.middleRows(row, topo.triangles.rows()) = topo.triangles.array() + o;
    row += int(topo.triangles.rows());
    binv_mass_.segment(o, topo.num_vertices()) = topo.inv_mass;
  }
  bx0_.resize(n, 3);
  bx_.resize(n, 3);
  bv_.resize(n, 3);
  between_ = std::make_unique<SelfCollision>(tri, n, scene_.self_collision);
  // Strain limiting inside the sweeps, each flag on its rows (its own x_, v_ as scratch: the
  // pass writes them afterwards anyway).
  between_projector_ = [this](MatX3& x, MatX3& v) {
    for (int i = 0; i < num_flags(); ++i) {
      Simulation& f = flag(i);
      if (!f.built(Stage::kStrainLimit)) continue;
      const Index o = between_offset_[std::size_t(i)], m = f.topo_.num_vertices();
      f.x_ = x.middleRows(o, m);
      f.v_ = v.middleRows(o, m);
      if (between_frame_) f.sweep_strain_momentum_ -= f.momentum();
      limit_strain(f.topo_, f.scene_.integrator.strain_limit,
                   f.scene_.integrator.strain_limit_iterations, f.x_, f.v_, f.forces_.contacts,
                   f.forces_.contact_offset, &f.sweep_pin_work_, f.forces_.contact_speed);
      if (between_frame_) f.sweep_strain_momentum_ += f.momentum();
      x.middleRows(o, m) = f.x_;
      v.middleRows(o, m) = f.v_;
    }
  };
}

// Could any two flags touch over this step: do their swept boxes (start and end positions),
// grown by the thickness, overlap? Flags apart from every other one skip the pass, so such a
// flag moves exactly as it would alone.
bool Simulation::flags_may_touch() const {
  const double d = scene_.self_collision.thickness;
  std::vector<Eigen::AlignedBox3d> boxes;
  for (int i = 0; i < num_flags(); ++i) {
    const Simulation& f = flag(i);
    Eigen::AlignedBox3d b;
    for (Index k = 0; k < f.x_.rows(); ++k) {
      b.extend(f.x_start_.row(k).transpose());
      b.extend(f.x_.row(k).transpose());
    }
    b.min().array() -= d;
    b.max().array() += d;
    for (const Eigen::AlignedBox3d& other : boxes)
      if (b.intersects(other)) return true;
    boxes.push_back(b);
  }
  return false;
}

// The frame contacts between flags run in: the pins' motion over the step when every flag's pins
// follow the same pose (keyframed or set by set_pin_pose; two flags carried by one pose are the
// same two flags at rest), else none (the lab's): the flags' start positions are collision-free
// between flags only as they were, and carried by different poses they may overlap. Pins at rest,
// held, or moved by targets (no pose) keep the lab's frame.
bool Simulation::common_pin_frame(RigidMotion& frame) const {
  const auto same = [](const Pose& a, const Pose& b) { return a.R == b.R && a.t == b.t; };
  frame = {pin_pose(time_), pin_pose(time_ + scene_.dt), scene_.dt};
  for (int i = 0; i < num_flags(); ++i) {
    const Simulation& f = flag(i);
    if (f.pin_driver_ != PinDriver::kKeyframes && f.pin_driver_ != PinDriver::kPose) return false;
    if (!same(f.pin_pose(time_), frame.from) || !same(f.pin_pose(time_ + scene_.dt), frame.to))
      return false;
  }
  return true;
}

// Contacts between flags over the whole step (start positions x_start_, collision-free, to the
// positions the flags' own stages left): the self-collision response on the union of the flags,
// with the same guarantees (collision/self_collision.h). The change of each flag's energy goes
// to its ledger's self_collision entry, but for the pins' work in it. When every flag's pins
// follow one pose, the response runs in its frame, as a flag's own does (stage_self_collision):
// the start carried by the pose to the step's end, and V . dP of each flag's response (V its pins'
// velocity) booked to its pins. No pole in this pass: each flag's own pass kept its pole.
void Simulation::stage_between_flags() {
  if (!between_) return;
  StageClock::Scope t(&clock_, Stage::kSelfCollision);
  between_stats_ = SelfCollisionStats{};
  if (!flags_may_touch()) return;
  RigidMotion frame;
  between_frame_ = common_pin_frame(frame);
  for (int i = 0; i < num_flags(); ++i) {
    const Simulation& f = flag(i);
    const Index o = between_offset_[std::size_t(i)], m = f.topo_.num_vertices();
    bx0_.middleRows(o, m) = f.x_start_;
    bx_.middleRows(o, m) = f.x_;
    bv_.middleRows(o, m) = f.v_;
  }
  if (between_frame_)
    for (Index k = 0; k < bx0_.rows(); ++k)
      bx0_.row(k) = frame.to.apply(frame.from.inverse(row(bx0_, k))).transpose();
  bool strain = false;
  for (int i = 0; i < num_flags(); ++i) {
    Simulation& f = flag(i);
    strain = strain || f.built(Stage::kStrainLimit);
    f.sweep_pin_work_ = 0;
    f.sweep_strain_momentum_.setZero();
    f.between_p0_ = between_frame_ ? f.momentum() : Vec3::Zero();
  }
  between_stats_ = between_->resolve(bx0_, bx_, bv_, binv_mass_, nullptr,
                                     strain ? &between_projector_ : nullptr);
  for (int i = 0; i < num_flags(); ++i) {
    Simulation& f = flag(i);
    const Index o = between_offset_[std::size_t(i)], m = f.topo_.num_vertices();
    f.x_ = bx_.middleRows(o, m);
    f.v_ = bv_.middleRows(o, m);
    if (between_frame_)
      f.sweep_pin_work_ +=
          f.pins_centre(f.v_).dot(f.momentum() - f.between_p0_ - f.sweep_strain_momentum_);
    const double e = f.energy_now();
    f.ledger_.pins += f.sweep_pin_work_;
    f.ledger_.self_collision += e - f.energy_end_ - f.sweep_pin_work_;
    f.energy_end_ = e;
  }
}

void Simulation::step(long n) {
  if (n < 0) fail_param("n", ">= 0", n);
  if (host_)
    throw std::runtime_error("flags[" + std::to_string(flag_index_) +
                             "] is stepped by the Simulation of its scene: call step() there");
  // One thread at a time (Python releases the GIL around step): a second caller is refused
  // rather than left to interleave its stages with the first one's.
  bool idle = false;
  if (!stepping_.compare_exchange_strong(idle, true))
    throw std::runtime_error(
        "Simulation.step was called while another thread is stepping this Simulation; a "
        "Simulation is stepped by one thread at a time (use one Simulation per thread, or wait "
        "for the other call to return)");
  struct Idle {
    std::atomic<bool>& flag;
    ~Idle() { flag.store(false); }
  } idle_again{stepping_};
  for (long k = 0; k < n; ++k) step_once();
}

// One step, as the method reads: air -> forces + integrate -> constraints -> check. A step that
// makes energy no stage's work explains (the check's "energy") is redone from its start as 2,
// 4, ... pieces, up to integrator.max_halvings levels: a projection's error grows with how far
// the cloth moves in a step (a vertex put back on the pole while its neighbours moved on
// stretches their springs), so shorter pieces make less of it; adaptive explicit substeps
// shrink with the pieces (ForceSet::refine). Other failures raise at once. Several flags: each
// flag's pieces, then the contacts between flags, then the air once; a failure in any flag puts
// every flag back to the start of the step.
void Simulation::step_once() {
  int i = 0;  // flags whose pieces are done
  bool air_advanced = false;
  try {
    if (pipelined()) air_advanced = steps_beside_air(i);
    for (; i < num_flags(); ++i) flag(i).step_pieces();
  } catch (const DivergenceError& e) {
    for (int k = 0; k < i; ++k) flag(k).undo_step();
    if (others_.empty()) throw;
    throw DivergenceError("flags[" + std::to_string(i) + "]: " + e.what(), e.step, e.time, e.vertex,
                          e.cause);
  }
  stage_between_flags();  // vertex-triangle and edge-edge contacts between flags
  const bool lag = lagged();
  if (!lag) hand_reactions();          // two-way: the drag's reaction, to this step's air
  if (!air_advanced) advance_fluid();  // after the check: a rolled-back step leaves the air
  if (lag) hand_reactions();           // lagged two-way: to the next step's air
  for (int k = 0; k < num_flags(); ++k) flag(k).finish_step();
}

void Simulation::hand_reactions() {
  for (int k = 0; k < num_flags(); ++k) flag(k).stage_coupling();
}

void Simulation::step_pieces() {
  begin_step();
  halve_until_plausible(pieces(0));
}

void Simulation::begin_step() {
  x_start_ = x_;
  v_start_ = v_;
  ledger_start_ = ledger_;
  energy_end_start_ = energy_end_;
  drag_impulse_.setZero();
  step_pin_impulse_.setZero();
  halvings_ = StepHalvings{};
  if (built(Stage::kFlap)) flap_.save_step_start();
  if (built(Stage::kPins)) {
    for (Index k = 0; k < pin_start_.rows(); ++k) pin_start_.row(k) = x_.row(pin_index_[k]);
  }
}

void Simulation::halve_until_plausible(Implausible bad) {
  int level = 0;
  while (!bad.cause.empty()) {
    if (level == scene_.integrator.max_halvings)
      diverge(bad.cause, bad.vertex,
              bad.why + " even in " + std::to_string(1L << level) + " pieces");
    count_halving(bad.cause);
    restore_step_start();
    bad = pieces(++level);
  }
  stats_.energy_halvings += level;
}

void Simulation::count_halving(const std::string& cause) {
  if (cause == "strain")
    ++halvings_.strain;
  else if (cause == "energy")
    ++halvings_.energy;
  else
    throw std::logic_error("count_halving: a step redone for '" + cause + "'");
}

void Simulation::finish_step() {
  pole_force_ = step_pin_impulse_ / scene_.dt;
  pole_impulse_ += step_pin_impulse_;
  if (built(Stage::kPins)) {
    // A pose or targets from Python hold for one step; the pins then stay where they got to.
    pose_now_ = pin_pose(time_ + scene_.dt);
    if (pin_driver_ == PinDriver::kTargets || pin_driver_ == PinDriver::kPose) {
      pin_driver_ = PinDriver::kHold;
      pin_hold_ = pin_at_;
    }
  }
  ++step_count_;
  time_ = double(step_count_) * scene_.dt;  // no drift from summing dt
  normals_for_x();  // stage_check computed them unless a stage moved x_ after it
  if (built(Stage::kFlapVisual)) stage_flap_visual();
}

Simulation::Implausible Simulation::pieces(int level) {
  const long pieces = 1L << level;
  h_ = scene_.dt / double(pieces);
  forces_.refine = 1.0 / double(pieces);
  Implausible bad;
  for (long k = 0; k < pieces && bad.cause.empty(); ++k) {
    t_piece_ = time_ + double(k) * h_;
    bad = step_piece();
    air_sampled_ = pole_air_sampled_ = false;  // sample_air_ahead's reads serve one piece
  }
  return bad;
}

// The first piece's reads of the air, at the masses and u_p along the pole, from the grid as it
// is now (u^n); that piece's stage_air and stage_flap use them instead of sampling.
void Simulation::sample_air_ahead() {
  t_piece_ = time_;
  stage_air();
  if (built(Stage::kFlap)) {
    StageClock::Scope t(&clock_, Stage::kFlap);
    u_p_ = sample_pole_air_speed(time_, scene_.dt);  // the step's first piece
  }
  air_sampled_ = pole_air_sampled_ = true;
}

// The pipeline (one-way coupling, or two-way lagged): the air's step u^n -> u^n+1 reads nothing
// of this step's cloth (lagged: the reaction of the step before, in reaction_ and reaction_at_,
// which this step's cloth does not write), and the cloth's step reads the air only at u^n. So
// the air advances on the helper thread while this thread samples every flag's first-piece
// reads of the air (sample_air_ahead, the two-way drag factors too) and then steps each flag's
// first piece; the air's step waits for those samples before it first writes the grid
// (Fluid::WriteGate: after it has copied u^n for its advection, which takes longer than the
// sampling). Each side runs the serial order's operations on the same data,
// so the bits are the serial order's. When a flag's piece throws or must be redone in pieces,
// whose later pieces read u^n at positions known only then, the air's step is taken back
// (Fluid::undo_step) and the step finishes in the serial order from that flag on (the flags
// after it keep their samples of u^n). True when the air advanced; `done`: the flags whose
// pieces are done (on a throw, the one that threw restored itself).
bool Simulation::steps_beside_air(int& done) {
  Implausible bad;
  std::exception_ptr cloth_error, air_error;
  std::atomic<bool> sampled{false};  // u^n read: the air may write the grid
  const Fluid::WriteGate gate{
      [](const void* f) { wait_until_set(*static_cast<const std::atomic<bool>*>(f)); }, &sampled};
  beside_->run(
      [&]() noexcept {
        try {
          {
            struct Open {  // also when sampling throws: the air must not wait for ever
              std::atomic<bool>& f;
              ~Open() { f.store(true, std::memory_order_release); }
            } open{sampled};
            for (int k = 0; k < num_flags(); ++k) flag(k).sample_air_ahead();
          }
          for (; done < num_flags(); ++done) {
            Simulation& f = flag(done);
            f.begin_step();
            bad = f.pieces(0);
            f.air_sampled_ = f.pole_air_sampled_ = false;
            if (!bad.cause.empty()) break;
          }
        } catch (...) {
          cloth_error = std::current_exception();
        }
      },
      [&]() noexcept {
        try {
          StageClock::Scope t(&air_clock_, Stage::kFluid);
          fluid_->step(scene_.dt, reactions_.empty() ? nullptr : &reactions_, &gate);
        } catch (...) {
          air_error = std::current_exception();
        }
      });
  if (cloth_error || !bad.cause.empty()) {
    if (!air_error) {  // a failed air step has taken itself back already
      StageClock::Scope t(&clock_, Stage::kFluid);
      fluid_->undo_step();
    }
    if (cloth_error) {
      Simulation& f = flag(done);
      f.air_sampled_ = f.pole_air_sampled_ = false;
      std::rethrow_exception(cloth_error);
    }
    flag(done).halve_until_plausible(bad);
    ++done;
    return false;
  }
  if (air_error) {
    try {
      std::rethrow_exception(air_error);
    } catch (const DivergenceError& e) {
      air_diverged(e);
    }
  }
  return true;
}

// One piece of h_ from t_piece_, the paper's method stage by stage: an empty cause when it passed
// its checks. A stage the scene does not build returns at once.
Simulation::Implausible Simulation::step_piece() {
  x_piece_ = x_;
  stage_air();              // air velocity at the masses: the wind schedule or the grid (eq. 1, 2)
  stage_flap();             // eq. 5 as a drift of the positions or a force, held over the piece
  stage_pins();             // moving pins: their velocity over the piece, the pole's motion
  find_resting_contacts();  // vertices on a solid at rest: the implicit solve holds them there
  stage_integrate();        // gravity, drag (eq. 3), springs (eq. 4); strain limiting per substep
  place_pins();             // the pinned vertices exactly where their motion puts them
  stage_pole();             // the pole cylinder, alternating with strain limiting
  stage_solids();           // boxes, spheres, capsules, meshes: swept, with thickness and friction
  stage_self_collision();   // vertex-triangle and edge-edge contacts (paper §1), pole kept out
  Implausible bad = stage_check();  // finite, strain within its promise, energy explained
  if (!bad.cause.empty()) return bad;
  if (built(Stage::kFlap)) flap_.commit();
  energy_end_ = energy_run_;
  return bad;
}

void Simulation::undo_step() {
  restore_step_start();
  update_normals();
}

void Simulation::restore_step_start() {
  x_ = x_start_;
  v_ = v_start_;
  ledger_ = ledger_start_;
  energy_end_ = energy_end_start_;
  drag_impulse_.setZero();
  step_pin_impulse_.setZero();
  if (built(Stage::kFlap)) flap_.restore_step_start();
}

// u_p of eq. 5 (paper §4): the mean speed of the air across the pole along the flag's pole-side
// edge, relative to the pole. A pole the pins' pose carries (flag.pin_motion, set_pin_pose) is
// sampled where the pose puts the edge at t, less the edge's velocity over [t, t + h]: a flag
// carried along with its air flaps as the still one does (docs/flapping.md). Pins that never
// moved have the identity pose (pose_now_), which leaves the edge's rest positions and the lab's
// air to the bit. Without air (air.model = "none") there is nothing to flap the flag: u_p = 0
// however the pole moves (relative to the pole, the missing air would read as a wind).
double Simulation::sample_pole_air_speed(double t, double h) {
  if (scene_.air.model == AirModel::kNone) return 0.0;
  const RigidMotion pole{pin_pose(t), pin_pose(t + h), h};
  for (Index r = 0; r < edge_points_.rows(); ++r)
    edge_at_.row(r) = pole.from.apply(row(edge_points_, r)).transpose();
  air_velocity(edge_at_, edge_air_);
  for (Index r = 0; r < edge_points_.rows(); ++r)
    edge_air_.row(r) -= pole.velocity_at(row(edge_points_, r)).transpose();
  return edge_air_.rowwise().norm().mean();
}

// Paper eq. 5 at the end of the piece (flapping/flap_stage.h), from the air speed at the pole
// and the normals at the piece's start: "displace" as a drift the integrator carries, "force" as
// an external force it holds over the piece.
void Simulation::stage_flap() {
  if (!built(Stage::kFlap)) return;
  StageClock::Scope t(&clock_, Stage::kFlap);
  if (!pole_air_sampled_) u_p_ = sample_pole_air_speed(t_piece_, h_);  // else sample_air_ahead did
  normals_for_x();
  if (scene_.flapping.mode == FlapMode::kDisplace)
    flap_.drift(topo_, n_, u_p_, t_piece_ + h_, h_, flap_drift_);
  else
    flap_.force(topo_, n_, u_p_, t_piece_ + h_, h_, flap_force_);
}

double Simulation::limit_cloth_strain(MatX3& x, MatX3& v) {
  return limit_strain_work(topo_, scene_.gravity, scene_.integrator.strain_limit,
                           scene_.integrator.strain_limit_iterations, x, v, forces_.contacts,
                           forces_.contact_offset, &ledger_.pins, forces_.contact_speed);
}

// Each projection's entry in the ledger is the change of E it made: the pole's less the strain
// limiting between its passes (which has its own entry), self-collision's with the strain
// limiting inside its sweeps (one evaluation around the whole response; the check counts the
// projections together either way).
void Simulation::stage_pole() {
  constexpr int kPoleStrainRounds = 10;
  if (!built(Stage::kPole)) return;
  const double strain_before = ledger_.strain_limit, pins_before = ledger_.pins;
  Index moved;
  {
    StageClock::Scope t(&clock_, Stage::kPole);
    moved = collide_pole(scene_.pole, x_piece_, x_, v_, topo_.inv_mass, nullptr,
                         pole_moves_ ? &pole_motion_ : nullptr, &topo_.mass, &ledger_.pins);
  }
  const bool changed = moved > 0;  // a vertex left alone keeps its position and velocity
  for (int k = 0; k < kPoleStrainRounds && moved > 0 && built(Stage::kStrainLimit); ++k) {
    {
      StageClock::Scope t(&clock_, Stage::kStrainLimit);
      ledger_.strain_limit += limit_cloth_strain(x_, v_);
    }
    StageClock::Scope t(&clock_, Stage::kPole);
    moved = collide_pole(scene_.pole, x_piece_, x_, v_, topo_.inv_mass, nullptr,
                         pole_moves_ ? &pole_motion_ : nullptr, &topo_.mass, &ledger_.pins);
  }
  if (changed)
    book_energy_change(ledger_.pole,
                       ledger_.strain_limit - strain_before + (ledger_.pins - pins_before));
}

// The pinned vertices' velocity over the piece: the secant of their prescribed path, so that the
// integrator carries them to where the motion puts them at the piece's end (place_pins puts them
// there to the last bit). The kinetic energy this gives the pinned masses is the pins' work.
void Simulation::stage_pins() {
  if (!built(Stage::kPins)) return;
  StageClock::Scope t(&clock_, Stage::kPins);
  pin_targets(t_piece_ + h_, pin_at_);
  double kinetic = 0;
  for (Index k = 0; k < Index(pin_index_.size()); ++k) {
    const Index i = pin_index_[k];
    const Vec3 vel = (row(pin_at_, k) - row(x_, i)) / h_;
    kinetic += 0.5 * topo_.mass[i] * (vel.squaredNorm() - v_.row(i).squaredNorm());
    v_.row(i) = vel.transpose();
  }
  ledger_.pins += kinetic;
  energy_end_ += kinetic;  // not an edit between steps
  pins_frame_ = {pin_pose(t_piece_), pin_pose(t_piece_ + h_), h_};
  pole_moves_ = scene_.pole.enabled && pin_driver_ != PinDriver::kNone;
  if (pole_moves_) pole_motion_ = pins_frame_;
}

void Simulation::place_pins() {
  if (!built(Stage::kPins)) return;
  {
    StageClock::Scope t(&clock_, Stage::kPins);
    for (Index k = 0; k < Index(pin_index_.size()); ++k) x_.row(pin_index_[k]) = pin_at_.row(k);
  }
  book_energy_change(ledger_.pins, 0.0);  // the last bits of the integrator's x + h v
}

// The contact planes (ForceSet::contacts) of the free vertices within the thickness (and a
// little) of a solid at rest, and of those near the side of the pole: within a radius of it, or
// as close as their speed takes them in the piece. The plane is tangent to the surface,
// (1 + kRestingSlack) x the thickness (the radius) from it. A moving pole's plane is where its
// surface is at the piece's end, moving along its normal with the surface's speed there
// (ForceSet::contact_speed); a moving solid's likewise, for the vertices within its thickness (and
// as close as their speed and the surface's take them in the piece), each vertex placed in the
// moving body's frame at the piece's start. A vertex near several surfaces gets the nearest's.
void Simulation::find_resting_contacts() {
  if (!forces_.contacts) return;
  StageClock::Scope t(&clock_, built(Stage::kSolids) ? Stage::kSolids : Stage::kPole);
  resting_.setZero();
  resting_offset_.setZero();
  resting_speed_.setZero();
  const PoleParams& pole = scene_.pole;
  const double pole_plane = (1.0 + kRestingSlack) * pole.radius;
  for (std::size_t k = 0; k < cloth_solids_.size(); ++k) {
    const MotionSchedule& keys = solid_motions_[k];
    if (!keys.empty()) solid_piece_[k] = {keys.at(t_piece_), keys.at(t_piece_ + h_), h_};
  }
  for (Index i = 0; i < x_.rows(); ++i) {
    if (topo_.inv_mass[i] == 0.0) continue;
    const Vec3 p = row(x_, i);
    // Of the surfaces near the vertex, the nearest gives its plane (a vertex on a box beside the
    // pole keeps the box's).
    double nearest = std::numeric_limits<double>::infinity();
    const auto offer = [&](double gap, const Vec3& n, double offset, double speed) {
      if (!(gap < nearest)) return;
      nearest = gap;
      resting_.row(i) = n.transpose();
      resting_offset_[i] = offset;
      resting_speed_[i] = speed;
    };
    // The pole, in its own frame at the piece's start (at rest: the world's).
    const Vec3 q = pole_moves_ ? pole_motion_.from.inverse(p) : p;
    if (built(Stage::kPole) && q.y() >= pole.base.y() && q.y() <= pole.base.y() + pole.height) {
      const Vec3 radial(q.x() - pole.base.x(), 0.0, q.z() - pole.base.z());
      const double r = radial.norm();
      if (r > 0 && r - pole_plane <= std::max(pole.radius, h_ * row(v_, i).norm())) {
        const Vec3 n = radial / r;
        if (!pole_moves_) {
          offer(r - pole_plane, n, pole.base.dot(n) + pole_plane, 0.0);
        } else {
          const Vec3 surface(pole.base.x() + n.x() * pole_plane, q.y(),
                             pole.base.z() + n.z() * pole_plane);  // in the pole's frame
          const Vec3 nw = pole_motion_.to.R * n;
          offer(r - pole_plane, nw, nw.dot(pole_motion_.to.apply(surface)),
                nw.dot(pole_motion_.velocity_at(surface)));
        }
      }
    }
    for (std::size_t k = 0; k < cloth_solids_.size(); ++k) {
      const ClothSolid& s = cloth_solids_[k];
      const double reach = (1.0 + kRestingSlack) * s.thickness;
      // True when q is farther than `listed` from the geometry along some axis: the bounding box
      // (grown by the thickness) grown to what the distance test below lists. Grown by the
      // thickness alone, it left out a vertex resting a hair (< 10 um) beyond the thickness, where
      // the sweep stops them, and the projection put back, every step, what the solve let fall
      // (docs/solids.md).
      const auto beyond = [&](const Vec3& q, double listed) {
        const double more = listed - s.thickness;
        return (q.array() < s.lo.array() - more).any() || (q.array() > s.hi.array() + more).any();
      };
      if (solid_motions_[k].empty()) {
        // Listed as far as its speed takes it in the piece (as the pole lists them), and at
        // least one more slack (a vertex the last piece ended on its plane is `reach` from a flat
        // surface give or take round-off). A vertex that slid s over a curved surface ends about
        // s^2 / 2R beyond its plane (R the radius): listed by the slack alone, it dropped out,
        // fell in unheld, and the projection pushed it out sideways, past the strain limit
        // (banner_walk's sphere, docs/solids.md).
        const double ahead = h_ * row(v_, i).norm();
        const double listed = reach + std::max(kRestingSlack * s.thickness, ahead);
        if (beyond(p, listed)) continue;
        Vec3 n;
        const double d = solid_distance(s.geometry, p, &n);
        if (d <= listed) offer(d - reach, n, p.dot(n) - (d - reach), 0.0);
        continue;
      }
      // Moving: in the solid's frame at the piece's start, listed as far as the vertex and the
      // surface can close in the piece (the solve holds only those it would carry through); the
      // plane where the surface is at the piece's end, moving with it.
      const RigidMotion& m = solid_piece_[k];
      const Vec3 ql = m.from.inverse(p);
      const double ahead = h_ * (row(v_, i).norm() + m.velocity_at(ql).norm());
      const double listed = reach + std::max(s.thickness, ahead);
      if (beyond(ql, listed)) continue;
      Vec3 n;
      const double d = solid_distance(s.geometry, ql, &n);
      if (d <= listed) {
        const Vec3 surface = ql - (d - reach) * n, nw = m.to.R * n;  // on the grown surface
        offer(d - reach, nw, nw.dot(m.to.apply(surface)), nw.dot(m.velocity_at(surface)));
      }
    }
  }
}

// Each solid in turn, moving or at rest; the work a moving solid does (its surface's velocity
// times the impulse it gave) is prescribed motion's, the rest the projection's.
void Simulation::stage_solids() {
  if (!built(Stage::kSolids)) return;
  SolidContacts all;
  {
    StageClock::Scope t(&clock_, Stage::kSolids);
    for (std::size_t k = 0; k < cloth_solids_.size(); ++k) {
      const bool moves = !solid_motions_[k].empty();
      const SolidContacts c = collide_solid(cloth_solids_[k], moves ? &solid_piece_[k] : nullptr,
                                            x_piece_, x_, v_, topo_.inv_mass, topo_.mass);
      all.moved += c.moved;
      all.wall_work += c.wall_work;
    }
  }
  if (all.moved == 0) return;
  ledger_.pins += all.wall_work;
  book_energy_change(ledger_.solids, all.wall_work);
}

void Simulation::stage_self_collision() {
  if (!built(Stage::kSelfCollision)) return;
  {
    StageClock::Scope t(&clock_, Stage::kSelfCollision);
    sweep_pin_work_ = 0;
    const bool frame = built(Stage::kPins);
    const Vec3 p0 = frame ? momentum() : Vec3::Zero();
    sweep_strain_momentum_.setZero();
    // Moving pins: the response runs in their frame. Its start is the piece's start carried by
    // the pins' pose to the piece's end (rigidly: as collision-free as the start, the pins where
    // they are), so a crossing stops short and the fallback freezes relative to the pins, not to
    // the lab: a flag carried at 5 m/s was sent back 5 cm a step behind its pins.
    if (frame)
      for (Index i = 0; i < x_.rows(); ++i)
        x0_carried_.row(i) =
            pins_frame_.to.apply(pins_frame_.from.inverse(row(x_piece_, i))).transpose();
    // The pole inside the sweeps, at rest or where the pins' pose puts it (at rest in their
    // frame: at the piece's end at both x0_carried_ and x_), moving with them.
    self_collision_->resolve(frame ? x0_carried_ : x_piece_, x_, v_, topo_.inv_mass,
                             built(Stage::kPole) ? &scene_.pole : nullptr,
                             built(Stage::kStrainLimit) ? &strain_projector_ : nullptr,
                             pole_moves_ ? &pole_motion_ : nullptr);
    // The rest of the response does not conserve momentum either: a pinned vertex takes no share
    // of a contact's impulse (the pin holds it), impulses are averaged per vertex (Jacobi), and
    // the fallback stops a group with a pin. Its work in the lab is its work in the pins' frame
    // plus V . dP (V: the pins' velocity), the frame's, booked to the pins (exact for pins that
    // translate; docs/design.md "Moving pins and Galilean invariance").
    if (frame) sweep_pin_work_ += pins_centre(v_).dot(momentum() - p0 - sweep_strain_momentum_);
  }
  // its change of E: stage_check, with the strain of the same positions
}

// entry += the change of E since energy_run_, less what other entries booked meanwhile (J).
void Simulation::book_energy_change(double& entry, double booked_elsewhere) {
  StageClock::Scope t(&clock_, Stage::kCheck);
  book_energy(entry, booked_elsewhere, energy_now());
}

// entry += e - energy_run_ - booked_elsewhere, with e = E now (J).
void Simulation::book_energy(double& entry, double booked_elsewhere, double e) {
  entry += e - energy_run_ - booked_elsewhere;
  energy_run_ = e;
  x_of_e_ = x_;
  v_of_e_ = v_;
}

// energy_run_ when (x_, v_) hold the bits it was computed from (and the integrator's gravity is
// the scene's): total_energy is a function of those bits, so the integrator need not sum it again.
void Simulation::offer_known_energy() {
  if (forces_.gravity && forces_.g == scene_.gravity && same_bits(x_, x_of_e_) &&
      same_bits(v_, v_of_e_))
    scratch_.energy_known = energy_run_;
}

// "visual": the exported geometry is the positions displaced by eq. 5; physics is untouched.
void Simulation::stage_flap_visual() {
  StageClock::Scope t(&clock_, Stage::kFlapVisual);
  u_p_ =
      sample_pole_air_speed(time_, scene_.dt);  // relative to the pins' motion over the next step
  flap_.displace(x_, n_, u_p_, time_, render_x_);
  compute_vertex_normals(topo_, render_x_, render_n_);
}

// Air at every mass for this step's start time: the wind schedule (analytic), or the grid
// sampled trilinearly (the grid then advances in advance_fluid, taking the flag's drag reaction
// when the coupling is two-way).
void Simulation::stage_air() {
  if (built(Stage::kWind)) {
    StageClock::Scope t(&clock_, Stage::kWind);
    const Vec3 w = scene_.air.wind.at(t_piece_);
    u_.rowwise() = w.transpose();
    if (noise_.enabled())
      parallel_for(u_.rows(), [&](Index i) {
        u_.row(i) += noise_.velocity(x_.row(i).transpose(), t_piece_).transpose();
      });
  }
  if (air_sampled_) return;  // sample_air_ahead did, and scaled the drag
  if (built(Stage::kFluid)) {
    StageClock::Scope t(&clock_, Stage::kFluid);
    air_outside_last_ = air_grid_->sample(x_, u_);
    air_outside_total_ += air_outside_last_;
  }
  scale_drag_for_air_response();
}

// Two-way coupling's implicit air response (docs/coupling.md). The air a mass drags is a parcel
// of mass rho h^3 / W (W: the sum of the squared weights the sampling gives the nodes there):
// the drag's slope beta = C_D rho S |w| (w = u - v; u for the paper's |u| u - |v| v) changes the
// air it reads by kappa = beta dt W / (rho h^3) of w over a step, so an explicit exchange
// overshoots past kappa = 1 and diverges past 2 (fine grids, strong wind). With the parcel's
// response implicit (linearised), F = (F0 - beta dv) / (1 + kappa): every mass's drag and its
// Jacobian times 1 / (1 + kappa), and the air takes that same impulse back.
void Simulation::scale_drag_for_air_response() {
  if (!built(Stage::kCoupling)) return;
  StageClock::Scope t(&clock_, Stage::kCoupling);
  const Index N = topo_.num_vertices();
  air_grid_->sample_weight_squares(x_.data(), long(N), weight_sq_.data());
  const double h = air_grid_->geometry().h;
  const double k = scene_.drag.coefficient * scene_.dt / (h * h * h);
  const bool paper = scene_.drag.model == DragModel::kPaper;
  for (Index i = 0; i < N; ++i) {
    const Vec3 w = paper ? Vec3(u_.row(i)) : Vec3(u_.row(i) - v_.row(i));
    drag_scale_[i] = 1.0 / (1.0 + k * topo_.area[i] * w.norm() * weight_sq_[i]);
  }
}

// Two-way coupling (docs/coupling.md): the air takes back the drag impulse each mass received in
// this step, with the opposite sign, at the positions the step sampled it (x_start_); the
// fluid's step spreads it with the sampling's weights after advection, before the projection:
// this step's ("two_way") or the next one's ("two_way_lagged"; in flight until then).
void Simulation::stage_coupling() {
  if (!built(Stage::kCoupling)) return;
  StageClock::Scope t(&clock_, Stage::kCoupling);
  reaction_ = -drag_impulse_;
  reaction_at_ = x_start_;
}

// The air restores itself when its step fails; the cloth's step is then undone too, so the
// whole Simulation is as it was at the start of the step.
void Simulation::advance_fluid() {
  if (!fluid_) return;
  StageClock::Scope t(&clock_, Stage::kFluid);
  try {
    fluid_->step(scene_.dt, reactions_.empty() ? nullptr : &reactions_);
  } catch (const DivergenceError& e) {
    air_diverged(e);
  }
}

void Simulation::air_diverged(const DivergenceError& e) {
  for (int k = 0; k < num_flags(); ++k) flag(k).undo_step();
  throw DivergenceError(std::string(e.what()) + " (air.cell_size, air.resolution)", step_count_,
                        time_, -1, e.cause);
}

// The pins hold the flag: over the piece they give it what its momentum gained beyond the
// forces that act on it (gravity, drag, eq. 5's force); the flag pushes them with the opposite
// (pole_force). The tethers' strain limiting inside the integrator counts with the pins.
void Simulation::stage_integrate() {
  const Vec3 p0 = momentum();
  const Vec3 j0 = forces_.drag ? Vec3(drag_impulse_.colwise().sum()) : Vec3::Zero();
  IntegrateStatus status;
  {
    // The force kernels, strain limiting and energy bookkeeping it calls time themselves.
    StageClock::Scope t(&clock_, Stage::kIntegrate);
    offer_known_energy();
    status =
        integrate(topo_, forces_, scene_.integrator, h_, u_, x_, v_, scratch_, stats_, &clock_);
  }
  book_integrator_work();
  halvings_.piece_energy += stats_.energy_halvings;  // this piece's, before the step's are added
  halvings_.cg += stats_.halvings - stats_.energy_halvings;
  if (status != IntegrateStatus::kOk) integrate_failed(status);
  Vec3 external = topo_.mass.sum() * h_ * scene_.gravity + stats_.work.contact_impulse;
  if (forces_.drag) external += Vec3(drag_impulse_.colwise().sum()) - j0;
  if (forces_.external) external += h_ * Vec3(forces_.external->colwise().sum());
  step_pin_impulse_ += external - (momentum() - p0);
}

Vec3 Simulation::momentum() const { return momentum(v_); }

Vec3 Simulation::momentum(const MatX3& v) const {
  Vec3 p = Vec3::Zero();
  for (Index i = 0; i < v.rows(); ++i) p += topo_.mass[i] * Vec3(v.row(i));
  return p;
}

Vec3 Simulation::pole_force_mean() const {
  const double t = time_ - pole_time_mark_;
  return t > 0 ? Vec3((pole_impulse_ - pole_impulse_mark_) / t) : pole_force_;
}

void Simulation::reset_pole_force_mean() {
  pole_impulse_mark_ = pole_impulse_;
  pole_time_mark_ = time_;
}

// The work of each force as the integrator applied it (StepWork) into the ledger.
void Simulation::book_integrator_work() {
  const StepWork& w = stats_.work;
  ledger_.edits += stats_.energy_before - energy_end_;  // the state written between steps
  ledger_.drag += w.drag;
  ledger_.flap += w.external + w.drift;
  ledger_.damping += w.damping;
  ledger_.pins += w.pins;
  ledger_.strain_limit += w.strain_limit;
  ledger_.integrator += w.remainder;
  energy_run_ = stats_.energy_after;
  x_of_e_(0, 0) = std::numeric_limits<double>::quiet_NaN();  // not the state E was taken at
}

void Simulation::integrate_failed(IntegrateStatus status) {
  const IntegratorParams& ip = scene_.integrator;
  std::ostringstream s;
  switch (status) {
    case IntegrateStatus::kTooManySubsteps:
      s << "the stable step estimate " << stats_.stable_step << " s needs more than "
        << ip.max_substeps << " substeps (integrator.max_substeps)";
      diverge("substeps", -1, s.str());
    case IntegrateStatus::kUnstableStep:
      s << "explicit step dt / substeps = " << scene_.dt / ip.substeps
        << " s exceeds the stable step estimate " << stats_.stable_step
        << " s (integrator.adaptive = false)";
      diverge("unstable_step", -1, s.str());
    case IntegrateStatus::kEnergyGain:
      s << "the implicit step made more than integrator.energy_tolerance x the energy scale = "
        << forces_.energy_guard << " J of energy beyond the work of its forces even after "
        << ip.max_halvings << " step halvings";
      diverge("energy", -1, s.str());
    case IntegrateStatus::kCgFailed:
      s << "conjugate gradient did not reach integrator.cg_tolerance = " << ip.cg_tolerance
        << " in " << ip.cg_max_iterations << " iterations even after " << ip.max_halvings
        << " step halvings";
      diverge("cg", -1, s.str());
    case IntegrateStatus::kOk: break;
  }
  throw std::logic_error("integrate_failed called without a failure");
}

// Finite and strain below integrator.max_strain, or DivergenceError now. Then plausibility
// (docs/energy.md): strain within the strain limit's promise, and the step so far (all its
// pieces) has made no more energy than the tolerance allows beyond what the stages' work
// explains; a piece that fails either is returned, and the step is redone in shorter pieces.
Simulation::Implausible Simulation::stage_check() {
  StageClock::Scope t(&clock_, Stage::kCheck);
  check_finite();
  double strain;
  Index worst;
  ClothEnergy e;
  const bool energy = built(Stage::kSelfCollision);  // its change of E, from the same lengths
  // Beside the strain and energy sums, the normals the step's end needs (finish_step finds them
  // computed from these bits): in a pipelined step the air's thread, done with its own, takes
  // one of the two (for_each_chunk), instead of the normals running after the join.
  for_each_chunk(2, [&](Index c) {
    if (c == 1)
      update_normals();
    else if (energy)
      e = cloth_energy_and_max_strain(topo_, scene_.gravity, x_, v_, strain, &worst);
    else
      strain = flagsim::max_strain(topo_, x_, &worst);
  });
  if (energy) {
    ledger_.pins += sweep_pin_work_;  // the moving pins' share of its response
    book_energy(ledger_.self_collision, sweep_pin_work_, e.total());
  }
  Implausible bad = check_strain(strain, worst);
  if (!bad.cause.empty()) return bad;
  return check_energy();
}

void Simulation::check_finite() {
  const Index N = topo_.num_vertices();
  for (Index i = 0; i < N; ++i)
    if (!x_.row(i).allFinite() || !v_.row(i).allFinite())
      diverge("non-finite", long(i), "non-finite position or velocity");
}

// Above integrator.max_strain: DivergenceError; above the strain limit's promise: implausible.
Simulation::Implausible Simulation::check_strain(double e, Index worst) {
  // the worst vertex: whichever end of the worst spring moved more in this step
  long vertex = -1;
  if (worst >= 0) {
    const int a = topo_.springs(worst, 0), b = topo_.springs(worst, 1);
    vertex = (x_.row(a) - x_start_.row(a)).norm() >= (x_.row(b) - x_start_.row(b)).norm() ? a : b;
  }
  if (e > scene_.integrator.max_strain) {
    std::ostringstream s;
    s << "spring strain " << e
      << " exceeds integrator.max_strain = " << scene_.integrator.max_strain;
    diverge("strain", vertex, s.str());
  }
  const double limit = scene_.integrator.strain_limit;
  if (limit > 0 && e > limit + kStrainLimitSlack) {
    std::ostringstream s;
    s << "spring strain " << e << " exceeds the strain limit's promise, integrator.strain_limit + "
      << kStrainLimitSlack << " = " << limit + kStrainLimitSlack;
    return {"strain", vertex, s.str()};
  }
  return {};
}

// Per step, and net over the run: steps each just within the tolerance must not add up to a
// flag that holds many times it (what the integrator and projections took out counts back).
// The net counts only as far as the flag still holds it: a flag can hold no more unexplained
// energy than its kinetic and spring energy and its rise above where it started. A flag hanging
// at its strain limit has the projection lift what the solve lets down every step, about
// 0.3 J/s (64 x 64 paper flag) that the solve and the damping take out again, while it holds
// 0.01 J; counted without that bound the net crossed the allowance after 3.4 s.
Simulation::Implausible Simulation::check_energy() const {
  if (scene_.integrator.energy_tolerance <= 0) return {};
  const double allowed = scene_.integrator.energy_tolerance * energy_scale_;
  const double gain = ledger_.unexplained_since(ledger_start_);
  double held = ledger_.unexplained_net();
  if (held > allowed) held = std::min(held, holdable_energy());
  if (!(gain > allowed) && !(held > allowed)) return {};
  const EnergyLedger& a = ledger_;
  const EnergyLedger& b = ledger_start_;
  std::ostringstream s;
  s << "the step (in pieces of " << h_ << " s) made " << gain
    << " J that no stage's work explains (integrator " << a.integrator - b.integrator
    << ", strain limiting " << a.strain_limit - b.strain_limit << ", pole " << a.pole - b.pole
    << ", solids " << a.solids - b.solids << ", self-collision "
    << a.self_collision - b.self_collision << " J; since the start, net "
    << ledger_.unexplained_net() << " J, of which the flag can still hold " << held
    << " J), more than integrator.energy_tolerance x the energy scale = " << allowed << " J";
  return {"energy", -1, s.str()};
}

// What the flag can hold of the energy no stage explains, J: its kinetic and spring energy and its
// rise above where it started. Once its pins have moved, the kinetic energy and the rise are
// taken relative to the pins (their centre of mass's velocity and rise), so that a flag carried
// at a constant velocity, or up, holds what the still one holds: the lab's kinetic energy of a
// flag carried at 5 m/s is mostly the frame's (0.82 J of the paper flag's), not the flag's.
double Simulation::holdable_energy() const {
  const ClothEnergy e = energy();
  if (!built(Stage::kPins))
    return e.kinetic + e.spring + std::max(e.gravity - gravity_potential_0_, 0.0);
  const Vec3 V = pins_centre(v_), lift = pins_centre(x_) - pins_centre_0_;
  double kinetic = 0;
  for (Index i = 0; i < v_.rows(); ++i)
    kinetic += 0.5 * topo_.mass[i] * (Vec3(v_.row(i)) - V).squaredNorm();
  const double rise =
      e.gravity - gravity_potential_0_ + topo_.mass.sum() * scene_.gravity.dot(lift);
  return kinetic + e.spring + std::max(rise, 0.0);
}

// The pinned rows' centre of mass of a (P x 3 in pin order when pins_only, else N x 3): the frame
// of the pins. No pins: zero.
Vec3 Simulation::pins_centre(const MatX3& a, bool pins_only) const {
  Vec3 sum = Vec3::Zero();
  double m = 0;
  for (Index k = 0; k < Index(pin_index_.size()); ++k) {
    const double mk = topo_.mass[pin_index_[k]];
    sum += mk * Vec3(a.row(pins_only ? k : pin_index_[k]));
    m += mk;
  }
  return m > 0 ? Vec3(sum / m) : Vec3::Zero();
}

void Simulation::diverge(const std::string& cause, long vertex, const std::string& detail) {
  restore_step_start();
  update_normals();
  std::ostringstream s;
  s << "simulation diverged at step " << step_count_ << " (t = " << time_ << " s)";
  if (vertex >= 0) s << ", vertex " << vertex;
  s << ": " << detail << "; the state was restored to the start of that step. Try ";
  const IntegratorParams& ip = scene_.integrator;
  if (ip.method == Method::kExplicit)
    s << (ip.adaptive ? "" : "integrator.adaptive = true, ") << "integrator.method = 'implicit', ";
  if (cause == "energy")
    s << "a smaller dt, stiffness closer to the shear and bend springs', or a larger "
         "integrator.energy_tolerance (0 switches the check off; docs/energy.md).";
  else
    s << "a smaller dt.";
  throw DivergenceError(s.str(), step_count_, time_, vertex, cause);
}

std::vector<std::pair<std::string, double>> Simulation::timings() const {
  std::vector<std::pair<std::string, double>> out;
  for (int s = 0; s < kNumStages; ++s) {
    bool any = false;
    double seconds = 0;
    for (int i = 0; i < num_flags(); ++i) {
      any = any || flag(i).built_[s];
      seconds += flag(i).clock_.seconds(Stage(s)) + flag(i).air_clock_.seconds(Stage(s));
    }
    if (any) out.emplace_back(name_of(Stage(s)), seconds);
  }
  return out;
}

ClothEnergy Simulation::energy() const { return cloth_energy(topo_, scene_.gravity, x_, v_); }

EnergyLedger Simulation::energy_ledger() const {
  EnergyLedger l = ledger_;
  l.gravity = gravity_potential_0_ - energy().gravity;
  return l;
}

void Simulation::air_velocity(const MatX3& points, MatX3& out) const {
  out.resize(points.rows(), 3);
  if (scene_.air.model == AirModel::kNone) {
    out.setZero();
    return;
  }
  if (air_grid_) {
    air_grid_->sample(points, out);
    return;
  }
  out.rowwise() = scene_.air.wind.at(time_).transpose();
  if (noise_.enabled())
    for (Index i = 0; i < points.rows(); ++i)
      out.row(i) += noise_.velocity(points.row(i).transpose(), time_).transpose();
}

}  // namespace flagsim
