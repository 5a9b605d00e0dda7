#include "fluid/params.h"

#include <cmath>

#include "common/errors.h"
#include "common/memory.h"
#include "fluid/multigrid.h"

namespace flagsim {

namespace {

std::string join(const std::string& prefix, const std::string& field) {
  return prefix.empty() ? field : prefix + "." + field;
}

// Half extents of a box: each in (0, 1e6] m.
void check_half_size(const std::string& name, const Vec3& half_size) {
  for (int d = 0; d < 3; ++d)
    if (!(std::isfinite(half_size[d]) && half_size[d] > 0 && half_size[d] <= kMaxCoordinate))
      fail_param(name, "in (0, 1e6] m in every component", detail::to_text(half_size.transpose()));
}

// A direction: finite and not zero (normalised where it is used).
void check_direction(const std::string& name, const Vec3& v) {
  check_finite_vec(name, v);
  if (!(v.norm() > 0)) fail_param(name, "a non-zero vector", "(0 0 0)");
}

}  // namespace

void ObstacleParams::validate(const std::string& prefix) const { validate_geometry(prefix); }

void FanParams::validate(const std::string& prefix) const {
  check_position(join(prefix, "center"), center);
  check_half_size(join(prefix, "half_size"), half_size);
  check_length(join(prefix, "radius"), radius);
  check_direction(join(prefix, "direction"), direction);
  check_finite(join(prefix, "force_density"), force_density);
  check_nonnegative(join(prefix, "max_speed"), max_speed);
  strength.validate(join(prefix, "strength"));
}

void FluidParams::validate(const std::string& prefix) const {
  const std::string res = join(prefix, "resolution");
  long long cells = 1;
  for (int d = 0; d < 3; ++d) {
    if (resolution[d] < 1 || resolution[d] > 4096)
      fail_param(res, "3 cell counts in [1, 4096]",
                 std::to_string(resolution[0]) + " x " + std::to_string(resolution[1]) + " x " +
                     std::to_string(resolution[2]));
    cells *= resolution[d];
  }
  if (cells > (1LL << 28)) fail_param(res, "at most 2^28 cells in all", cells);
  // Below a micrometre h^3 and the pressure scale underflow long before any flag needs it.
  check_range(join(prefix, "cell_size"), cell_size, kMinCellSize, kMaxCellSize);
  check_position(join(prefix, "origin"), origin);
  check_nonnegative(join(prefix, "viscosity"), viscosity);
  check_positive(join(prefix, "density"), density);
  if (!(std::isfinite(pcg_tolerance) && pcg_tolerance > 0 && pcg_tolerance < 1))
    fail_param(join(prefix, "pcg_tolerance"), "in (0, 1)", pcg_tolerance);
  if (pcg_max_iterations < 1)
    fail_param(join(prefix, "pcg_max_iterations"), ">= 1", pcg_max_iterations);
  wind.validate(join(prefix, "wind"));
  for (size_t i = 0; i < fans.size(); ++i)
    fans[i].validate(join(prefix, "fans[" + std::to_string(i) + "]"));
  if (obstacles.size() > 65535)
    fail_param(join(prefix, "obstacles"), "at most 65535 obstacles", obstacles.size());
  for (size_t i = 0; i < obstacles.size(); ++i) {
    obstacles[i].validate(join(prefix, "obstacles[" + std::to_string(i) + "]"));
    obstacles[i].validate_mesh(join(prefix, "obstacles[" + std::to_string(i) + "]"));
  }
  turbulence.validate(join(prefix, "turbulence"));
}

bool TurbulenceParams::enabled() const {
  for (const auto& k : intensity.keys)
    if (k.second != 0) return true;
  return false;
}

void TurbulenceParams::validate(const std::string& p) const {
  intensity.validate(join(p, "intensity"));
  length_scale.validate(join(p, "length_scale"));
  evolution.validate(join(p, "evolution"));
  for (size_t i = 0; i < intensity.keys.size(); ++i)
    check_nonnegative(join(p, "intensity") + "[" + std::to_string(i) + "].value",
                      intensity.keys[i].second);
  for (size_t i = 0; i < length_scale.keys.size(); ++i)
    check_length(join(p, "length_scale") + "[" + std::to_string(i) + "].value",
                 length_scale.keys[i].second);
  for (size_t i = 0; i < evolution.keys.size(); ++i)
    check_nonnegative(join(p, "evolution") + "[" + std::to_string(i) + "].value",
                      evolution.keys[i].second);
  check_length(join(p, "ramp_distance"), ramp_distance);
}

double FluidParams::memory_bytes() const {
  const bool masks = !obstacles.empty() || wall_y_min == Slip::kNoSlip ||
                     wall_y_max == Slip::kNoSlip || wall_z_min == Slip::kNoSlip ||
                     wall_z_max == Slip::kNoSlip;
  const double n0 = resolution[0], n1 = resolution[1], n2 = resolution[2], n = cells();
  const bool periodic = boundary == Boundary::kPeriodic, fft = pressure == Pressure::kFft;
  const bool maccormack = advection == Advection::kMacCormack;
  // The grid-sized arrays of fluid.cpp's TypedSolver, in values of the grid's precision (the
  // table in docs/design.md "Memory"; tests/cpp/fluid/test_fluid.cpp counts them):
  // u; div, phi (pcg, multigrid); the ghost-padded u^n and the MacCormack predictor's (a tunnel's
  // components in a common box of (n + 1)^3 nodes); hat (MacCormack, tunnel, pcg / multigrid); the
  // CG vectors (pcg, multigrid); fft: 3 spectra.
  constexpr double G = 2 * 3;  // PaddedComponent::kGhost on either side
  const double m = periodic ? 0.0 : 1.0;
  const double padded = 3 * (n0 + m + G) * (n1 + m + G) * (n2 + m + G);
  const double faces = 3 * n + (periodic ? 0.0 : n1 * n2 + n0 * n2 + n0 * n1);
  double values = faces + (fft ? 0 : 2) * n;
  values += padded * (maccormack ? 2 : 1);
  if (maccormack || !periodic || !fft) values += faces;
  if (!fft) values += 4 * (faces / 3 + n1 * n2 + n0 * n2);  // CgScratch: the largest component
  if (!fft) values += n;                                    // phi_start (undo_step's warm start)
  if (fft) values += 3 * n0 * n1 * (std::floor(n2 / 2) + 1) * 2;
  // The solid map (csrc/fluid/solids.h): 3 face kinds, an owner (2 bytes) and a mask per cell;
  // the pressure solve's mask (1 byte). Turbulence: psi on the edges now and at the last step,
  // and in double the two noise slices it blends and, with obstacles, the ramp (EdgeNoise). The
  // multigrid hierarchy (csrc/fluid/multigrid.h) and its own mask.
  const double edges =
      periodic ? 3 * n
               : n0 * (n1 + 1) * (n2 + 1) + (n0 + 1) * n1 * (n2 + 1) + (n0 + 1) * (n1 + 1) * n2;
  const bool turbulent = turbulence.enabled();
  values += turbulent ? 2 * edges : 0.0;
  const double noise_doubles = turbulent ? (obstacles.empty() ? 2 : 3) * edges : 0.0;
  const double multigrid = pressure == Pressure::kMultigrid ? kMultigridBytesPerCell + 1.0 : 0.0;
  const double bytes =
      values * double(precision == Precision::kFloat ? sizeof(float) : sizeof(double)) +
      noise_doubles * double(sizeof(double));
  // kMemorySlack: FFTW's plans and what the measured peak adds beyond the arrays (docs/design.md).
  return kMemorySlack * bytes + n * (1.0 + (masks ? 6.0 : 0.0) + multigrid);
}

void FluidParams::validate_combination(const std::string& prefix) const {
  if (pressure == Pressure::kFft && boundary != Boundary::kPeriodic)
    fail_param(join(prefix, "pressure"),
               "\"pcg\" or \"multigrid\" with boundary \"" + std::string(name_of(boundary)) +
                   "\" (fft needs a periodic domain)",
               "\"fft\"");
  if (pressure == Pressure::kFft && !obstacles.empty())
    fail_param(join(prefix, "pressure"),
               "\"pcg\" or \"multigrid\" with obstacles (the fft solve cannot see solids)",
               "\"fft\"");
  if (boundary == Boundary::kPeriodic) {
    // A periodic grid has no walls and no inflow face: a condition set there would be ignored.
    static const char* kWalls[4] = {"wall_y_min", "wall_y_max", "wall_z_min", "wall_z_max"};
    for (int w = 0; w < 4; ++w)
      if (wall(1 + w / 2, w % 2) != Slip::kFreeSlip)
        fail_param(join(prefix, kWalls[w]),
                   "\"free_slip\" with boundary \"periodic\" (a periodic grid has no walls)",
                   "\"no_slip\"");
    if (inflow_profile != InflowProfile::kUniform)
      fail_param(join(prefix, "inflow_profile"),
                 "\"uniform\" with boundary \"periodic\" (a periodic grid has no inflow face)",
                 "\"parabolic\"");
  } else if (inflow_profile == InflowProfile::kParabolic &&
             !(wall(1, 0) == Slip::kNoSlip && wall(1, 1) == Slip::kNoSlip) &&
             !(wall(2, 0) == Slip::kNoSlip && wall(2, 1) == Slip::kNoSlip)) {
    fail_param(join(prefix, "inflow_profile"),
               "\"uniform\" unless both y walls or both z walls are \"no_slip\" (the parabola "
               "runs between two no-slip walls)",
               "\"parabolic\"");
  }
  if (pressure == Pressure::kFft) require_fftw(join(prefix, "pressure"));
}

void require_fftw(const std::string& name, bool built_with_fftw) {
  if (!built_with_fftw)
    throw MissingFeature(name +
                         " should be \"pcg\" or \"multigrid\": this flagsim was built without FFTW "
                         "(FLAGSIM_WITH_FFTW=OFF), got \"fft\"");
}

}  // namespace flagsim
