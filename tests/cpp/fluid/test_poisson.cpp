#include "fluid/poisson.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "poisson_cases.h"

namespace flagsim {

namespace {

/// Max |(alpha I + beta K) x - b| over the unknown nodes.
double residual(const Laplace7& op, double alpha, double beta, const AlignedVector<double>& x,
                const AlignedVector<double>& b) {
  AlignedVector<double> y(x.size());
  apply_laplace7(op, alpha, beta, x.data(), y.data());
  double m = 0;
  const Shape3& sh = op.shape;
  for (int i = 0; i < sh.n[0]; ++i)
    for (int j = 0; j < sh.n[1]; ++j)
      for (int k = 0; k < sh.n[2]; ++k) {
        if (op.fixed(0, i) || op.fixed(1, j) || op.fixed(2, k)) continue;  // known values
        const std::size_t q = sh.index(i, j, k);
        m = std::max(m, std::fabs(y[q] - b[q]));
      }
  return m;
}

}  // namespace

TEST(Laplace7, ConstantsAreTheNullSpaceOfThePeriodicOperator) {
  Laplace7 op;
  op.shape = Shape3{{5, 4, 3}};
  AlignedVector<double> x(op.shape.size(), 2.5), y(op.shape.size());
  apply_laplace7(op, 0.0, 1.0, x.data(), y.data());
  for (double v : y) EXPECT_EQ(v, 0.0);
  EXPECT_TRUE(op.singular());
}

TEST(Laplace7, ReproducesTheSecondDifferenceOfAQuadratic) {
  // K = -h^2 lap: for x(i) = i^2 along a Neumann-free interior, K x = -2 per axis.
  Laplace7 op;
  op.shape = Shape3{{6, 5, 7}};
  for (int d = 0; d < 3; ++d) op.lo[d] = op.hi[d] = Side::kNeumann;
  AlignedVector<double> x(op.shape.size()), y(op.shape.size());
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 5; ++j)
      for (int k = 0; k < 7; ++k) x[op.shape.index(i, j, k)] = i * i + 2.0 * j * j - k * k;
  apply_laplace7(op, 0.0, 1.0, x.data(), y.data());
  EXPECT_DOUBLE_EQ(y[op.shape.index(2, 2, 3)], -2.0 - 4.0 + 2.0);
}

class CgSolves : public ::testing::TestWithParam<int> {};

TEST_P(CgSolves, TunnelPressureWithMicAndPeriodicWithAndWithoutIt) {
  const int variant = GetParam();
  Laplace7 op;
  op.shape = Shape3{{9, 7, 6}};
  if (variant == 0) {  // tunnel pressure
    for (int d = 0; d < 3; ++d) op.lo[d] = op.hi[d] = Side::kNeumann;
    op.hi[0] = Side::kGhostZero;
  }
  const std::size_t n = op.shape.size();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  AlignedVector<double> b(n), x(n, 0.0);
  double mean = 0;
  for (double& v : b) mean += (v = u(rng));
  if (op.singular())
    for (double& v : b) v -= mean / double(n);
  MicPreconditioner<double> mic;
  mic.build(op);
  CgScratch<double> w;
  w.resize(n);
  const double tol = 1e-10;
  const CgResult r =
      solve_cg(op, 0.0, 1.0, b.data(), x.data(), tol, 500, variant == 2 ? nullptr : &mic, w);
  EXPECT_TRUE(r.converged);
  EXPECT_LE(residual(op, 0.0, 1.0, x, b), 1.01 * tol * 1.0);
  // MIC(0) should beat Jacobi by a wide margin on the same system.
  if (variant == 1) {
    AlignedVector<double> x2(n, 0.0);
    const CgResult j = solve_cg(op, 0.0, 1.0, b.data(), x2.data(), tol, 500,
                                static_cast<const MicPreconditioner<double>*>(nullptr), w);
    EXPECT_LT(r.iterations, j.iterations);
  }
}

INSTANTIATE_TEST_SUITE_P(Poisson, CgSolves, ::testing::Values(0, 1, 2));

TEST(Cg, DiffusionWithFixedEndsKeepsThemAndSolvesTheRest) {
  Laplace7 op;
  op.shape = Shape3{{8, 5, 4}};
  for (int d = 0; d < 3; ++d) op.lo[d] = op.hi[d] = Side::kNeumann;
  op.lo[0] = op.hi[0] = Side::kFixed;
  const std::size_t n = op.shape.size();
  AlignedVector<double> b(n), x(n);
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 5; ++j)
      for (int k = 0; k < 4; ++k)
        b[op.shape.index(i, j, k)] = (i == 0 ? 3.0 : i == 7 ? -1.0 : 0.5 * j);
  x = b;
  CgScratch<double> w;
  w.resize(n);
  const CgResult r = solve_cg(op, 1.0, 0.7, b.data(), x.data(), 1e-12, 200,
                              static_cast<const MicPreconditioner<double>*>(nullptr), w);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(x[op.shape.index(0, 2, 1)], 3.0);
  EXPECT_EQ(x[op.shape.index(7, 4, 3)], -1.0);
  EXPECT_LE(residual(op, 1.0, 0.7, x, b), 1e-11 * 3.0);
}

// ---- solids: the masked operator -----------------------------------------------------------

namespace {
using namespace poisson_cases;
}  // namespace

TEST(MaskedLaplace7, IsSymmetricOnRandomVectors) {
  for (bool tunnel : {false, true}) {
    Laplace7 op = pressure_like(9, 7, 6, tunnel);
    const AlignedVector<uint8_t> mask = random_mask(op.shape, 0.25, 4);
    op.solid = mask.data();
    const std::size_t n = op.shape.size();
    AlignedVector<double> x = random_vector<double>(n, 1), y = random_vector<double>(n, 2);
    for (std::size_t i = 0; i < n; ++i)
      if (mask[i]) x[i] = y[i] = 0;  // the unknowns only: K is not defined on solid cells
    AlignedVector<double> kx(n), ky(n);
    apply_laplace7(op, 0.0, 1.0, x.data(), kx.data());
    apply_laplace7(op, 0.0, 1.0, y.data(), ky.data());
    const double a = dot(x, ky), b = dot(y, kx);
    EXPECT_NEAR(a, b, 1e-12 * std::fabs(a)) << (tunnel ? "tunnel" : "periodic");
    EXPECT_GT(dot(x, kx), 0.0);  // positive on a non-constant vector
  }
}

TEST(MaskedLaplace7, NoFluxCrossesASolidFace) {
  // K x on the fluid cells does not read x on solid cells (no coupling across their faces), and
  // on a periodic grid constants over the fluid cells are still K's null space: a face to a
  // solid neighbour adds no term to the diagonal either.
  Laplace7 op = pressure_like(8, 6, 7, false);
  const AlignedVector<uint8_t> mask = random_mask(op.shape, 0.3, 9);
  op.solid = mask.data();
  const std::size_t n = op.shape.size();
  AlignedVector<double> x = random_vector<double>(n, 3), x2 = x, kx(n), kx2(n);
  for (std::size_t i = 0; i < n; ++i)
    if (mask[i]) x2[i] = 1e6 * (i % 7 + 1);
  apply_laplace7(op, 0.0, 1.0, x.data(), kx.data());
  apply_laplace7(op, 0.0, 1.0, x2.data(), kx2.data());
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(kx[i], kx2[i]) << i;
    if (mask[i]) {
      EXPECT_EQ(kx[i], 0.0) << i;
    }
  }
  AlignedVector<double> one(n, 1.0), k1(n);
  apply_laplace7(op, 0.0, 1.0, one.data(), k1.data());
  for (double v : k1) EXPECT_EQ(v, 0.0);
}

TEST(MaskedLaplace7, AnAllFluidMaskGivesTheSameBitsAsNoMask) {
  // The masked paths of apply_laplace7, MIC(0) and solve_cg reduce to the unmasked ones.
  for (bool tunnel : {false, true}) {
    Laplace7 op = pressure_like(10, 7, 9, tunnel);
    const std::size_t n = op.shape.size();
    const AlignedVector<uint8_t> fluid(n, 0);
    Laplace7 masked = op;
    masked.solid = fluid.data();
    const AlignedVector<double> b = consistent_rhs<double>(op, 5);
    AlignedVector<double> y1(n), y2(n);
    apply_laplace7(op, 0.0, 1.0, b.data(), y1.data());
    apply_laplace7(masked, 0.0, 1.0, b.data(), y2.data());
    EXPECT_EQ(std::memcmp(y1.data(), y2.data(), n * sizeof(double)), 0);
    MicPreconditioner<double> m1, m2;
    m1.build(op);
    m2.build(masked);
    EXPECT_EQ(std::memcmp(m1.inv_diag.data(), m2.inv_diag.data(), n * sizeof(double)), 0);
    EXPECT_EQ(m1.plus, m2.plus);
    CgScratch<double> w;
    w.resize(n);
    AlignedVector<double> x1(n, 0.0), x2(n, 0.0);
    const CgResult r1 = solve_cg(op, 0.0, 1.0, b.data(), x1.data(), 1e-10, 500, &m1, w);
    const CgResult r2 = solve_cg(masked, 0.0, 1.0, b.data(), x2.data(), 1e-10, 500, &m2, w);
    EXPECT_EQ(r1.iterations, r2.iterations);
    EXPECT_EQ(std::memcmp(x1.data(), x2.data(), n * sizeof(double)), 0);
  }
}

TEST(MaskedLaplace7, PcgSolvesWithSolidsAndLeavesThemZero) {
  for (bool tunnel : {false, true}) {
    Laplace7 op = pressure_like(12, 9, 8, tunnel);
    const AlignedVector<uint8_t> mask = box_mask(op.shape);
    op.solid = mask.data();
    const std::size_t n = op.shape.size();
    const AlignedVector<double> b = consistent_rhs<double>(op, 6);
    AlignedVector<double> x(n, 1.0);  // a guess that is wrong on the solid cells too
    MicPreconditioner<double> mic;
    mic.build(op);
    CgScratch<double> w;
    w.resize(n);
    const CgResult r = solve_cg(op, 0.0, 1.0, b.data(), x.data(), 1e-10, 500, &mic, w);
    EXPECT_TRUE(r.converged);
    EXPECT_LE(residual(op, x, b), 1e-10 * max_abs(b) * 1.01);
    for (std::size_t i = 0; i < n; ++i)
      if (mask[i]) {
        EXPECT_EQ(x[i], 0.0);
      }
  }
}

}  // namespace flagsim
