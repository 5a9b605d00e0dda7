// Parameters of the air solver (Stable Fluids on a MAC grid). Plain struct, validated by
// validate().
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "common/enums.h"
#include "common/keyframes.h"
#include "common/shapes.h"
#include "common/types.h"

namespace flagsim {

enum class FanShape { kBox, kSphere };
template <>
struct EnumNames<FanShape> {
  static constexpr std::array<const char*, 2> names{"box", "sphere"};
};

enum class Boundary { kPeriodic, kTunnel };
template <>
struct EnumNames<Boundary> {
  static constexpr std::array<const char*, 2> names{"periodic", "tunnel"};
};

enum class Advection { kSemiLagrangian, kMacCormack };
template <>
struct EnumNames<Advection> {
  static constexpr std::array<const char*, 2> names{"semi_lagrangian", "maccormack"};
};

/// FFT (periodic only, FFTW, no solids), MIC(0)-preconditioned CG (the reference), or CG
/// preconditioned by a geometric multigrid V-cycle (fluid/multigrid.h): periodic or tunnel, with
/// or without solids.
enum class Pressure { kFft, kPcg, kMultigrid };
template <>
struct EnumNames<Pressure> {
  static constexpr std::array<const char*, 3> names{"fft", "pcg", "multigrid"};
};

enum class Precision { kDouble, kFloat };
template <>
struct EnumNames<Precision> {
  static constexpr std::array<const char*, 2> names{"double", "float"};
};

/// The condition a solid (an obstacle or a tunnel wall) puts on the air beside it: both hold the
/// normal velocity at 0; free-slip leaves the tangential velocity free, no-slip holds it at 0
/// (the wall halfway between the last fluid node and its mirror, so the viscous stress is
/// second-order).
enum class Slip { kFreeSlip, kNoSlip };
template <>
struct EnumNames<Slip> {
  static constexpr std::array<const char*, 2> names{"free_slip", "no_slip"};
};

/// Velocity across the tunnel's inflow face (x-min): uniform, or parabolic across each axis
/// whose two walls are no-slip (the laminar channel profile), with the same mean, so the flux is
/// the wind's either way.
enum class InflowProfile { kUniform, kParabolic };
template <>
struct EnumNames<InflowProfile> {
  static constexpr std::array<const char*, 2> names{"uniform", "parabolic"};
};

/// A static solid in the air: a box, a sphere, a capped cylinder, a capsule or a closed triangle
/// mesh (common/shapes.h). The cells whose centres lie inside it are solid (csrc/fluid/solids.h).
struct ObstacleParams : SolidGeometry {
  Slip slip = Slip::kNoSlip;
  /// Throws InvalidArgument naming "<prefix>.<field>" (e.g. "air.obstacles[0].radius").
  void validate(const std::string& prefix) const;
};

/// A region that pushes the air: force density f (N/m^3) along `direction` inside a box or sphere.
struct FanParams {
  FanShape shape = FanShape::kBox;
  Vec3 center{0, 0, 0};              ///< m
  Vec3 half_size{0.25, 0.25, 0.25};  ///< m, box half extents (shape "box")
  double radius = 0.25;              ///< m (shape "sphere")
  Vec3 direction{1, 0, 0};           ///< normalised on use
  double force_density = 20.0;       ///< N/m^3
  /// m/s, fan curve: along each axis the force fades linearly to 0 as the air reaches
  /// max_speed * direction (a fan pushes no faster than it blows); 0 = constant force.
  double max_speed = 0.0;
  ScalarSchedule strength;  ///< (time s, factor) keyframes; empty = always 1
  /// Throws InvalidArgument naming "<prefix>.<field>" (e.g. "air.fans[0].radius").
  void validate(const std::string& prefix) const;
};

/// Curl-noise turbulence (Bridson, Hourihan, Nordenstam 2007, "Curl-Noise for Procedural Fluid
/// Flow"): a vector potential psi from three gradient-noise channels, u = curl psi, so the
/// velocity is divergence-free by construction; psi is ramped to 0 near solids (the pole,
/// obstacles) so the normal velocity vanishes there. Each quantity is a keyframed schedule
/// ((time s, value) pairs, linear between keys); empty takes the default in brackets.
/// csrc/fluid/turbulence.h.
struct TurbulenceParams {
  ScalarSchedule intensity;     ///< m/s, velocity scale of the noise [0: off]
  ScalarSchedule length_scale;  ///< m, noise lattice spacing, about the eddies' size [0.3]
  ScalarSchedule evolution;     ///< 1/s, noise slices per second: how fast eddies change [0.5]
  double ramp_distance = 0.1;   ///< m, d_0 of Bridson's ramp: full noise beyond it from a solid
  uint32_t seed = 0;
  static constexpr double kDefaultLength = 0.3, kDefaultEvolution = 0.5;
  /// True when some key of intensity is non-zero.
  bool enabled() const;
  void validate(const std::string& prefix) const;
};

/// The cell sizes FluidParams accepts, m: below a micrometre h^3 and the pressure scale head for
/// underflow; above 10 km a grid no longer describes wind around a flag.
constexpr double kMinCellSize = 1e-6, kMaxCellSize = 1e4;

/// Stable Fluids (Stam 1999) on a staggered MAC grid; see csrc/fluid/fluid.h for the layout.
/// Periodic boundary: the mean flow (k = 0 mode) follows `wind` when it has keys (gusts are its
/// keyframes) and is left free otherwise. Tunnel: inflow `wind` through the x-min face (shaped by
/// inflow_profile), zero-pressure outflow at x-max, a wall on each y and z face (free-slip or
/// no-slip, one condition per face). Obstacles: static solids in either kind of grid.
struct FluidParams {
  std::array<int, 3> resolution{16, 16, 16};  ///< cells nx, ny, nz
  double cell_size = 0.125;                   ///< m
  Vec3 origin{-0.5, -1.0, -1.0};              ///< m, min corner of the domain
  Boundary boundary = Boundary::kPeriodic;    ///< tunnel: inflow through x-min, outflow x-max
  Advection advection = Advection::kSemiLagrangian;
#ifdef FLAGSIM_HAVE_FFTW
  Pressure pressure = Pressure::kFft;  ///< fft needs a periodic boundary
#else
  Pressure pressure = Pressure::kPcg;  ///< fft is not in this build (no FFTW)
#endif
  Precision precision = Precision::kDouble;
  double viscosity = 1.5e-5;     ///< m^2/s, kinematic; 0 = no diffusion stage
  double density = 1.2;          ///< kg/m^3
  double pcg_tolerance = 1e-8;   ///< relative residual (pcg and multigrid)
  int pcg_max_iterations = 500;  ///< per solve (pressure and each diffusion solve)
  WindSchedule wind;             ///< periodic: mean flow (k = 0 mode); tunnel: inflow velocity
  std::vector<FanParams> fans;
  std::vector<ObstacleParams> obstacles;
  /// Curl noise added to the air: the change of its velocity over a step is a forcing (after the
  /// fans), so without advection the air is the mean flow plus the noise; advection carries it.
  TurbulenceParams turbulence;
  /// Tunnel walls, one condition per face: y-min, y-max, z-min, z-max.
  Slip wall_y_min = Slip::kFreeSlip, wall_y_max = Slip::kFreeSlip;
  Slip wall_z_min = Slip::kFreeSlip, wall_z_max = Slip::kFreeSlip;
  InflowProfile inflow_profile = InflowProfile::kUniform;
  /// The wall condition on side `hi` (0 = min, 1 = max) of axis d (1 = y, 2 = z).
  Slip wall(int d, int hi) const {
    return d == 1 ? (hi ? wall_y_max : wall_y_min) : (hi ? wall_z_max : wall_z_min);
  }
  double cells() const { return double(resolution[0]) * resolution[1] * resolution[2]; }
  /// Bytes a Fluid of these parameters allocates, about (common/memory.h, measured).
  double memory_bytes() const;
  /// Each field on its own: throws InvalidArgument naming "<prefix>.<field>" ("resolution" when
  /// prefix is empty). Field setters run this, so fields can be set in any order.
  void validate(const std::string& prefix) const;
  /// The fields together: pressure "fft" needs boundary "periodic", and FFTW in this build
  /// (MissingFeature otherwise). Run by Scene::validate and by Fluid's constructor.
  void validate_combination(const std::string& prefix) const;
};

#ifdef FLAGSIM_HAVE_FFTW
inline constexpr bool kBuiltWithFftw = true;
#else
inline constexpr bool kBuiltWithFftw = false;
#endif

/// Pressure "fft" asked for as `name`: MissingFeature naming it unless built_with_fftw (a
/// parameter, so that every build tests the message).
void require_fftw(const std::string& name, bool built_with_fftw = kBuiltWithFftw);

}  // namespace flagsim
