#include "scene/simulation.h"

#include <cmath>
#include <sstream>

#include "common/errors.h"
#include "common/timer.h"

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
    case kCheck: return "check";
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
  built_[kCheck] = true;
  for (int s = 0; s < kNumStages; ++s)
    if (built_[s]) stage_names_.emplace_back(stage_name(Stage(s)));
  n_.resize(N, 3);
  update_normals();
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
  stage_check();
  advance_fluid();  // after the check: a rolled-back step leaves the air as it was
  ++step_count_;
  time_ = double(step_count_) * scene_.dt;  // no drift from summing dt
  update_normals();
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
