#include "fluid/fluid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>

#include "../support/alloc_counter.h"
#include "common/errors.h"
#include "common/memory.h"
#include "common/parallel.h"
#include "common/simd.h"
#include "fluid/advect.h"
#include "fluid/pressure.h"

namespace flagsim {

namespace {

FluidParams small(const std::string& pressure, const std::string& advection) {
  FluidParams p;
  p.resolution = {12, 10, 8};
  p.cell_size = 0.1;
  p.origin = Vec3::Zero();
  p.pressure = parse_enum<Pressure>("pressure", pressure);
  p.advection = parse_enum<Advection>("advection", advection);
  p.viscosity = 1e-3;
  return p;
}

void randomise(Fluid& f, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int c = 0; c < 3; ++c) {
    std::vector<double> v(f.component_shape(c).size());
    for (double& x : v) x = n(rng);
    f.set_component(c, v.data());
  }
}

std::size_t f_bytes(const Fluid& f) { return f.is_double() ? sizeof(double) : sizeof(float); }

}  // namespace

class FluidBackends : public ::testing::TestWithParam<std::tuple<std::string, std::string>> {};

TEST_P(FluidBackends, ProjectionLeavesNoDivergence) {
  const auto [pressure, advection] = GetParam();
#ifndef FLAGSIM_HAVE_FFTW
  if (pressure == "fft") GTEST_SKIP() << "built without FFTW";
#endif
  FluidParams p = small(pressure, advection);
  Fluid f(p);
  randomise(f, 7);
  const double before = f.max_divergence();
  ASSERT_GT(before, 10.0);
  f.step(0.01);
  if (pressure == "fft")
    EXPECT_LT(f.max_divergence(), 1e-10);
  else
    EXPECT_LE(f.max_divergence(), p.pcg_tolerance * before * 1.01);
}

// Fluid::WriteGate: called once a step, while the grid still holds u^n (the Simulation's pipeline
// samples it until then), and a held step gives the bits of one that is not.
TEST_P(FluidBackends, WriteGateHoldsTheStepBeforeItWritesTheGrid) {
  const auto [pressure, advection] = GetParam();
#ifndef FLAGSIM_HAVE_FFTW
  if (pressure == "fft") GTEST_SKIP() << "built without FFTW";
#endif
  Fluid held(small(pressure, advection)), plain(small(pressure, advection));
  randomise(held, 11);
  randomise(plain, 11);
  struct Seen {
    const Fluid* f;
    std::vector<std::vector<char>> start;
    int calls = 0;
    bool unchanged = true;
  } seen{&held, {}};
  for (int c = 0; c < 3; ++c) {
    const auto* b = static_cast<const char*>(held.component_data(c));
    seen.start.emplace_back(b, b + held.component_shape(c).size() * f_bytes(held));
  }
  const Fluid::WriteGate gate{[](const void* a) {
                                auto& s = *static_cast<Seen*>(const_cast<void*>(a));
                                ++s.calls;
                                for (int c = 0; c < 3; ++c)
                                  s.unchanged =
                                      s.unchanged &&
                                      std::memcmp(s.f->component_data(c), s.start[size_t(c)].data(),
                                                  s.start[size_t(c)].size()) == 0;
                              },
                              &seen};
  held.step(0.01, nullptr, &gate);
  plain.step(0.01);
  EXPECT_EQ(seen.calls, 1);
  EXPECT_TRUE(seen.unchanged);
  for (int c = 0; c < 3; ++c)
    EXPECT_EQ(std::memcmp(held.component_data(c), plain.component_data(c),
                          held.component_shape(c).size() * f_bytes(held)),
              0);
}

// The readouts give the MAC divergence of the current field whatever holds it (div for pcg and
// multigrid, the projector's scratch for fft): the same bits as divergence() on a copy.
TEST_P(FluidBackends, DivergenceReadoutsAreTheFieldsDivergence) {
  const auto [pressure, advection] = GetParam();
#ifndef FLAGSIM_HAVE_FFTW
  if (pressure == "fft") GTEST_SKIP() << "built without FFTW";
#endif
  Fluid f(small(pressure, advection));
  randomise(f, 3);
  f.step(0.01);
  randomise(f, 4);  // a field with a divergence to read
  const GridGeometry& g = f.geometry();
  MacGrid<double> u(g);
  for (int c = 0; c < 3; ++c) {
    const double* q = static_cast<const double*>(f.component_data(c));
    std::copy(q, q + u.comp[c].size(), u.comp[c].begin());
  }
  std::vector<double> expected(g.cells().size()), got(g.cells().size());
  divergence(u, expected.data());
  f.divergence(got.data());
  double largest = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    ASSERT_EQ(got[i], expected[i]) << "cell " << i;
    largest = std::max(largest, std::fabs(expected[i]));
  }
  EXPECT_GT(largest, 1.0);
  EXPECT_EQ(f.max_divergence(), largest);
}

TEST_P(FluidBackends, StepAllocatesNothing) {
  const auto [pressure, advection] = GetParam();
#ifndef FLAGSIM_HAVE_FFTW
  if (pressure == "fft") GTEST_SKIP() << "built without FFTW";
#endif
  FluidParams p = small(pressure, advection);
  p.wind = WindSchedule(Vec3(2, 0, 0));
  p.fans.emplace_back();
  p.fans[0].center = Vec3(0.6, 0.5, 0.4);
  Fluid f(p);
  f.step(0.01);  // first step: thread pools and lazy runtime state
  MatX3 points = MatX3::Constant(88, 3, 0.4), out(88, 3);
  testing::CountAllocations count;
  for (int i = 0; i < 100; ++i) {
    f.step(0.01);
    f.sample(points, out);
  }
  EXPECT_EQ(count.count(), 0);
}

INSTANTIATE_TEST_SUITE_P(Fluid, FluidBackends,
                         ::testing::Combine(::testing::Values("fft", "pcg", "multigrid"),
                                            ::testing::Values("semi_lagrangian", "maccormack")));

// A whole periodic step (the padded copy's fill, the advection fast path with the explicit
// viscosity, the mean flow's shift, the divergence, the spectral solve and the gradient) gives the
// same bits on 32-byte AVX vectors as on 16-byte ones, in double and in float. Rows of 8 cells
// (7 faces of w after the wrapped one) and 5 complex modes leave scalar tails at both widths.
TEST(Fluid, PeriodicStepIsTheSameAtEveryVectorWidth) {
#ifndef FLAGSIM_HAVE_FFTW
  GTEST_SKIP() << "built without FFTW";
#endif
  if (vector_bytes() < 32) GTEST_SKIP() << "this CPU has one vector width only (no AVX)";
  for (const char* precision : {"double", "float"}) {
    FluidParams p = small("fft", "semi_lagrangian");
    p.precision = parse_enum<Precision>("precision", precision);
    p.wind = WindSchedule(Vec3(0.7, -0.2, 0.1));  // a driven mean: set_mean_flow runs too
    auto run = [&](int cap) {
      vector_bytes(cap);
      auto f = std::make_unique<Fluid>(p);
      randomise(*f, 3);
      f->step(0.02);
      f->step(0.02);
      vector_bytes(0);
      return f;
    };
    const auto wide = run(0), narrow = run(16);
    const std::size_t bytes = f_bytes(*wide);
    for (int c = 0; c < 3; ++c)
      ASSERT_EQ(std::memcmp(wide->component_data(c), narrow->component_data(c),
                            wide->component_shape(c).size() * bytes),
                0)
          << precision << " component " << c;
  }
}

class TunnelBackends : public ::testing::TestWithParam<std::string> {};

TEST_P(TunnelBackends, StepAllocatesNothingAndBalancesFlux) {
  FluidParams p;
  p.resolution = {16, 8, 8};
  p.cell_size = 0.125;
  p.origin = Vec3::Zero();
  p.boundary = Boundary::kTunnel;
  p.pressure = parse_enum<Pressure>("pressure", GetParam());
  p.pcg_tolerance = 1e-10;
  p.wind = WindSchedule(Vec3(2, 0, 0));
  p.fans.emplace_back();
  p.fans[0].center = Vec3(0.8, 0.5, 0.5);
  p.fans[0].force_density = 60;
  Fluid f(p);
  f.step(0.01);
  {
    testing::CountAllocations count;
    for (int i = 0; i < 20; ++i) f.step(0.01);
    EXPECT_EQ(count.count(), 0);
  }
  const Shape3 su = f.component_shape(0);
  const double* u = static_cast<const double*>(static_cast<const Fluid&>(f).component_data(0));
  double in = 0, out = 0;
  for (int j = 0; j < su.n[1]; ++j)
    for (int k = 0; k < su.n[2]; ++k) {
      in += u[su.index(0, j, k)];
      out += u[su.index(su.n[0] - 1, j, k)];
    }
  EXPECT_DOUBLE_EQ(in, 2.0 * 64);
  EXPECT_NEAR(out, in, 1e-8 * in);
  EXPECT_TRUE(f.stats().pressure_converged);
  EXPECT_GT(f.stats().pressure_iterations, 0);
}

INSTANTIATE_TEST_SUITE_P(Fluid, TunnelBackends, ::testing::Values("pcg", "multigrid"));

// Solid cells (the pressure solve's mask alone: Fluid::set_solid_cells) rebuild the multigrid
// hierarchy once; steps then allocate nothing, and multigrid and pcg agree on the projection.
TEST(Fluid, SolidCellsStepAllocatesNothingAndBackendsAgree) {
  // One thread: pcg's hundreds of small dot products would each wake a team.
  const int threads = num_threads();
  set_num_threads(1);
  for (Boundary boundary : {Boundary::kPeriodic, Boundary::kTunnel}) {
    FluidParams p;
    p.resolution = {24, 16, 16};
    p.cell_size = 0.1;
    p.origin = Vec3::Zero();
    p.boundary = boundary;
    p.pcg_tolerance = 1e-10;
    p.viscosity = 0;
    p.wind = WindSchedule(Vec3(2, 0, 0));
    std::vector<uint8_t> mask(std::size_t(24) * 16 * 16, 0);
    for (int i = 6; i < 9; ++i)
      for (int j = 4; j < 12; ++j)
        for (int k = 4; k < 12; ++k) mask[(std::size_t(i) * 16 + j) * 16 + k] = 1;
    std::unique_ptr<Fluid> f[2];
    const char* names[2] = {"multigrid", "pcg"};
    for (int b = 0; b < 2; ++b) {
      p.pressure = parse_enum<Pressure>("pressure", names[b]);
      f[b] = std::make_unique<Fluid>(p);
      f[b]->set_solid_cells(mask.data());
      randomise(*f[b], 5);
      f[b]->step(0.01);
    }
    {
      testing::CountAllocations count;
      for (int i = 0; i < 3; ++i) f[0]->step(0.01);
      EXPECT_EQ(count.count(), 0);
    }
    for (int i = 0; i < 3; ++i) f[1]->step(0.01);
    EXPECT_TRUE(f[0]->stats().pressure_converged);
    EXPECT_LE(f[0]->stats().pressure_iterations, 15);
    for (int c = 0; c < 3; ++c) {
      const double* a =
          static_cast<const double*>(static_cast<const Fluid&>(*f[0]).component_data(c));
      const double* b =
          static_cast<const double*>(static_cast<const Fluid&>(*f[1]).component_data(c));
      double diff = 0, top = 0;
      for (std::size_t i = 0; i < f[0]->component_shape(c).size(); ++i) {
        diff = std::max(diff, std::fabs(a[i] - b[i]));
        top = std::max(top, std::fabs(b[i]));
      }
      EXPECT_LT(diff, 1e-6 * top) << "component " << c;
    }
  }
  set_num_threads(threads);
}

TEST(Fluid, FftRejectsSolidCells) {
#ifndef FLAGSIM_HAVE_FFTW
  GTEST_SKIP() << "built without FFTW";
#endif
  Fluid f(small("fft", "semi_lagrangian"));
  std::vector<uint8_t> mask(f.component_shape(0).size(), 0);
  f.set_solid_cells(mask.data());  // no solid cell: fine
  mask[7] = 1;
  EXPECT_THROW(f.set_solid_cells(mask.data()), InvalidArgument);
}

TEST(Fluid, FloatPrecisionStoresFloats) {
  FluidParams p = small("pcg", "semi_lagrangian");
  p.precision = Precision::kFloat;
  Fluid f(p);
  EXPECT_FALSE(f.is_double());
  randomise(f, 3);
  f.step(0.01);
  EXPECT_LT(f.max_divergence(), 1e-3);
}

TEST(Fluid, RejectsBadStep) {
  Fluid f(small("pcg", "semi_lagrangian"));
  EXPECT_THROW(f.step(0.0), InvalidArgument);
  EXPECT_THROW(f.step(NAN), InvalidArgument);
  EXPECT_EQ(f.time(), 0.0);
}

// The FFT diffusion shows its result finite from its spectral pass (the projection alone from its
// gradient pass), so that Fluid::step skips the full-grid check: true for an ordinary field, and
// false (the caller then checks the grid) when a value is NaN, when one is finite but large enough
// that the transforms could overflow, and when the mean flow set is.
template <class T>
void expect_finite_certificate() {
  GridGeometry g;
  g.nx = 8;
  g.ny = 6;
  g.nz = 10;
  g.h = 0.1;
  FftProjector<T> fft(g);
  MacGrid<T> u(g);
  std::mt19937 rng(5);
  std::normal_distribution<double> normal(0.0, 1.0);
  auto fill = [&] {
    for (auto& c : u.comp)
      for (T& x : c) x = T(normal(rng));
  };
  const double big = std::sqrt(double(std::numeric_limits<T>::max())) * 480;  // finite in T
  const Vec3 mean(0.5, 0, 0), big_mean(big, 0, 0);
  fill();
  EXPECT_TRUE(fft.diffuse_and_project(u, 1e-3, nullptr));
  fill();
  EXPECT_TRUE(fft.diffuse_and_project(u, 1e-3, &mean));
  for (const auto& c : u.comp)
    for (const T x : c) ASSERT_TRUE(std::isfinite(x));
  fill();
  u.comp[1][7] = std::numeric_limits<T>::quiet_NaN();
  EXPECT_FALSE(fft.diffuse_and_project(u, 1e-3, nullptr));
  fill();
  u.comp[2][3] = T(big);
  EXPECT_FALSE(fft.diffuse_and_project(u, 1e-3, nullptr));
  fill();
  EXPECT_FALSE(fft.diffuse_and_project(u, 1e-3, &big_mean));
  // The projection alone checks its new values as it subtracts the gradient: true for an
  // ordinary field, false when one is NaN or infinite.
  fill();
  EXPECT_TRUE(fft.project(u));
  for (const auto& c : u.comp)
    for (const T x : c) ASSERT_TRUE(std::isfinite(x));
  for (int c = 0; c < 3; ++c) {
    fill();
    u.comp[c][11] = std::numeric_limits<T>::quiet_NaN();
    EXPECT_FALSE(fft.project(u)) << "component " << c;
    fill();
    u.comp[c][4] = std::numeric_limits<T>::infinity();
    EXPECT_FALSE(fft.project(u)) << "component " << c;
  }
}

TEST(FftProjector, DiffusionShowsItsResultFinite) {
#ifndef FLAGSIM_HAVE_FFTW
  GTEST_SKIP() << "built without FFTW";
#endif
  expect_finite_certificate<double>();
  expect_finite_certificate<float>();
}

}  // namespace flagsim

namespace flagsim {
namespace {

// The grid-sized arrays a Fluid holds after two steps, in grids of the cell count (values of the
// grid's precision per cell), counted by the aligned allocator (common/memory.h). A buffer added
// to the air without its row in docs/design.md "Memory" fails GridArrays.*.
struct Counted {
  double arrays;  ///< bytes / (cells * sizeof(value))
  double bytes;
  double estimate;  ///< FluidParams::memory_bytes
};
Counted count_arrays(const FluidParams& p) {
  const std::int64_t before = aligned_bytes_live();
  double bytes = 0;
  {
    Fluid f(p);
    randomise(f, 5);
    f.step(0.01);
    f.step(0.01);
    bytes = double(aligned_bytes_live() - before);
  }
  EXPECT_EQ(aligned_bytes_live(), before);  // all given back
  const double value = p.precision == Precision::kFloat ? sizeof(float) : sizeof(double);
  return {bytes / (p.cells() * value), bytes, p.memory_bytes()};
}

/// A padded copy of one 32^3 component (PaddedComponent: kGhost layers each side), in grids.
const double padded = std::pow((32.0 + 2 * PaddedComponent<double>::kGhost) / 32.0, 3);

FluidParams cube(int n, const std::string& pressure, const std::string& advection) {
  FluidParams p = small(pressure, advection);
  p.resolution = {n, n, n};
  return p;
}

}  // namespace

TEST(GridArrays, PeriodicSemiLagrangianFftHoldsTenGrids) {
  // u (3) + u^n with 3 ghost layers (3 (38/32)^3 = 5.02) + 3 half spectra (3 * 2 * 17/32 =
  // 3.19) + the solid mask (1 byte a cell): 10.3 grids at 32^3 (9.6 at 128^3, where the ghosts
  // weigh less). Before issue 28: 23.6 (MacCormack's scratch, the CG vectors, two divergences,
  // an FFT real buffer and phi were allocated whatever the scene used).
  for (const Precision precision : {Precision::kDouble, Precision::kFloat}) {
    FluidParams p = cube(32, "fft", "semi_lagrangian");
    p.precision = precision;
    const double value = precision == Precision::kFloat ? 4.0 : 8.0;
    const double expected = 3 + 3 * padded + 3 * 2 * 17.0 / 32 + 1 / value;
    const Counted c = count_arrays(p);
    EXPECT_NEAR(c.arrays, expected, 1e-3);
    EXPECT_GE(c.estimate, c.bytes);  // the up-front memory check covers what is allocated
    EXPECT_LE(c.estimate, 1.5 * c.bytes);
  }
}

TEST(GridArrays, MacCormackAddsItsPredictorAndItsPaddedCopy) {
  const Counted sl = count_arrays(cube(32, "fft", "semi_lagrangian"));
  const Counted mc = count_arrays(cube(32, "fft", "maccormack"));
  EXPECT_NEAR(mc.arrays - sl.arrays, 3 + 3 * padded, 1e-3);
  EXPECT_GE(mc.estimate, mc.bytes);
  EXPECT_LE(mc.estimate, 1.5 * mc.bytes);
}

TEST(GridArrays, TunnelAdvectsFromPaddedCopiesInACommonBox) {
  // A tunnel's u^n is padded with its three components in one box of 33^3 nodes plus the ghosts
  // (advect_padded); MacCormack adds the predictor's padded copy (the predictor itself, hat, is
  // there already: the multigrid diffusion's copy).
  const double box = std::pow((33.0 + 2 * PaddedComponent<double>::kGhost) / 32.0, 3);
  FluidParams p = cube(32, "multigrid", "semi_lagrangian");
  p.boundary = Boundary::kTunnel;
  const Counted sl = count_arrays(p);
  p.advection = Advection::kMacCormack;
  const Counted mc = count_arrays(p);
  EXPECT_NEAR(mc.arrays - sl.arrays, 3 * box, 1e-3);
  for (const Counted& c : {sl, mc}) {
    EXPECT_GE(c.estimate, c.bytes);
    EXPECT_LE(c.estimate, 2.0 * c.bytes);
  }
}

TEST(GridArrays, IterativeBackendsAreCoveredByTheEstimate) {
  for (const char* pressure : {"pcg", "multigrid"})
    for (const char* boundary : {"periodic", "tunnel"}) {
      FluidParams p = cube(16, pressure, "semi_lagrangian");
      p.boundary = parse_enum<Boundary>("boundary", boundary);
      const Counted c = count_arrays(p);
      EXPECT_GE(c.estimate, c.bytes) << pressure << " " << boundary;
      EXPECT_LE(c.estimate, 2.0 * c.bytes) << pressure << " " << boundary;
    }
}

TEST(GridArrays, TurbulenceKeepsPsiAndItsNoiseSlices) {
  // psi now and at the last step (2 edge arrays of the grid's precision), the two noise slices it
  // blends (2 in double) and, with an obstacle, the ramp (1 in double): 3 edges per cell when
  // periodic.
  for (const Precision precision : {Precision::kDouble, Precision::kFloat})
    for (const bool obstacle : {false, true}) {
      FluidParams p = cube(32, obstacle ? "multigrid" : "fft", "semi_lagrangian");
      p.precision = precision;
      if (obstacle) {
        p.obstacles.emplace_back();
        p.obstacles[0].center = p.origin + Vec3(1.0, 1.0, 1.0) * 16 * p.cell_size;
      }
      const Counted plain = count_arrays(p);
      p.turbulence.intensity.keys = {{0.0, 1.0}};
      const Counted noisy = count_arrays(p);
      const double value = precision == Precision::kFloat ? 4.0 : 8.0;
      EXPECT_NEAR(noisy.arrays - plain.arrays, 3 * (2 + (obstacle ? 3 : 2) * 8.0 / value), 1e-9);
      EXPECT_GE(noisy.estimate, noisy.bytes);
      EXPECT_LE(noisy.estimate, 2.0 * noisy.bytes);
    }
}

}  // namespace flagsim
