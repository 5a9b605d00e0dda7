// The multigrid-preconditioned CG (fluid/multigrid.h): a symmetric positive V-cycle, its product
// is the masked operator, agreement with MIC(0)-PCG, the residual it reports, iteration counts
// that stay flat as the grid is refined, the same bits on 1 and 2 threads, and the sizes and
// masks that stress the hierarchy.
#include "fluid/multigrid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <tuple>

#include "common/errors.h"
#include "common/parallel.h"
#include "common/simd.h"
#include "fluid/poisson.h"
#include "poisson_cases.h"

namespace flagsim {

namespace {

using namespace poisson_cases;

/// Restores the thread count at the end of a test.
struct ThreadCount {
  int saved = num_threads();
  ~ThreadCount() { set_num_threads(saved); }
};

template <class T>
double tolerance_for() {
  return sizeof(T) == 8 ? 1e-10 : 1e-5;
}

}  // namespace

// ---- the multigrid ---------------------------------------------------------------------------

TEST(PressureMultigrid, VcycleIsASymmetricPositiveOperator) {
  // CG needs a symmetric positive preconditioner: r1 . M r2 = r2 . M r1 (to the float round-off
  // of the cycle) and r . M r > 0.
  for (bool tunnel : {false, true}) {
    Laplace7 op = pressure_like(24, 20, 16, tunnel);
    const AlignedVector<uint8_t> mask = box_mask(op.shape);
    op.solid = mask.data();
    PoissonMultigrid<double> mg;
    mg.build(op);
    ASSERT_GE(mg.levels(), 3);
    const std::size_t n = op.shape.size();
    const AlignedVector<double> r1 = consistent_rhs<double>(op, 1),
                                r2 = consistent_rhs<double>(op, 2);
    AlignedVector<double> z1(n), z2(n);
    mg.apply(r1.data(), z1.data());
    mg.apply(r2.data(), z2.data());
    const double a = dot(r1, z2), b = dot(r2, z1);
    EXPECT_NEAR(a, b, 1e-5 * std::sqrt(dot(r1, z1) * dot(r2, z2)));
    EXPECT_GT(dot(r1, z1), 0.0);
    for (std::size_t i = 0; i < n; ++i)
      if (mask[i]) {
        EXPECT_EQ(z1[i], 0.0);
      }
  }
}

TEST(PressureMultigrid, ItsProductIsTheMaskedOperator) {
  // Level 0 in the grid's precision, unit conductances with x = 0 on solid cells.
  for (bool tunnel : {false, true}) {
    Laplace7 op = pressure_like(8, 6, 7, tunnel);
    const AlignedVector<uint8_t> mask = random_mask(op.shape, 0.3, 9);
    op.solid = mask.data();
    const std::size_t n = op.shape.size();
    AlignedVector<double> x = random_vector<double>(n, 3), kx(n), ky(n);
    for (std::size_t i = 0; i < n; ++i)
      if (mask[i]) x[i] = 0;
    PoissonMultigrid<double> mg;
    mg.build(op);
    apply_laplace7(op, 0.0, 1.0, x.data(), kx.data());
    mg.apply_operator(x.data(), ky.data());
    for (std::size_t i = 0; i < n; ++i) EXPECT_NEAR(kx[i], ky[i], 1e-14 * 6) << i;  // |x| <= 1
  }
}

TEST(PressureMultigrid, RejectsAFixedSide) {
  Laplace7 op = pressure_like(8, 8, 8, true);
  op.lo[0] = Side::kFixed;
  PoissonMultigrid<double> mg;
  EXPECT_THROW(mg.build(op), InvalidArgument);
}

/// (boundary: tunnel?, solid box?, double?)
class MultigridAgrees : public ::testing::TestWithParam<std::tuple<bool, bool, bool>> {
 protected:
  template <class T>
  void check() {
    const auto [tunnel, solid, is_double] = GetParam();
    (void)is_double;
    Laplace7 op = pressure_like(20, 16, 12, tunnel);
    const AlignedVector<uint8_t> mask = box_mask(op.shape);
    if (solid) op.solid = mask.data();
    const std::size_t n = op.shape.size();
    const AlignedVector<T> b = consistent_rhs<T>(op, 11);
    const double tol = tolerance_for<T>();
    PoissonMultigrid<T> mg;
    mg.build(op);
    MicPreconditioner<T> mic;
    mic.build(op);
    CgScratch<T> w;
    w.resize(n);
    AlignedVector<T> x_mg(n, T(0)), x_pcg(n, T(0));
    const CgResult rm = solve_cg(op, b.data(), x_mg.data(), tol, 200, mg, w);
    const CgResult rp = solve_cg(op, 0.0, 1.0, b.data(), x_pcg.data(), tol, 2000, &mic, w);
    ASSERT_TRUE(rm.converged);
    ASSERT_TRUE(rp.converged);
    EXPECT_LE(rm.iterations, 15);
    EXPECT_LT(rm.iterations, rp.iterations);
    // The residual it reports is the residual of the operator (checked in double).
    EXPECT_LE(residual(op, x_mg, b), (sizeof(T) == 8 ? 1.01 : 1.5) * tol * max_abs(b));
    EXPECT_LE(rm.residual, tol);
    // Both solve one problem: the solutions differ by what the two residuals allow (K^-1 grows
    // like the squared number of cells across, ~20^2 here).
    const AlignedVector<double> a = without_mean(op, x_mg), c = without_mean(op, x_pcg);
    double diff = 0;
    for (std::size_t i = 0; i < n; ++i) diff = std::max(diff, std::fabs(a[i] - c[i]));
    EXPECT_LE(diff, 1e3 * tol * max_abs(b)) << "max |x| " << max_abs(a);
    for (std::size_t i = 0; i < n; ++i)
      if (op.is_solid(i)) {
        EXPECT_EQ(x_mg[i], T(0));
      }
  }
};

TEST_P(MultigridAgrees, WithPcgToTheTolerance) {
  if (std::get<2>(GetParam()))
    check<double>();
  else
    check<float>();
}

INSTANTIATE_TEST_SUITE_P(Poisson, MultigridAgrees,
                         ::testing::Combine(::testing::Bool(), ::testing::Bool(),
                                            ::testing::Bool()),
                         [](const auto& info) {
                           return std::string(std::get<0>(info.param) ? "Tunnel" : "Periodic") +
                                  (std::get<1>(info.param) ? "Solid" : "Open") +
                                  (std::get<2>(info.param) ? "Double" : "Float");
                         });

TEST(PressureMultigrid, IterationsStayFlatAsTheGridIsRefined) {
  // To a 1e-8 relative residual from x = 0, a random right-hand side (harder than a fluid's):
  // at most 15 iterations and no growth with the size (MIC(0) grows like n). The counts do not
  // depend on the thread count (SameBitsOnOneAndTwoThreads): one thread, which a loaded machine
  // runs fastest.
  ThreadCount restore;
  set_num_threads(1);
  for (bool tunnel : {false, true}) {
    int previous = 0;
    for (int size : {16, 32, 64}) {
      Laplace7 op = pressure_like(size, size, size, tunnel);
      const AlignedVector<uint8_t> mask = box_mask(op.shape);
      op.solid = mask.data();
      const AlignedVector<double> b = consistent_rhs<double>(op, 3);
      PoissonMultigrid<double> mg;
      mg.build(op);
      CgScratch<double> w;
      w.resize(op.shape.size());
      AlignedVector<double> x(op.shape.size(), 0.0);
      const CgResult r = solve_cg(op, b.data(), x.data(), 1e-8, 100, mg, w);
      EXPECT_TRUE(r.converged);
      EXPECT_LE(r.iterations, 15) << size << (tunnel ? " tunnel" : " periodic");
      if (previous > 0) {
        EXPECT_LE(r.iterations, previous + 1) << size;
      }
      previous = r.iterations;
    }
  }
}

TEST(PressureMultigrid, SevenIterationsFromRestWithMoreSweepsOnCoarseLevels) {
  // Three sweeps each way on the coarse levels (two on level 0), and the residual and
  // prolongation on one colour of level 0 only: 7 iterations to 1e-8 from x = 0 at 32^3 and
  // 64^3 with the plate, tunnel and periodic (8 with two sweeps everywhere).
  ThreadCount restore;
  set_num_threads(1);
  for (bool tunnel : {false, true})
    for (int size : {32, 64}) {
      Laplace7 op = pressure_like(size, size, size, tunnel);
      const AlignedVector<uint8_t> mask = box_mask(op.shape);
      op.solid = mask.data();
      const AlignedVector<double> b = consistent_rhs<double>(op, 1);
      PoissonMultigrid<double> mg;
      mg.build(op);
      CgScratch<double> w;
      w.resize(op.shape.size());
      AlignedVector<double> x(op.shape.size(), 0.0);
      const CgResult r = solve_cg(op, b.data(), x.data(), 1e-8, 100, mg, w);
      EXPECT_TRUE(r.converged);
      EXPECT_LE(r.iterations, 7) << size << (tunnel ? " tunnel" : " periodic");
      EXPECT_LE(residual(op, x, b), 1.01e-8 * max_abs(b));
    }
}

TEST(PressureMultigrid, SameBitsOnOneAndTwoThreads) {
  ThreadCount restore;
  for (bool tunnel : {false, true}) {
    Laplace7 op = pressure_like(40, 32, 24, tunnel);  // above the parallel grain on every pass
    const AlignedVector<uint8_t> mask = box_mask(op.shape);
    op.solid = mask.data();
    const std::size_t n = op.shape.size();
    const AlignedVector<double> b = consistent_rhs<double>(op, 8);
    auto solve = [&](int threads) {
      set_num_threads(threads);
      PoissonMultigrid<double> mg;
      mg.build(op);
      CgScratch<double> w;
      w.resize(n);
      AlignedVector<double> x(n, 0.0);
      const CgResult r = solve_cg(op, b.data(), x.data(), 1e-9, 100, mg, w);
      EXPECT_TRUE(r.converged);
      return x;
    };
    const AlignedVector<double> one = solve(1), two = solve(2);
    EXPECT_EQ(std::memcmp(one.data(), two.data(), n * sizeof(double)), 0)
        << (tunnel ? "tunnel" : "periodic");
  }
}

/// x from MGPCG on op with vectors of at most cap bytes (0: the widest).
template <class T>
AlignedVector<T> solve_at_width(const Laplace7& op, const AlignedVector<T>& b, int cap) {
  vector_bytes(cap);
  const std::size_t n = op.shape.size();
  PoissonMultigrid<T> mg;
  mg.build(op);
  CgScratch<T> w;
  w.resize(n);
  AlignedVector<T> x(n, T(0));
  solve_cg(op, b.data(), x.data(), tolerance_for<T>(), 100, mg, w);
  vector_bytes(0);
  return x;
}

TEST(PressureMultigrid, SameBitsAtEveryVectorWidth) {
  // Every cell by one expression at every width (a last vector may overlap the one before and
  // recompute cells), dot products in 8 fixed lanes: 16-byte and 32-byte vectors agree.
  if (vector_bytes() < 32) GTEST_SKIP() << "this CPU has one vector width only (no AVX)";
  // Rows of 22: an overlapping last vector; level 1's rows of 11: halves shorter than a 32-byte
  // vector, which the 32-byte code runs by 16-byte vectors.
  Laplace7 op = pressure_like(28, 18, 22, true);
  const AlignedVector<uint8_t> mask = box_mask(op.shape);
  op.solid = mask.data();
  const std::size_t n = op.shape.size();
  const AlignedVector<float> bf = consistent_rhs<float>(op, 4);
  const AlignedVector<double> bd = consistent_rhs<double>(op, 4);
  EXPECT_EQ(std::memcmp(solve_at_width(op, bf, 0).data(), solve_at_width(op, bf, 16).data(),
                        n * sizeof(float)),
            0);
  EXPECT_EQ(std::memcmp(solve_at_width(op, bd, 0).data(), solve_at_width(op, bd, 16).data(),
                        n * sizeof(double)),
            0);
}

TEST(PressureMultigrid, OddSizesThinWallsAndPockets) {
  // Sizes that are not powers of two (a bounded odd axis is padded, a periodic odd one stops
  // halving and needs a colouring pass of its own), a grid too small to coarsen, scattered solids
  // (thin walls everywhere), and a periodic grid cut into two pockets by two solid planes (two
  // null vectors: each pocket's right-hand side sums to zero).
  struct Case {
    int nx, ny, nz;
    bool tunnel;
    int mask;  // 0 none, 1 box, 2 scattered, 3 two planes
  };
  const Case cases[] = {{24, 20, 9, true, 1},  {15, 16, 16, false, 1}, {12, 10, 6, false, 0},
                        {3, 1, 2, true, 0},    {17, 13, 11, true, 2},  {16, 12, 10, false, 2},
                        {16, 12, 10, false, 3}};
  for (const Case& c : cases) {
    Laplace7 op = pressure_like(c.nx, c.ny, c.nz, c.tunnel);
    AlignedVector<uint8_t> mask(op.shape.size(), 0);
    if (c.mask == 1) mask = box_mask(op.shape);
    if (c.mask == 2) mask = random_mask(op.shape, 0.2, 21);
    if (c.mask == 3)
      for (int j = 0; j < c.ny; ++j)
        for (int k = 0; k < c.nz; ++k)
          mask[op.shape.index(0, j, k)] = mask[op.shape.index(8, j, k)] = 1;
    if (c.mask) op.solid = mask.data();
    const std::size_t n = op.shape.size();
    AlignedVector<double> b = consistent_rhs<double>(op, 13);
    if (c.mask == 3) {  // zero sum in each pocket (x in 1..7 and 9..15)
      for (int pocket = 0; pocket < 2; ++pocket) {
        double s = 0, count = 0;
        for (int i = 1 + 8 * pocket; i < 8 + 8 * pocket; ++i)
          for (int j = 0; j < c.ny; ++j)
            for (int k = 0; k < c.nz; ++k) {
              s += b[op.shape.index(i, j, k)];
              count += 1;
            }
        for (int i = 1 + 8 * pocket; i < 8 + 8 * pocket; ++i)
          for (int j = 0; j < c.ny; ++j)
            for (int k = 0; k < c.nz; ++k) b[op.shape.index(i, j, k)] -= s / count;
      }
    }
    // Scattered solids wall in some fluid cells on all six sides: K's row is 0 there, so b must
    // be too, and (periodic) sum to 0 over the rest. K's diagonal from 7 products: cells with one
    // value of (i + 2j + 3k) mod 7 have no neighbour with the same value (steps change it by 1, 2
    // or 3; n_d >= 7 on this grid).
    if (c.mask == 2) {
      AlignedVector<uint8_t> walled(n, 0);
      for (int colour = 0; colour < 7; ++colour) {
        AlignedVector<double> e(n, 0.0), ke(n);
        for (int i = 0; i < c.nx; ++i)
          for (int j = 0; j < c.ny; ++j)
            for (int k = 0; k < c.nz; ++k)
              if ((i + 2 * j + 3 * k) % 7 == colour) e[op.shape.index(i, j, k)] = 1;
        apply_laplace7(op, 0.0, 1.0, e.data(), ke.data());
        for (std::size_t q = 0; q < n; ++q)
          if (e[q] == 1 && ke[q] == 0) walled[q] = 1;
      }
      double s = 0, count = 0;
      for (std::size_t q = 0; q < n; ++q)
        if (!mask[q] && !walled[q]) {
          s += b[q];
          count += 1;
        }
      for (std::size_t q = 0; q < n; ++q)
        b[q] = (mask[q] || walled[q]) ? 0.0 : b[q] - (op.singular() ? s / count : 0.0);
    }
    PoissonMultigrid<double> mg;
    mg.build(op);
    CgScratch<double> w;
    w.resize(n);
    AlignedVector<double> x(n, 0.0);
    const CgResult r = solve_cg(op, b.data(), x.data(), 1e-9, 200, mg, w);
    const std::string name = std::to_string(c.nx) + "x" + std::to_string(c.ny) + "x" +
                             std::to_string(c.nz) + (c.tunnel ? " tunnel" : " periodic") +
                             " mask " + std::to_string(c.mask);
    EXPECT_TRUE(r.converged) << name << ", " << r.iterations << " iterations";
    EXPECT_LE(residual(op, x, b), 1.01e-9 * max_abs(b)) << name;
    EXPECT_LE(r.iterations, c.mask == 2 ? 40 : 20) << name;
  }
}

}  // namespace flagsim
