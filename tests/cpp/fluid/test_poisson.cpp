#include "fluid/poisson.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

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

}  // namespace flagsim
