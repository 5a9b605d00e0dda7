#include "common/simd.h"
#include "fluid/advect.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

namespace flagsim {

namespace {

MacGrid<double> random_grid(bool periodic, double scale, unsigned seed) {
  GridGeometry g;
  g.nx = 9;
  g.ny = 6;
  g.nz = 5;
  g.h = 0.1;
  g.origin = Vec3(0.3, -0.2, 0.0);
  g.periodic = periodic;
  MacGrid<double> m(g);
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, scale);
  for (auto& comp : m.comp)
    for (double& x : comp) x = n(rng);
  return m;
}

GridGeometry periodic_geometry(int nx, int ny, int nz) {
  GridGeometry g;
  g.nx = nx;
  g.ny = ny;
  g.nz = nz;
  g.h = 0.1;
  g.periodic = true;
  return g;
}

template <class T>
bool same_bits(const MacGrid<T>& a, const MacGrid<T>& b) {
  for (int c = 0; c < 3; ++c)
    if (std::memcmp(a.comp[c].data(), b.comp[c].data(), a.comp[c].size() * sizeof(T)) != 0)
      return false;
  return true;
}

}  // namespace

double max_abs_difference(const MacGrid<double>& a, const MacGrid<double>& b) {
  double m = 0;
  for (int c = 0; c < 3; ++c)
    for (std::size_t i = 0; i < a.comp[c].size(); ++i)
      m = std::max(m, std::fabs(a.comp[c][i] - b.comp[c][i]));
  return m;
}

class PeriodicFastPath : public ::testing::TestWithParam<std::tuple<bool, double>> {};

// The padded periodic path against the generic kernels on the same field. Below one cell per
// step it interpolates from the node towards its upwind neighbour, the generic kernel from the
// lower node: the same trilinear value, to round-off. Nodes with departures of a cell or more
// (most of them at scale 3: several cells per step, beyond the ghost layers too) take the general
// sampler on padded copies.
TEST_P(PeriodicFastPath, MatchesTheGenericKernels) {
  const auto [maccormack, scale] = GetParam();
  const MacGrid<double> u0 = random_grid(true, scale, 11);
  const double dt = 0.1;  // u dt / h = scale cells
  MacGrid<double> generic(u0.geo), hat(u0.geo);
  if (maccormack)
    advect_maccormack(u0, dt, SampleBoundary{}, hat, generic);
  else
    advect_semi_lagrangian(u0, dt, SampleBoundary{}, generic);
  MacGrid<double> fast = u0;
  AdvectScratch<double> scratch;
  scratch.resize(u0.geo);
  advect_padded(fast, dt, maccormack, scratch, hat);
  EXPECT_FALSE(same_bits(generic, fast));  // the fast path ran (different rounding)
  EXPECT_LT(max_abs_difference(generic, fast), 3e-15 * scale);  // |u| <~ 4 scale: a few ulps
}

INSTANTIATE_TEST_SUITE_P(Advect, PeriodicFastPath,
                         ::testing::Combine(::testing::Bool(), ::testing::Values(0.3, 3.0)));

// A smooth flow moving 1.1 to 2.6 cells a step along x, and up to 0.9 across (the 128^3 benchmark
// field's regime): every node's departure is a cell or more away, so every node takes far_sample
// (within the 3 ghost layers; contiguous loads where the lanes' lower nodes share their offsets,
// lane by lane where the flow crosses a cell face within a vector), which does the general
// sampler's arithmetic: the generic kernel's bits on every node, at every vector width, on double
// and float grids (float: the departure point in double, the interpolation in float). MacCormack's
// correction (far_cell forward into the predictor and back into u^n, on vectors) then gives
// advect_maccormack's bits too.
template <class T>
void expect_far_departures_give_the_generic_bits(int nz) {
  const GridGeometry g = periodic_geometry(10, 9, nz);
  const double dt = 0.1, s = dt / g.h;  // cells per step per m/s
  MacGrid<T> u0(g);
  const double two_pi = 6.283185307179586;
  for (int c = 0; c < 3; ++c)
    for (int i = 0; i < g.nx; ++i)
      for (int j = 0; j < g.ny; ++j)
        for (int k = 0; k < g.nz; ++k) {
          const double x = two_pi * i / g.nx, y = two_pi * j / g.ny, z = two_pi * k / g.nz;
          const double cells = c == 0   ? 1.85 + 0.75 * std::sin(z + 0.3) * std::cos(y)
                               : c == 1 ? 0.9 * std::sin(x + z)
                                        : -0.6 + 0.3 * std::cos(x - y);
          u0.at(c, i, j, k) = T(cells / s);
        }
  for (const bool maccormack : {false, true}) {
    MacGrid<T> generic(g), hat(g);
    if (maccormack)
      advect_maccormack(u0, dt, SampleBoundary{}, hat, generic);
    else
      advect_semi_lagrangian(u0, dt, SampleBoundary{}, generic);
    for (const int cap : {0, 16}) {
      vector_bytes(cap);
      MacGrid<T> fast = u0;
      AdvectScratch<T> scratch;
      scratch.resize(g, maccormack);
      advect_padded(fast, dt, maccormack, scratch, hat);
      vector_bytes(0);
      EXPECT_TRUE(same_bits(generic, fast))
          << "vector cap " << cap << " nz " << nz << " maccormack " << maccormack;
    }
  }
}

// Rows of 23 nodes leave a scalar tail at every width; rows of 16 and 32 take the AVX kernel's
// unrolled rows (sl_plane_32).
constexpr int kRowLengths[] = {23, 16, 32};

TEST(Advect, PeriodicFarDeparturesGiveTheGenericKernelsBits) {
  for (const int nz : kRowLengths) expect_far_departures_give_the_generic_bits<double>(nz);
}

TEST(Advect, PeriodicFarDeparturesGiveTheGenericKernelsBitsOnAFloatGrid) {
  for (const int nz : kRowLengths) expect_far_departures_give_the_generic_bits<float>(nz);
}

// The fast path reproduces a uniform field exactly, whatever the direction of the flow, on grids
// whose rows are not a multiple of the vector width (the scalar tail).
TEST(Advect, PeriodicFastPathKeepsAUniformFieldExactly) {
  const GridGeometry g = periodic_geometry(5, 4, 7);
  for (const Vec3& w : {Vec3(0.3, -0.2, 0.45), Vec3(-0.7, 0.1, -0.05)}) {
    MacGrid<double> u(g), hat(g);
    for (int c = 0; c < 3; ++c) std::fill(u.comp[c].begin(), u.comp[c].end(), w[c]);
    AdvectScratch<double> scratch;
    scratch.resize(g);
    advect_padded(u, 0.1, false, scratch, hat);
    for (int c = 0; c < 3; ++c)
      for (double x : u.comp[c]) ASSERT_EQ(x, w[c]);
  }
}

TEST(Advect, MacCormackStaysWithinTheExtremaOfItsStencil) {
  const MacGrid<double> u0 = random_grid(false, 1.0, 5);
  MacGrid<double> hat(u0.geo), out(u0.geo);
  advect_maccormack(u0, 0.05, SampleBoundary{}, hat, out);
  for (int c = 0; c < 3; ++c) {
    double lo = 1e300, hi = -1e300;
    for (double x : u0.comp[c]) lo = std::min(lo, x), hi = std::max(hi, x);
    for (double x : out.comp[c]) {
      EXPECT_GE(x, lo);
      EXPECT_LE(x, hi);
    }
  }
}

TEST(Advect, PaddedComponentWrapsItsGhosts) {
  PaddedComponent<double> p;
  p.resize(Shape3{{3, 2, 1}});
  std::vector<double> src = {0, 1, 2, 3, 4, 5};  // (i, j) -> 2 i + j
  p.fill(src.data());
  EXPECT_EQ(p.data[p.index(-1, 0, 0)], 4.0);
  EXPECT_EQ(p.data[p.index(3, -2, 0)], 0.0);
  EXPECT_EQ(p.data[p.index(4, 3, 2)], 3.0);
}

// A periodic 6 x 5 x nz field of normal values of standard deviation `scale` (m/s): rows of 21
// nodes leave a scalar tail at every vector width, rows of 16 and 32 take the AVX kernel's
// unrolled rows.
template <class T>
MacGrid<T> random_width_field(unsigned seed, double scale, int nz = 21) {
  MacGrid<T> u(periodic_geometry(6, 5, nz));
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, scale);
  for (auto& comp : u.comp)
    for (T& x : comp) x = T(n(rng));
  return u;
}

// The fast path's vector widths (32-byte AVX where the CPU has it, 16-byte SSE2) do the same
// operations per lane, so they give the same bits, in double and in float; rows of 21 nodes
// leave a scalar tail at every width.
template <class T>
void expect_widths_agree(double scale, int nz) {
  const MacGrid<T> u0 = random_width_field<T>(17, scale, nz);
  const GridGeometry& g = u0.geo;
  auto run = [&](int cap) {
    vector_bytes(cap);
    MacGrid<T> u = u0, hat(g);
    AdvectScratch<T> scratch;
    scratch.resize(g);
    advect_padded(u, 0.1, false, scratch, hat);
    vector_bytes(0);
    return u;
  };
  const MacGrid<T> wide = run(0), narrow = run(16);
  for (int c = 0; c < 3; ++c)
    ASSERT_EQ(
        std::memcmp(wide.comp[c].data(), narrow.comp[c].data(), wide.comp[c].size() * sizeof(T)), 0)
        << "component " << c << " nz " << nz;
}

TEST(Advect, PeriodicFastPathVectorWidthsGiveTheSameBits) {
  if (vector_bytes() < 32) GTEST_SKIP() << "this CPU has one vector width only (no AVX)";
  for (const double scale : {0.3, 3.0}) {  // 3: many nodes take the general sampler too
    for (const int nz : {21, 16, 32}) {
      expect_widths_agree<double>(scale, nz);
      expect_widths_agree<float>(scale, nz);
    }
  }
}

// The explicit viscous term (viscous_beta > 0) is the advected field plus beta times the periodic
// 7-point Laplacian of u^n, summed as differences from the node (z, y, x pairs): computed here
// node by node with wrapped indices, the kernel's bits on every node, fused into the
// semi-Lagrangian pass (fast path, far path, scalar redo at scale 3) or in a pass of its own
// after MacCormack, at both vector widths, in double and in float.
template <class T>
void expect_viscous_term_exact(bool maccormack, double scale, int nz) {
  const MacGrid<T> u0 = random_width_field<T>(23, scale, nz);
  const GridGeometry& g = u0.geo;
  const double beta = 0.0075;
  auto run = [&](double b, int cap) {
    vector_bytes(cap);
    MacGrid<T> u = u0, hat(g);
    AdvectScratch<T> scratch;
    scratch.resize(g, maccormack);
    advect_padded(u, 0.1, maccormack, scratch, hat, SampleBoundary{}, b);
    vector_bytes(0);
    return u;
  };
  MacGrid<T> expected = run(0.0, 0);
  for (int c = 0; c < 3; ++c) {
    const Shape3 sh = u0.shape[c];
    auto at = [&](int i, int j, int k) {
      auto w = [](int a, int m) { return ((a % m) + m) % m; };
      return u0.comp[c][sh.index(w(i, sh.n[0]), w(j, sh.n[1]), w(k, sh.n[2]))];
    };
    for (int i = 0; i < sh.n[0]; ++i)
      for (int j = 0; j < sh.n[1]; ++j)
        for (int k = 0; k < sh.n[2]; ++k) {
          const T m = at(i, j, k);
          const T z = (at(i, j, k - 1) - m) + (at(i, j, k + 1) - m);
          const T y = (at(i, j - 1, k) - m) + (at(i, j + 1, k) - m);
          const T x = (at(i - 1, j, k) - m) + (at(i + 1, j, k) - m);
          expected.comp[c][sh.index(i, j, k)] += T(beta) * ((z + y) + x);
        }
  }
  for (const int cap : {0, 16}) {
    const MacGrid<T> got = run(beta, cap);
    for (int c = 0; c < 3; ++c)
      ASSERT_EQ(
          std::memcmp(got.comp[c].data(), expected.comp[c].data(), got.comp[c].size() * sizeof(T)),
          0)
          << "component " << c << " maccormack " << maccormack << " scale " << scale << " cap "
          << cap << " nz " << nz;
  }
}

TEST(Advect, PeriodicViscousTermIsTheLaplacianOfTheOldField) {
  for (const bool maccormack : {false, true})
    for (const double scale : {0.3, 3.0})
      for (const int nz : {21, 16, 32}) {
        expect_viscous_term_exact<double>(maccormack, scale, nz);
        expect_viscous_term_exact<float>(maccormack, scale, nz);
      }
}

// Every padded node is the wrapped source node: rows of 6 (one vector of 16 bytes or less), and
// planes of 5 rows of 16 or 21 nodes, whose inner rows take their ghosts by vectors, at every
// vector width, in double and float.
template <class T>
void expect_ghosts_are_the_wrapped_nodes(int n0, int n1, int n2) {
  constexpr int G = PaddedComponent<T>::kGhost;
  std::vector<T> src(std::size_t(n0) * n1 * n2);
  for (std::size_t i = 0; i < src.size(); ++i) src[i] = T(i);
  auto wrap = [](int i, int n) { return ((i % n) + n) % n; };
  for (const int cap : {0, 16}) {
    vector_bytes(cap);
    PaddedComponent<T> p;
    p.resize(Shape3{{n0, n1, n2}});
    p.fill(src.data());
    vector_bytes(0);
    for (int i = -G; i < n0 + G; ++i)
      for (int j = -G; j < n1 + G; ++j)
        for (int k = -G; k < n2 + G; ++k)
          ASSERT_EQ(p.data[p.index(i, j, k)],
                    src[(std::size_t(wrap(i, n0)) * n1 + wrap(j, n1)) * n2 + wrap(k, n2)])
              << "node " << i << " " << j << " " << k << " shape " << n0 << " " << n1 << " " << n2
              << " cap " << cap;
  }
}

TEST(Advect, PaddedComponentGhostsAreTheWrappedNodes) {
  for (const int n2 : {6, 16, 21}) {
    expect_ghosts_are_the_wrapped_nodes<double>(4, n2 == 6 ? 3 : 5, n2);
    expect_ghosts_are_the_wrapped_nodes<float>(4, n2 == 6 ? 3 : 5, n2);
  }
}

// A bounded grid's ghosts repeat the nearest node, past the box's every end: the components of
// a tunnel share the box (n + 1 nodes per axis), so a component's nodes beyond its own count are
// ghosts too.
TEST(Advect, ClampedGhostsRepeatTheNearestNode) {
  constexpr int G = PaddedComponent<double>::kGhost;
  const int n[3] = {4, 3, 5}, m[3] = {5, 4, 6};
  std::vector<double> src(static_cast<std::size_t>(n[0]) * n[1] * n[2]);
  for (std::size_t i = 0; i < src.size(); ++i) src[i] = double(i);
  PaddedComponent<double> p;
  p.resize_clamped(Shape3{{n[0], n[1], n[2]}}, m);
  p.fill(src.data());
  auto clamp = [](int i, int n) { return std::min(std::max(i, 0), n - 1); };
  for (int i = -G; i < m[0] + G; ++i)
    for (int j = -G; j < m[1] + G; ++j)
      for (int k = -G; k < m[2] + G; ++k)
        ASSERT_EQ(
            p.data[p.index(i, j, k)],
            src[(std::size_t(clamp(i, n[0])) * n[1] + clamp(j, n[1])) * n[2] + clamp(k, n[2])])
            << "node " << i << " " << j << " " << k;
  std::vector<double> back(src.size());
  p.unpad(back.data());
  EXPECT_EQ(back, src);
}

// A tunnel's padded advection (advect_padded on a tunnel: clamped ghosts, far_cell on vectors,
// ClampedRow node by node beside the inflow face and where a departure leaves the ghosts) against
// the generic kernels on the unpadded field: the same bits on every node, semi-Lagrangian and
// MacCormack, double and float, at every vector width, with a uniform and a parabolic inflow.
// Departures of 0.3 cells (within a cell), 2 (within the ghosts) and 5 (past them, and past the
// box, where the clamp and the inflow decide) in the random field's standard deviation; rows of
// 23 and 24 nodes (a last vector overlapping the one before at every width) and of 5 (shorter
// than a float vector).
template <class T>
void expect_bounded_fast_path_gives_the_generic_bits(double scale, int nz, bool parabolic) {
  GridGeometry g;
  g.nx = 11;
  g.ny = 7;
  g.nz = nz;
  g.h = 0.1;
  g.origin = Vec3(0.3, -0.2, 0.0);
  g.periodic = false;
  MacGrid<T> u0(g);
  std::mt19937 rng(17);
  std::normal_distribution<double> normal(0.0, scale);
  for (auto& comp : u0.comp)
    for (T& x : comp) x = T(normal(rng));
  SampleBoundary bc;
  bc.inflow = Vec3(0.7 * scale, -0.2 * scale, 0.1 * scale);
  if (parabolic) {
    bc.shape.parabolic[1] = bc.shape.parabolic[2] = true;
    bc.shape.n[1] = g.ny;
    bc.shape.n[2] = g.nz;
  }
  const double dt = 0.1;  // u dt / h = u cells
  for (const bool maccormack : {false, true}) {
    MacGrid<T> generic(g), hat(g);
    if (maccormack)
      advect_maccormack(u0, dt, bc, hat, generic);
    else
      advect_semi_lagrangian(u0, dt, bc, generic);
    for (const int cap : {0, 16}) {
      vector_bytes(cap);
      MacGrid<T> fast = u0;
      AdvectScratch<T> scratch;
      scratch.resize(g, maccormack);
      advect_padded(fast, dt, maccormack, scratch, hat, bc);
      vector_bytes(0);
      EXPECT_TRUE(same_bits(generic, fast))
          << "scale " << scale << " nz " << nz << " maccormack " << maccormack << " cap " << cap;
    }
  }
}

TEST(Advect, BoundedFastPathGivesTheGenericKernelsBits) {
  for (const double scale : {0.3, 2.0, 5.0})
    for (const int nz : {23, 24, 5})
      for (const bool parabolic : {false, true}) {
        expect_bounded_fast_path_gives_the_generic_bits<double>(scale, nz, parabolic);
        expect_bounded_fast_path_gives_the_generic_bits<float>(scale, nz, parabolic);
      }
}

}  // namespace flagsim
