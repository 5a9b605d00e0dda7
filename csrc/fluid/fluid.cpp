#include "fluid/fluid.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <sstream>
#include <type_traits>

#include "common/errors.h"
#include "common/memory.h"
#include "common/timer.h"
#include "fluid/advect.h"
#include "fluid/forces.h"
#include "fluid/multigrid.h"
#include "fluid/pressure.h"
#include "fluid/solids.h"
#include "fluid/turbulence.h"

namespace flagsim {

struct Fluid::Solver {
  FluidParams params;
  GridGeometry geo;
  double time = 0;
  mutable FluidStats stats;
  virtual ~Solver() = default;
  /// One step; true when the step itself showed the new field finite (the FFT diffusion's
  /// spectral pass, FftProjector::diffuse_and_project), false when all_finite must tell.
  virtual bool step(double dt, const std::vector<PointImpulses>* impulses,
                    const Fluid::WriteGate* gate) = 0;
  /// Every velocity value finite.
  virtual bool all_finite() const = 0;
  /// Back to the field and time t0 at the start of the last step (the step keeps its copy).
  virtual void undo_step(double t0) = 0;
  virtual void* data(int c) = 0;
  virtual void set_component(int c, const double* values) = 0;
  virtual long sample(const double* points, long m, double* out) const = 0;
  virtual void weight_squares(const double* points, long m, double* out) const = 0;
  virtual void divergence(double* out) const = 0;
  virtual double max_divergence() const = 0;
  /// Rebuilds the solid map (and what the pressure solve precomputes) from params.obstacles.
  virtual void rebuild_solids() = 0;
  virtual Vec3 obstacle_force(int index) const = 0;
  SolidMap solids;
  double last_dt = 0;     ///< s, the last step's dt (pressure = rho phi / dt)
  double step_start = 0;  ///< s, the time at the start of the last step (undo_step)
  /// Copies the iterative solve's warm start at the start of every step from now on.
  virtual void keep_warm_start() = 0;
  /// Back to the warm start kept at the start of the last step (zero when none is kept).
  virtual void restore_warm_start() = 0;
  /// Copies the solid-cell mask (nx*ny*nz, 1 = solid; nullptr: none) and rebuilds what the
  /// pressure backend precomputes (MIC factor, multigrid hierarchy).
  virtual void set_solid(const uint8_t* mask) = 0;
};

namespace {

/// Largest beta = nu dt / h^2 for which a periodic grid without solids diffuses explicitly
/// (forward Euler on u^n, fused into the advection): fft then projects with 2 transforms instead
/// of the spectral backward Euler's 6, pcg and multigrid skip the 3 diffusion solves. Per Fourier
/// mode the 7-point Laplacian's eigenvalue is -m / h^2 with m in [0, 12], so a step multiplies the
/// mode by 1 - x (explicit) or 1 / (1 + x) (implicit), x = beta m <= 12 beta, where the exact
/// factor is exp(-x): the two are first order with opposite errors of x^2 / 2 to leading order. At
/// beta <= 0.01 (x <= 0.12) even the grid-scale mode's explicit factor lies within 0.8 % of exp(-x)
/// (implicit: 0.7 %), every factor is in (0, 1] (monotone decay, no sign flip), and the step is 16x
/// inside forward Euler's stability limit beta <= 1/6. Air at the bench's and the scenes' grids has
/// beta ~ 1e-5 .. 1e-3.
constexpr double kExplicitViscosityBeta = 0.01;

template <class T>
struct TypedSolver final : Fluid::Solver {
  // Grid-sized arrays, each allocated only where a stage of this configuration uses it (counted
  // in docs/design.md "Memory"; tests/cpp/fluid/test_fluid.cpp GridArrays.* hold the counts).
  MacGrid<T> u, hat;           // current field; MacCormack / rhs scratch
  AlignedVector<T> phi;        // nx*ny*nz or empty (fft): potential dt p / rho (m^2/s)
  AlignedVector<T> phi_start;  // nx*ny*nz or empty (fft): phi at the step's start (undo_step)
  // nx*ny*nz or empty (fft), 1/s: the pcg / multigrid right-hand side in a step, divergence()
  // between steps
  mutable AlignedVector<T> div;
  std::unique_ptr<FftProjector<T>> fft;
  Laplace7 pressure_op;
  std::array<Laplace7, 3> diffusion_op;
  MicPreconditioner<T> mic;
  PoissonMultigrid<T> mg;
  CgScratch<T> cg;
  AlignedVector<uint8_t> solid;  // nx*ny*nz, 1 = solid cell (the pressure solve's mask)
  std::vector<FanStencil<T>> fans;
  AdvectScratch<T> padded;  // ghost-padded u^n and MacCormack predictor (the advection's source)
  double tol = 0;
  bool maccormack = false, use_fft = false, use_mg = false;
  std::vector<double> inflow_w;  // tunnel: the inflow profile per (j, k) of the x-min face
  InflowShape inflow_profile;    // and at departure points upstream of it
  bool explicit_viscosity = false;
  // Curl-noise turbulence (fluid/turbulence.h): psi on the edges at psi_time (psi_prev) and the
  // step's end (psi_next); NaN psi_time: psi_prev must be recomputed (after an undo or rebuild).
  // The noise slices psi blends, kept between steps (EdgeNoise).
  CurlNoise noise{TurbulenceParams{}, {}};
  EdgeNoise noise_slices;
  std::array<AlignedVector<T>, 3> psi_prev, psi_next;
  double psi_time = std::numeric_limits<double>::quiet_NaN();
  bool turbulent = false;

  explicit TypedSolver(const FluidParams& p) {
    params = p;
    geo.nx = p.resolution[0];
    geo.ny = p.resolution[1];
    geo.nz = p.resolution[2];
    geo.h = p.cell_size;
    geo.origin = p.origin;
    geo.periodic = p.boundary == Boundary::kPeriodic;
    maccormack = p.advection == Advection::kMacCormack;
    use_fft = p.pressure == Pressure::kFft;
    use_mg = p.pressure == Pressure::kMultigrid;
    u = MacGrid<T>(geo);
    // hat: MacCormack's predictor, the tunnel's, and the iterative and explicit diffusion's copy
    // (pcg, multigrid); a periodic semi-Lagrangian fft grid never touches it.
    if (maccormack || !geo.periodic || !use_fft) hat = MacGrid<T>(geo);
    padded.resize(geo, maccormack);
    const std::size_t cells = geo.cells().size();
    // fft projects in its first half spectrum: phi is the pcg / multigrid potential (and the
    // obstacles' pressure, which fft cannot have).
    if (!use_fft) phi.assign(cells, T(0));
    if (!use_fft) div.assign(cells, T(0));  // fft: the divergence readouts use its scratch
    solid.assign(cells, 0);
    // float cannot reach residuals near its epsilon: floor the relative tolerance there.
    tol = std::max(p.pcg_tolerance, 50.0 * double(std::numeric_limits<T>::epsilon()));
    pressure_op = pressure_operator(geo);
    for (int c = 0; c < 3; ++c) diffusion_op[c] = diffusion_operator(geo, c);
    if (use_fft) fft = std::make_unique<FftProjector<T>>(geo);  // MIC or multigrid: rebuild_solids
    std::size_t largest = cells;
    for (int c = 0; c < 3; ++c) largest = std::max(largest, u.shape[c].size());
    if (!use_fft) cg.resize(largest);  // the CG solves: pcg, multigrid, iterative diffusion
    fans = build_fan_stencils<T>(geo, p.fans, p.density);
    if (!geo.periodic) {
      inflow_w = inflow_weights(geo, p);
      inflow_profile = inflow_shape(geo, p);
    }
    turbulent = p.turbulence.enabled();
    if (turbulent)
      for (int a = 0; a < 3; ++a) {
        psi_prev[a].assign(edge_shape(geo, a).size(), T(0));
        psi_next[a].assign(edge_shape(geo, a).size(), T(0));
      }
    rebuild_solids();
    const Vec3 w0 = p.wind.at(0.0);
    set_uniform(geo.periodic ? w0 : Vec3(w0.x(), 0, 0));
    if (turbulent) {  // the noise at t = 0 on top of the mean flow
      noise.potential_on_edges(geo, 0.0, noise_slices, psi_next);
      for (int a = 0; a < 3; ++a) std::fill(psi_prev[a].begin(), psi_prev[a].end(), T(0));
      add_discrete_curl(psi_next, psi_prev, u);
      std::swap(psi_prev, psi_next);
      psi_time = 0.0;
      apply_boundary(Vec3(w0.x(), 0, 0));
    }
  }

  /// u += curl (psi(t1) - psi(t0)): the change of the noise over the step, a divergence-free
  /// forcing (a discrete curl), so without advection u stays the mean flow plus the noise.
  void add_turbulence(double t0, double t1) {
    if (!(psi_time == t0)) noise.potential_on_edges(geo, t0, noise_slices, psi_prev);
    noise.potential_on_edges(geo, t1, noise_slices, psi_next);
    add_discrete_curl(psi_next, psi_prev, u);
    std::swap(psi_prev, psi_next);
    psi_time = t1;
  }

  /// du = w J / (density h^3) at the nodes sample() reads at each point (spread_velocity).
  void add_impulses(const PointImpulses& j) {
    const double cell_mass = params.density * geo.h * geo.h * geo.h;
    spread_velocity(j.points->data(), long(j.points->rows()), j.impulses->data(), 1.0 / cell_mass,
                    u);
  }

  /// The MIC factor or the multigrid hierarchy of pressure_op (and its mask).
  void build_pressure_solver() {
    if (use_mg)
      mg.build(pressure_op);
    else
      mic.build(pressure_op);
  }

  void set_solid(const uint8_t* mask) override {
    const std::size_t n = solid.size();
    bool any = false;
    for (std::size_t i = 0; mask && i < n; ++i) any = any || mask[i] != 0;
    if (any && use_fft)
      fail_param("pressure", "\"multigrid\" or \"pcg\" with solid cells (fft has no solids)",
                 "\"fft\"");
    for (std::size_t i = 0; i < n; ++i) solid[i] = mask && mask[i] ? 1 : 0;
    pressure_op.solid = any ? solid.data() : nullptr;
    for (std::size_t i = 0; i < phi.size(); ++i)
      if (solid[i]) phi[i] = T(0);  // not an unknown any more (the warm start reads phi)
    if (!use_fft) build_pressure_solver();
  }

  void rebuild_solids() override {
    solids.build(geo, params);
    noise = CurlNoise(params.turbulence, params.obstacles);
    if (turbulent) noise_slices.reset(geo, noise.ramped());
    psi_time = std::numeric_limits<double>::quiet_NaN();
    set_solid(solids.any_solid ? solids.solid.data() : nullptr);
    // Walls and solids make their own viscous step (ghost mirrors); without them the implicit
    // solves (spectral or CG) stay.
    explicit_viscosity = solids.any_solid || solids.any_no_slip;
    enforce_solids(solids, u);
  }

  Vec3 obstacle_force(int index) const override {
    if (last_dt <= 0) return Vec3::Zero();
    return flagsim::obstacle_force(solids, index, u, phi.data(), last_dt, params.density,
                                   params.viscosity);
  }

  void apply_boundary(const Vec3& wind) {
    if (!geo.periodic) apply_tunnel_boundary(wind, inflow_w.data(), u);
    enforce_solids(solids, u);
  }

  void set_uniform(const Vec3& v) {
    for (int c = 0; c < 3; ++c) std::fill(u.comp[c].begin(), u.comp[c].end(), T(v[c]));
    apply_boundary(Vec3(v.x(), 0, 0));
  }

  void keep_warm_start() override {
    if (!use_fft) phi_start.assign(phi.size(), T(0));  // fft: phi is an output only
  }

  void restore_warm_start() override {
    if (phi_start.empty())
      std::fill(phi.begin(), phi.end(), T(0));
    else
      std::copy(phi_start.begin(), phi_start.end(), phi.begin());
  }

  bool step(double dt, const std::vector<PointImpulses>* impulses,
            const Fluid::WriteGate* gate) override {
    const double t0 = time, t1 = time + dt;
    const FluidParams& p = params;
    if (!phi_start.empty()) std::copy(phi.begin(), phi.end(), phi_start.begin());
    SampleBoundary bc;
    if (!geo.periodic) {
      bc.inflow = p.wind.at(t0);
      bc.shape = inflow_profile;
    }
    // Periodic grids without solids and with a small nu dt / h^2 diffuse u^n explicitly within
    // the advection (kExplicitViscosityBeta): fft projects with 2 transforms instead of 6, the
    // iterative backends skip the diffusion solves, and all of them still agree.
    const double nu_dt = p.viscosity * dt;
    const double beta = nu_dt / (geo.h * geo.h);
    const bool viscous_explicit =
        geo.periodic && !explicit_viscosity && beta > 0 && beta <= kExplicitViscosityBeta;
    // 1. self-advection of u^n (reads its padded copy, writes u)
    {
      ScopedTimer timer(stats.seconds_advect);
      const auto pass = [gate]() {  // u^n is copied; from here on u is written
        if (gate) gate->wait(gate->arg);
      };
      fill_advect_source(u, padded);
      pass();
      advect_from_source(u, dt, maccormack, padded, hat, bc, viscous_explicit ? beta : 0.0);
    }
    // 2. external force
    {
      ScopedTimer timer(stats.seconds_forces);
      apply_fans(fans, t0, dt, u);
      if (turbulent) add_turbulence(t0, t1);
      if (impulses)
        for (const PointImpulses& j : *impulses) add_impulses(j);
    }
    ScopedTimer timer(stats.seconds_project);
    // 3. boundary values at the new time: tunnel faces and solids, or the periodic mean flow
    if (!geo.periodic || solids.any_solid) apply_boundary(p.wind.at(t1));
    const bool drive_mean = geo.periodic && !p.wind.keys.empty();
    const Vec3 mean = drive_mean ? p.wind.at(t1) : Vec3::Zero();
    // 4-5. diffusion (unless explicit, in step 1) and projection
    stats.diffusion_iterations = 0;
    bool finite = false;
    if (use_fft) {
      if (nu_dt > 0 && !viscous_explicit) {
        finite = fft->diffuse_and_project(u, nu_dt, drive_mean ? &mean : nullptr);
      } else {
        if (drive_mean) set_mean_flow(mean, u);
        finite = fft->project(u);
      }
    } else {
      if (nu_dt > 0 && !viscous_explicit) {
        if (explicit_viscosity)
          diffuse_explicit(solids, nu_dt, u, hat);
        else
          diffuse_iterative(nu_dt);
      }
      if (drive_mean) {
        if (solids.any_solid)
          set_air_mean_flow(solids, mean, u);
        else
          set_mean_flow(mean, u);
      }
      if (use_mg)
        project_multigrid();
      else
        project_pcg();
      enforce_solids(solids, u);  // the gradient may not cross a solid face
    }
    last_dt = dt;
    time = t1;
    ++stats.steps;
    return finite;
  }

  // A value is not finite exactly when its exponent bits are all set: an integer test the
  // compiler vectorises, where a floating-point reduction may not be reordered (a max-abs
  // reduction through parallel_max cost 8 % of the paper step).
  bool all_finite() const override {
    using Bits = std::conditional_t<sizeof(T) == 8, std::uint64_t, std::uint32_t>;
    constexpr Bits kExponent = sizeof(T) == 8 ? Bits(0x7ff0000000000000ull) : Bits(0x7f800000u);
    Bits bad = 0;
    for (int c = 0; c < 3; ++c) {
      const auto& a = u.comp[c];
      for (std::size_t i = 0; i < a.size(); ++i) {
        Bits b;
        std::memcpy(&b, &a[i], sizeof b);
        bad |= Bits((b & kExponent) == kExponent);
      }
    }
    return bad == 0;
  }

  // u^n is still held by the step's own copy: the padded source.
  // The pcg warm start phi may hold the failure too: it restarts from zero.
  void undo_step(double t0) override {
    for (int c = 0; c < 3; ++c) padded.u[c].unpad(u.comp[c].data());
    std::fill(phi.begin(), phi.end(), T(0));
    time = t0;
    --stats.steps;
  }

  /// (I - nu dt lap) u_new = u per component, CG with Jacobi (diagonally dominant system).
  void diffuse_iterative(double nu_dt) {
    const double beta = nu_dt / (geo.h * geo.h);
    for (int c = 0; c < 3; ++c) {
      std::copy(u.comp[c].begin(), u.comp[c].end(), hat.comp[c].begin());
      const CgResult r = solve_cg(diffusion_op[c], 1.0, beta, hat.comp[c].data(), u.comp[c].data(),
                                  tol, params.pcg_max_iterations,
                                  static_cast<const MicPreconditioner<T>*>(nullptr), cg);
      stats.diffusion_iterations = std::max(stats.diffusion_iterations, r.iterations);
    }
  }

  /// K phi = -h^2 div u (K = -h^2 lap), warm-started from the previous phi; u -= grad phi.
  void project_pcg() {
    pressure_rhs();
    report(solve_cg(pressure_op, 0.0, 1.0, div.data(), phi.data(), tol, params.pcg_max_iterations,
                    &mic, cg));
    subtract_gradient(phi.data(), u);
  }

  /// The same system by multigrid-preconditioned CG (fluid/multigrid.h).
  void project_multigrid() {
    pressure_rhs();
    report(solve_cg(pressure_op, div.data(), phi.data(), tol, params.pcg_max_iterations, mg, cg));
    subtract_gradient(phi.data(), u);
  }

  /// div <- -h^2 div u: the right-hand side of K phi = -h^2 div u.
  void pressure_rhs() { flagsim::divergence(u, div.data(), 0, -geo.h * geo.h); }

  void report(const CgResult& r) {
    stats.pressure_iterations = r.iterations;
    stats.pressure_residual = r.residual;
    stats.pressure_converged = r.converged;
  }

  void divergence_into(T* out) const { flagsim::divergence(u, out); }

  void* data(int c) override { return u.comp[c].data(); }

  void set_component(int c, const double* values) override {
    const std::size_t n = u.comp[c].size();
    for (std::size_t i = 0; i < n; ++i)
      if (!std::isfinite(values[i]))
        fail_param(std::string("velocity.") + "uvw"[c], "finite everywhere",
                   "a non-finite value at flat index " + std::to_string(i));
    for (std::size_t i = 0; i < n; ++i) u.comp[c][i] = T(values[i]);
  }

  long sample(const double* points, long m, double* out) const override {
    const long outside = sample_velocity(u, points, m, out);
    stats.samples_outside += outside;
    return outside;
  }

  void weight_squares(const double* points, long m, double* out) const override {
    flagsim::sample_weight_squares(u, points, m, out);
  }

  // The divergence between steps, in rows of nz values `stride` apart: div (free between steps:
  // each step's pressure_rhs writes it before reading it) or, fft, the projector's scratch.
  const T* divergence_rows(int& stride) const {
    if (fft) {
      T* rows = fft->scratch(stride);
      flagsim::divergence(u, rows, stride);
      return rows;
    }
    stride = geo.nz;
    divergence_into(div.data());
    return div.data();
  }

  void divergence(double* out) const override {
    int stride = 0;
    const T* rows = divergence_rows(stride);
    const std::size_t nrows = std::size_t(geo.nx) * geo.ny;
    for (std::size_t r = 0; r < nrows; ++r)
      std::copy(rows + r * stride, rows + r * stride + geo.nz, out + r * geo.nz);
  }

  double max_divergence() const override {
    int stride = 0;
    const T* rows = divergence_rows(stride);
    const std::size_t nz = std::size_t(geo.nz);
    return parallel_max(geo.cells().size(), [&](std::size_t i) {
      return std::fabs(double(rows[(i / nz) * stride + i % nz]));
    });
  }
};

template <class T>
TypedSolver<T>& typed(Fluid::Solver& s) {
  return static_cast<TypedSolver<T>&>(s);
}

}  // namespace

Fluid::Fluid(const FluidParams& params, const std::string& prefix) {
  params.validate(prefix);
  params.validate_combination(prefix);
  check_memory("a grid of " + detail::to_text(params.cells()) + " cells", params.memory_bytes(),
               "use a coarser " +
                   (prefix.empty() ? std::string("resolution") : prefix + ".resolution") +
                   " or precision 'float'");
  if (params.precision == Precision::kFloat)
    s_ = std::make_unique<TypedSolver<float>>(params);
  else
    s_ = std::make_unique<TypedSolver<double>>(params);
}

Fluid::~Fluid() = default;
Fluid::Fluid(Fluid&&) noexcept = default;
Fluid& Fluid::operator=(Fluid&&) noexcept = default;

// A step that leaves a non-finite velocity is undone and raises DivergenceError: the air is as
// it was, as Simulation promises for the cloth (a too-small cell_size or a huge dt gets here).
void Fluid::step(double dt, const std::vector<PointImpulses>* impulses, const WriteGate* gate) {
  check_positive("dt", dt);
  if (impulses)
    for (const PointImpulses& j : *impulses)
      if (!(j.points && j.impulses && j.points->rows() == j.impulses->rows()))
        throw InvalidArgument("impulses should give as many impulses as points");
  const double t0 = s_->time;
  s_->step_start = t0;
  if (s_->step(dt, impulses, gate) || s_->all_finite()) return;
  s_->undo_step(t0);
  std::ostringstream s;
  s << "the air diverged at step " << s_->stats.steps << " (t = " << t0
    << " s): a non-finite velocity; the state was restored to the start of that step. Try a "
       "smaller dt or a larger cell_size (h = "
    << s_->geo.h << " m)";
  throw DivergenceError(s.str(), s_->stats.steps, t0, -1, "non-finite");
}

void Fluid::undo_step() {
  s_->undo_step(s_->step_start);
  s_->restore_warm_start();
}

void Fluid::keep_warm_start() { s_->keep_warm_start(); }

double Fluid::time() const { return s_->time; }
const FluidParams& Fluid::params() const { return s_->params; }
const GridGeometry& Fluid::geometry() const { return s_->geo; }
bool Fluid::is_double() const { return s_->params.precision == Precision::kDouble; }
const FluidStats& Fluid::stats() const { return s_->stats; }
Shape3 Fluid::component_shape(int c) const { return s_->geo.face_shape(c); }
void* Fluid::component_data(int c) { return s_->data(c); }
const void* Fluid::component_data(int c) const { return s_->data(c); }

MatX3 Fluid::face_positions(int c) const {
  const Shape3 sh = component_shape(c);
  MatX3 out(Index(sh.size()), 3);
  Index r = 0;
  for (int i = 0; i < sh.n[0]; ++i)
    for (int j = 0; j < sh.n[1]; ++j)
      for (int k = 0; k < sh.n[2]; ++k)
        out.row(r++) = s_->geo.face_position(c, i, j, k).transpose();
  return out;
}

void Fluid::set_component(int c, const double* values) { s_->set_component(c, values); }

void Fluid::add_obstacle(const ObstacleParams& obstacle) {
  obstacle.validate("obstacle");
  FluidParams next = s_->params;
  next.obstacles.push_back(obstacle);
  next.validate("");
  next.validate_combination("");
  s_->params = next;
  s_->rebuild_solids();
}

Vec3 Fluid::obstacle_force(int index) const {
  const int n = int(s_->params.obstacles.size());
  if (index < 0 || index >= n)
    fail_param("index", "an obstacle index in [0, " + std::to_string(n) + ")", index);
  return s_->obstacle_force(index);
}

const std::vector<uint16_t>& Fluid::solid_owner() const { return s_->solids.owner; }

std::vector<std::string> Fluid::warnings() const {
  return s_->solids.warnings(s_->params.obstacles);
}

void Fluid::set_solid_cells(const uint8_t* mask) { s_->set_solid(mask); }

void Fluid::set_uniform(const Vec3& velocity) {
  check_finite_vec("velocity", velocity);
  if (is_double())
    typed<double>(*s_).set_uniform(velocity);
  else
    typed<float>(*s_).set_uniform(velocity);
}

long Fluid::sample(const double* points, long m, double* out) const {
  return s_->sample(points, m, out);
}
void Fluid::sample_weight_squares(const double* points, long m, double* out) const {
  s_->weight_squares(points, m, out);
}
void Fluid::divergence(double* out) const { s_->divergence(out); }
double Fluid::max_divergence() const { return s_->max_divergence(); }

}  // namespace flagsim
