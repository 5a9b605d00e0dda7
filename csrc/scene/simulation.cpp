#include "scene/simulation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "collision/pole.h"
#include "common/errors.h"
#include "common/timer.h"
#include "flapping/flapping.h"

namespace flagsim {

const char* Simulation::stage_name(Stage s) {
  switch (s) {
    case kWind: return "wind";
    case kFluid: return "fluid";
    case kGravity: return "gravity";
    case kDrag: return "drag";
    case kSprings: return "springs";
    case kIntegrate: return "integrate";
    case kStrainLimit: return "strain_limit";
    case kFlap: return "flap";
    case kPole: return "pole";
    case kSelfCollision: return "self_collision";
    case kCheck: return "check";
    case kFlapVisual: return "flap";
    case kNumStages: break;
  }
  throw std::logic_error("stage_name: unknown stage");
}

namespace {
Scene validated(const Scene& s) {
  s.validate();
  return s;
}
}  // namespace

Simulation::Simulation(const Scene& scene)
    : scene_(validated(scene)),
      topo_(build_flag_topology(scene_.flag)),
      scratch_(topo_) {
  const Index N = topo_.num_vertices();
  x_ = topo_.rest_positions;
  v_.setZero(N, 3);
  u_.setZero(N, 3);
  x_start_ = x_;
  v_start_ = v_;

  // Build only what the scene needs: a stage left out is never called and costs nothing.
  const bool air = scene_.air.model != "none" && scene_.air.density > 0;
  forces_.gravity = scene_.gravity.squaredNorm() > 0;
  forces_.drag = air && (scene_.drag.coefficient > 0 ||
                         (scene_.drag.model == "triangle" && scene_.drag.tangential_coefficient > 0));
  forces_.springs = topo_.stiffness.maxCoeff() > 0 || topo_.damping.maxCoeff() > 0;
  forces_.g = scene_.gravity;
  forces_.drag_params = scene_.drag;
  forces_.rho = scene_.air.density;
  built_[kWind] = forces_.drag && scene_.air.model == "uniform";
  built_[kFluid] = forces_.drag && scene_.air.model == "grid";
  if (built_[kFluid]) build_fluid();
  built_[kGravity] = forces_.gravity;
  built_[kDrag] = forces_.drag;
  built_[kSprings] = forces_.springs;
  built_[kIntegrate] = true;
  built_[kStrainLimit] = scene_.integrator.strain_limit > 0;
  const std::string& flap = scene_.flapping.mode;
  built_[kFlap] = flap == "displace" || flap == "force";
  built_[kFlapVisual] = flap == "visual";
  built_[kPole] = scene_.pole.enabled;
  built_[kSelfCollision] = scene_.self_collision.enabled;
  built_[kCheck] = true;
  if (built_[kSelfCollision]) {
    self_collision_ = std::make_unique<SelfCollision>(topo_.triangles, N, scene_.self_collision);
    // Strain limiting inside the collision sweeps: contacts alone would hold a stretch.
    strain_projector_ = [this](MatX3& x, MatX3& v) { limit_cloth_strain(x, v); };
  }
  for (int s = 0; s < kNumStages; ++s)
    if (built_[s]) stage_names_.emplace_back(stage_name(Stage(s)));
  n_.resize(N, 3);
  update_normals();
  setup_flapping();
}

void Simulation::setup_flapping() {
  const Index N = topo_.num_vertices();
  flap_z_.setZero(N);
  if (!built_[kFlap] && !built_[kFlapVisual]) return;
  const FlappingParams& fp = scene_.flapping;
  noise_ = Perlin1D(fp.seed);
  flap_xy_ = topo_.uv;  // x = u (0 at the pole edge), y = v; y (1 - y) is symmetric
  // L: rest distance to the nearest pinned vertex (infinite, so A = amplitude, without pins).
  flap_L_.setConstant(N, std::numeric_limits<double>::infinity());
  for (Index j = 0; j < N; ++j) {
    if (!topo_.pinned(j)) continue;
    for (Index i = 0; i < N; ++i)
      flap_L_[i] = std::min(flap_L_[i], (topo_.rest_positions.row(i) - topo_.rest_positions.row(j)).norm());
  }
  flap_applied_.setZero(N);
  flap_before_.setZero(N);
  flap_after_.setZero(N);
  // u_p is sampled along the flag's pole-side edge (column 0, beside the pole), at rest.
  edge_points_.resize(topo_.rows, 3);
  for (int r = 0; r < topo_.rows; ++r) edge_points_.row(r) = topo_.rest_positions.row(r * topo_.cols);
  edge_air_.resize(topo_.rows, 3);
  visual_ = built_[kFlapVisual];
  if (visual_) {
    u_p_ = sample_pole_air_speed();
    flapping_displacement(noise_, flap_xy_, flap_L_, u_p_, time_, fp, flap_z_);
    render_x_ = x_ + flap_z_.asDiagonal() * n_;
    render_n_.resize(N, 3);
    compute_vertex_normals(topo_, render_x_, render_n_);
  }
}

// The air grid (paper §2): one-way coupling, so it only needs the flag to start inside it.
void Simulation::build_fluid() {
  const AirParams& a = scene_.air;
  const Vec3 lo = a.origin, hi = a.origin + a.cell_size * Vec3(a.resolution[0], a.resolution[1], a.resolution[2]);
  for (Index i = 0; i < x_.rows(); ++i) {
    const Vec3 p = x_.row(i).transpose();
    if ((p.array() < lo.array()).any() || (p.array() > hi.array()).any()) {
      std::ostringstream s;
      s << "flag.origin should place the flag inside the air grid [" << lo.x() << ", " << hi.x() << "] x ["
        << lo.y() << ", " << hi.y() << "] x [" << lo.z() << ", " << hi.z() << "] m (air.origin, air.resolution, "
        << "air.cell_size), got vertex " << i << " at (" << p.x() << ", " << p.y() << ", " << p.z() << ")";
      throw InvalidArgument(s.str());
    }
  }
  fluid_ = std::make_unique<Fluid>(static_cast<const FluidParams&>(a), "air");
}

void Simulation::update_normals() { compute_vertex_normals(topo_, x_, n_); }

void Simulation::step(long n) {
  if (n < 0) fail_param("n", ">= 0", n);
  for (long k = 0; k < n; ++k) step_once();
}

// One step, as the method reads: air -> forces + integrate -> constraints -> check.
void Simulation::step_once() {
  x_start_ = x_;
  v_start_ = v_;
  stage_air();
  stage_integrate();  // includes strain limiting after every substep, timed as its own stage
  if (built_[kFlap]) stage_flap();
  stage_collide();
  stage_check();
  if (built_[kFlap]) flap_applied_ = flap_z_;
  advance_fluid();  // after the check: a rolled-back step leaves the air as it was
  ++step_count_;
  time_ = double(step_count_) * scene_.dt;  // no drift from summing dt
  update_normals();
  if (built_[kFlapVisual]) stage_flap_visual();
}

double Simulation::sample_pole_air_speed() {
  air_velocity(edge_points_, edge_air_);
  return edge_air_.rowwise().norm().mean();
}

// Paper eq. 5 at the end of the step, t + dt. "displace" moves each vertex along its normal by
// the change of z since the last step, so the applied offset follows eq. 5 and springs, drag,
// pins and collisions respond to it. "force" applies F = m d2z/dt2 n (the force that would move a
// free mass along the wave; d2z/dt2 by the central difference over dt) by operator splitting,
// v += dt F / m and x += dt^2 F / m, so pinned vertices (inv_mass 0) stay put.
void Simulation::stage_flap() {
  ScopedTimer t(seconds_[kFlap]);
  const FlappingParams& fp = scene_.flapping;
  const double h = scene_.dt, t1 = double(step_count_ + 1) * h;
  u_p_ = sample_pole_air_speed();
  compute_vertex_normals(topo_, x_, n_);
  flapping_displacement(noise_, flap_xy_, flap_L_, u_p_, t1, fp, flap_z_);
  const Index N = topo_.num_vertices();
  if (fp.mode == "displace") {
    for (Index i = 0; i < N; ++i) {
      if (topo_.pinned(i)) continue;
      x_.row(i) += (flap_z_[i] - flap_applied_[i]) * n_.row(i);
    }
    // The cloth stays within its strain limit: eq. 5's amplitude grows with the wind, and at
    // storm speeds its wave alone would stretch the cloth severalfold.
    if (built_[kStrainLimit]) limit_cloth_strain(x_, v_);
    return;  // flap_applied_ = flap_z_ once the step has passed its check
  }
  flapping_displacement(noise_, flap_xy_, flap_L_, u_p_, t1 - h, fp, flap_before_);
  flapping_displacement(noise_, flap_xy_, flap_L_, u_p_, t1 + h, fp, flap_after_);
  for (Index i = 0; i < N; ++i) {
    if (topo_.pinned(i)) continue;
    const double a = (flap_after_[i] - 2 * flap_z_[i] + flap_before_[i]) / (h * h);
    v_.row(i) += (h * a) * n_.row(i);
    x_.row(i) += (h * h * a) * n_.row(i);
  }
}

// Pole, then self-collision, which keeps the pole in its own sweeps and ends on it, both from
// the start-of-step positions (so both are swept). A vertex the pole stops while its neighbours
// move on stretches their springs, and strain limiting pulls it along chords through the pole:
// the two projections alternate (at most kPoleStrainRounds times) until the pole moves nothing,
// so that a flag blown back wraps around the pole without over-stretching; the pole has the
// last word.
// The integrator's strain limit on (x, v) over one step: outside the integrator, after the
// flapping displacement, between pole passes and inside the collision sweeps.
void Simulation::limit_cloth_strain(MatX3& x, MatX3& v) {
  limit_strain(topo_, scene_.integrator.strain_limit, scene_.integrator.strain_limit_iterations,
               scene_.dt, x, v);
}

void Simulation::stage_collide() {
  constexpr int kPoleStrainRounds = 10;
  if (built_[kPole]) {
    Index moved;
    {
      ScopedTimer t(seconds_[kPole]);
      moved = collide_pole(scene_.pole, x_start_, x_, v_, topo_.inv_mass);
    }
    for (int k = 0; k < kPoleStrainRounds && moved > 0 && built_[kStrainLimit]; ++k) {
      {
        ScopedTimer t(seconds_[kStrainLimit]);
        limit_cloth_strain(x_, v_);
      }
      ScopedTimer t(seconds_[kPole]);
      moved = collide_pole(scene_.pole, x_start_, x_, v_, topo_.inv_mass);
    }
  }
  if (built_[kSelfCollision]) {
    ScopedTimer t(seconds_[kSelfCollision]);
    self_collision_->resolve(x_start_, x_, v_, topo_.inv_mass,
                             built_[kPole] ? &scene_.pole : nullptr,
                             built_[kStrainLimit] ? &strain_projector_ : nullptr);
  }
}

// "visual": the exported geometry is the positions displaced by eq. 5; physics is untouched.
void Simulation::stage_flap_visual() {
  ScopedTimer t(seconds_[kFlapVisual]);
  u_p_ = sample_pole_air_speed();
  flapping_displacement(noise_, flap_xy_, flap_L_, u_p_, time_, scene_.flapping, flap_z_);
  for (Index i = 0; i < topo_.num_vertices(); ++i)
    render_x_.row(i) = x_.row(i) + flap_z_[i] * n_.row(i);
  compute_vertex_normals(topo_, render_x_, render_n_);
}

// Air at every mass for this step's start time: the wind schedule (analytic), or the grid
// sampled trilinearly (the grid then advances in advance_fluid). The flag never pushes the air.
void Simulation::stage_air() {
  if (built_[kWind]) {
    ScopedTimer t(seconds_[kWind]);
    const Vec3 w = scene_.air.wind.at(time_);
    u_.rowwise() = w.transpose();
  }
  if (built_[kFluid]) {
    ScopedTimer t(seconds_[kFluid]);
    air_outside_last_ = fluid_->sample(x_, u_);
    air_outside_total_ += air_outside_last_;
  }
}

void Simulation::advance_fluid() {
  if (!built_[kFluid]) return;
  ScopedTimer t(seconds_[kFluid]);
  fluid_->step(scene_.dt);
}

void Simulation::stage_integrate() {
  const ForceTimings before = force_seconds_;
  double total = 0;
  IntegrateStatus status;
  {
    ScopedTimer t(total);
    status = integrate(topo_, forces_, scene_.integrator, scene_.dt, u_, x_, v_, scratch_, stats_,
                       &force_seconds_);
  }
  // The integrate stage's own cost excludes the force kernels it called (timed separately).
  seconds_[kGravity] += force_seconds_.gravity - before.gravity;
  seconds_[kDrag] += force_seconds_.drag - before.drag;
  seconds_[kSprings] += force_seconds_.springs - before.springs;
  seconds_[kStrainLimit] += force_seconds_.strain_limit - before.strain_limit;
  seconds_[kIntegrate] += total - (force_seconds_.gravity - before.gravity) -
                          (force_seconds_.drag - before.drag) -
                          (force_seconds_.springs - before.springs) -
                          (force_seconds_.strain_limit - before.strain_limit);
  if (status == IntegrateStatus::kTooManySubsteps) {
    std::ostringstream s;
    s << "the stable step estimate " << stats_.stable_step << " s needs more than "
      << scene_.integrator.max_substeps << " substeps (integrator.max_substeps)";
    diverge("substeps", -1, s.str());
  }
  if (status == IntegrateStatus::kUnstableStep) {
    std::ostringstream s;
    s << "explicit step dt / substeps = " << scene_.dt / scene_.integrator.substeps
      << " s exceeds the stable step estimate " << stats_.stable_step
      << " s (integrator.adaptive = false)";
    diverge("unstable_step", -1, s.str());
  }
  if (status == IntegrateStatus::kCgFailed) {
    std::ostringstream s;
    s << "conjugate gradient did not reach integrator.cg_tolerance = "
      << scene_.integrator.cg_tolerance << " in " << scene_.integrator.cg_max_iterations
      << " iterations even after " << scene_.integrator.max_halvings << " step halvings";
    diverge("cg", -1, s.str());
  }
}

void Simulation::stage_check() {
  ScopedTimer t(seconds_[kCheck]);
  const Index N = topo_.num_vertices();
  for (Index i = 0; i < N; ++i)
    if (!x_.row(i).allFinite() || !v_.row(i).allFinite())
      diverge("non-finite", long(i), "non-finite position or velocity");
  Index worst = -1;
  const double e = flagsim::max_strain(topo_, x_, &worst);
  if (e > scene_.integrator.max_strain) {
    std::ostringstream s;
    s << "spring strain " << e << " exceeds integrator.max_strain = " << scene_.integrator.max_strain;
    // the worst vertex: whichever end of the worst spring moved more in this step
    long vertex = -1;
    if (worst >= 0) {
      const int a = topo_.springs(worst, 0), b = topo_.springs(worst, 1);
      vertex = (x_.row(a) - x_start_.row(a)).norm() >= (x_.row(b) - x_start_.row(b)).norm() ? a : b;
    }
    diverge("strain", vertex, s.str());
  }
}

void Simulation::diverge(const std::string& cause, long vertex, const std::string& detail) {
  x_ = x_start_;
  v_ = v_start_;
  update_normals();
  std::ostringstream s;
  s << "simulation diverged at step " << step_count_ << " (t = " << time_ << " s)";
  if (vertex >= 0) s << ", vertex " << vertex;
  s << ": " << detail << "; the state was restored to the start of that step. Try "
    << (scene_.integrator.method == "explicit" ? "integrator.adaptive = true, " : "")
    << "integrator.method = 'implicit' or a smaller dt.";
  throw DivergenceError(s.str(), step_count_, time_, vertex, cause);
}

std::vector<std::pair<std::string, double>> Simulation::timings() const {
  std::vector<std::pair<std::string, double>> out;
  for (int s = 0; s < kNumStages; ++s)
    if (built_[s]) out.emplace_back(stage_name(Stage(s)), seconds_[s]);
  return out;
}

ClothEnergy Simulation::energy() const { return cloth_energy(topo_, scene_.gravity, x_, v_); }

void Simulation::air_velocity(const MatX3& points, MatX3& out) const {
  out.resize(points.rows(), 3);
  if (scene_.air.model == "none") {
    out.setZero();
    return;
  }
  if (fluid_) {
    fluid_->sample(points, out);
    return;
  }
  out.rowwise() = scene_.air.wind.at(time_).transpose();
}

}  // namespace flagsim
