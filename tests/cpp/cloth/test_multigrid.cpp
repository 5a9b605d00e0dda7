// Preconditioners of the implicit cloth solve: the multigrid cycle (positive, contracting, the same
// answer as block Jacobi to the CG tolerance, far fewer CG iterations on fine flags) and SSOR in
// Eisenstat's form (the split system it solves, the same answer in fewer iterations).
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <utility>

#include "cloth/integrators.h"
#include "cloth/multigrid.h"
#include "common/simd.h"
#include "scene/simulation.h"

namespace flagsim {
namespace {

// The paper flag meshed rows x rows, in its 2 m/s wind, alone (no pole collision changes).
Scene grid_flag(int rows, const std::string& preconditioner, const std::string& drag = "paper") {
  Scene s = Scene::paper();
  s.air.model = AirModel::kUniform;
  s.self_collision.enabled = false;
  s.flapping.mode = FlapMode::kOff;
  s.flag.rows = s.flag.cols = rows;
  s.drag.model = parse_enum<DragModel>("drag.model", drag);
  s.integrator.method = Method::kImplicit;
  s.integrator.preconditioner = parse_enum<Preconditioner>("preconditioner", preconditioner);
  return s;
}

MatX3 random_rows(const ClothTopology& topo, std::mt19937& rng) {
  std::normal_distribution<double> g;
  MatX3 a(topo.num_vertices(), 3);
  for (Index i = 0; i < a.rows(); ++i)
    for (int k = 0; k < 3; ++k) a(i, k) = topo.pinned(i) ? 0.0 : g(rng);
  return a;
}

// The implicit system of a rows x rows flag after 20 steps in its wind, in 2 m/s air.
struct MovingFlagSystem {
  Simulation sim;
  IntegratorScratch s;
  MovingFlagSystem(int rows, const std::string& preconditioner, const std::string& drag)
      : sim(grid_flag(rows, preconditioner, drag)), s(sim.topology()) {
    sim.step(20);
    const ClothTopology& topo = sim.topology();
    ForceSet fs;
    fs.gravity = fs.drag = fs.springs = true;
    fs.drag_params = sim.scene().drag;
    const MatX3 u =
        MatX3::Constant(topo.num_vertices(), 3, 0.0).rowwise() + Vec3(2, 0, 0).transpose();
    assemble_implicit_system(topo, fs, sim.scene().dt, sim.positions(), sim.velocities(), u, s.sys,
                             s.tmp);
  }
};

class Multigrid32 : public ::testing::TestWithParam<const char*> {};

// The cycle V as a preconditioner of flexible CG, on the system of a flag moving in wind (with
// "triangle" drag, the triangle coupling terms J_t too): positive (x^T V x > 0), homogeneous
// (V(c x) = c V(x): the K-cycle's weights do not depend on the scale), zero on pinned rows, and
// as one step of a solver, e <- e - V(A e), it contracts the slowest error's A-norm below 0.8
// (here 0.68; a W-cycle gives 0.71, Gauss-Seidel without the coarse correction 0.93). The K-cycle
// makes V slightly nonlinear, so symmetry holds only approximately.
TEST_P(Multigrid32, CycleIsPositiveHomogeneousAndContracts) {
  MovingFlagSystem m(32, "multigrid", GetParam());
  const ClothTopology& topo = m.sim.topology();
  IntegratorScratch& s = m.s;
  ASSERT_FALSE(s.mg.levels.empty());
  multigrid_setup(topo, s.sys, s.mg);
  std::mt19937 rng(7);
  for (int trial = 0; trial < 5; ++trial) {
    const MatX3 x = random_rows(topo, rng);
    MatX3 vx(x.rows(), 3), v3x(x.rows(), 3);
    multigrid_vcycle(topo, s.sys, s.mg, x, vx);
    EXPECT_GT(dot(x, vx), 0.0);
    multigrid_vcycle(topo, s.sys, s.mg, MatX3(-3.0 * x), v3x);
    EXPECT_LE((v3x + 3.0 * vx).norm(), 1e-12 * v3x.norm());
    for (Index i = 0; i < topo.num_vertices(); ++i) {
      if (topo.pinned(i)) {
        EXPECT_EQ(vx.row(i).norm(), 0.0);
      }
    }
  }
  // As a solver, e <- e - V(A e): the A-norm contraction of the slowest error, found by repeating
  // the step (power iteration from a random e). Gauss-Seidel alone takes a random error down by
  // ~7x in one step but leaves the smooth ones: this measures the coarse correction.
  MatX3 e = random_rows(topo, rng), Ae(e.rows(), 3), ve(e.rows(), 3);
  apply_system(topo, s.sys, e, Ae);
  double contraction = 1;
  for (int it = 0; it < 15; ++it) {
    const double before = std::sqrt(dot(e, Ae));
    multigrid_vcycle(topo, s.sys, s.mg, Ae, ve);
    e = (e - ve) / before;  // A-norm 1 before the step
    apply_system(topo, s.sys, e, Ae);
    contraction = std::sqrt(dot(e, Ae));
  }
  RecordProperty("contraction", std::to_string(contraction));
  EXPECT_LT(contraction, 0.8);
}

// A assembled densely from its definition in ClothSystem (3N x 3N): the D_i, B_s and J_t terms.
Eigen::MatrixXd dense_system(const ClothTopology& topo, const ClothSystem& A) {
  const Index N = topo.num_vertices();
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(3 * N, 3 * N);
  for (Index i = 0; i < N; ++i) dense.block<3, 3>(3 * i, 3 * i) += A.D[i];
  for (Index sp = 0; sp < topo.num_springs(); ++sp) {
    const Index i = topo.springs(sp, 0), j = topo.springs(sp, 1);
    const Mat3 B = A.B[sp].matrix();
    dense.block<3, 3>(3 * i, 3 * i) += B;
    dense.block<3, 3>(3 * j, 3 * j) += B;
    dense.block<3, 3>(3 * i, 3 * j) -= B;
    dense.block<3, 3>(3 * j, 3 * i) -= B;
  }
  for (size_t t = 0; t < A.J.size(); ++t)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        dense.block<3, 3>(3 * topo.triangles(Index(t), a), 3 * topo.triangles(Index(t), b)) +=
            A.J[t];
  return dense;
}

// apply_system (the CG product, which shares the smoother's neighbour-block kernel) against A
// assembled densely from its definition in ClothSystem: the D_i, B_s and J_t terms with the
// pinned rows and columns dropped.
TEST_P(Multigrid32, ProductIsTheDefinedMatrix) {
  MovingFlagSystem m(12, "jacobi", GetParam());
  const ClothTopology& topo = m.sim.topology();
  const ClothSystem& A = m.s.sys;
  EXPECT_EQ(A.J.empty(), std::string(GetParam()) != "triangle");
  const Index N = topo.num_vertices();
  const Eigen::MatrixXd dense = dense_system(topo, A);
  std::mt19937 rng(11);
  for (int trial = 0; trial < 3; ++trial) {
    const MatX3 p = random_rows(topo, rng);
    MatX3 out(N, 3);
    apply_system(topo, A, p, out);
    const VecX flat = Eigen::Map<const VecX>(p.data(), 3 * N);
    const VecX expect = dense * flat;
    for (Index i = 0; i < N; ++i) {
      const Vec3 e = topo.pinned(i) ? Vec3::Zero() : Vec3(expect.segment<3>(3 * i));
      EXPECT_LE((Vec3(out.row(i)) - e).norm(), 1e-12 * expect.norm()) << "vertex " << i;
    }
  }
}

// Eisenstat's product and the forward substitution against A's free rows and columns assembled
// densely, split as A = L + D + U by 3x3 blocks in vertex order: t = (D + U)^-1 p, w = (D + L)^-1
// A (D + U)^-1 p, D w, p . w, and (D + L)^-1 b; zero on pinned rows.
TEST_P(Multigrid32, EisenstatProductIsTheSplitSystem) {
  MovingFlagSystem m(8, "ssor", GetParam());
  const ClothTopology& topo = m.sim.topology();
  const ClothSystem& A = m.s.sys;
  const Index N = topo.num_vertices();
  std::vector<Index> free_dof;
  for (Index i = 0; i < N; ++i)
    if (!topo.pinned(i))
      for (int k = 0; k < 3; ++k) free_dof.push_back(3 * i + k);
  const Index n = Index(free_dof.size());
  const Eigen::MatrixXd full = dense_system(topo, A);
  Eigen::MatrixXd a(n, n), d = Eigen::MatrixXd::Zero(n, n);
  for (Index r = 0; r < n; ++r)
    for (Index c = 0; c < n; ++c) {
      a(r, c) = full(free_dof[r], free_dof[c]);
      if (free_dof[r] / 3 == free_dof[c] / 3) d(r, c) = a(r, c);
    }
  Eigen::MatrixXd lower = a.triangularView<Eigen::StrictlyLower>(), upper = lower.transpose();
  for (Index r = 0; r < n; ++r)  // the blocks' own lower and upper parts belong to D
    for (Index c = 0; c < n; ++c)
      if (free_dof[r] / 3 == free_dof[c] / 3) lower(r, c) = upper(r, c) = 0;
  const Eigen::MatrixXd dl = d + lower, du = d + upper;
  auto flat = [&](const MatX3& x) {
    VecX v(n);
    for (Index r = 0; r < n; ++r) v[r] = x.data()[free_dof[r]];
    return v;
  };
  auto pinned_rows_zero = [&](const MatX3& x) {
    for (Index i = 0; i < N; ++i)
      if (topo.pinned(i)) {
        EXPECT_EQ(x.row(i).norm(), 0.0) << "vertex " << i;
      }
  };
  std::mt19937 rng(5);
  for (int trial = 0; trial < 3; ++trial) {
    const MatX3 p = random_rows(topo, rng);
    MatX3 t(N, 3), u(N, 3), w(N, 3), dw(N, 3), x(N, 3);
    const double pw = eisenstat_product(topo, A, p, t, u, w, dw);
    lower_block_solve(topo, A, p, x);
    const VecX pf = flat(p), te = du.lu().solve(pf), we = dl.lu().solve(a * te);
    const VecX xe = dl.lu().solve(pf);
    EXPECT_LE((flat(t) - te).norm(), 1e-10 * te.norm());
    EXPECT_LE((flat(w) - we).norm(), 1e-10 * we.norm());
    EXPECT_LE((flat(dw) - d * we).norm(), 1e-10 * (d * we).norm());
    EXPECT_NEAR(pw, pf.dot(we), 1e-10 * std::abs(pf.dot(we)));
    EXPECT_LE((flat(x) - xe).norm(), 1e-10 * xe.norm());
    for (const MatX3* y : {&t, &w, &dw, &x}) pinned_rows_zero(*y);
  }
}

// SSOR-preconditioned CG (Eisenstat's form) solves the same system as block Jacobi: the paper
// flag after 30 steps agrees at the level the CG tolerance allows, and to 1e-10 m with a tight
// one, in well under half the iterations.
// 30 steps of a rows x rows flag with `preconditioner` against block Jacobi: the same motion to
// the CG tolerance (1e-6 m at the default, 1e-10 m at 1e-9), no halving; returns the CG
// iterations of each (Jacobi, other) at the default tolerance.
std::pair<long, long> expect_same_motion_as_block_jacobi(int rows, const char* preconditioner,
                                                         const char* drag) {
  Simulation a(grid_flag(rows, "jacobi", drag)), b(grid_flag(rows, preconditioner, drag));
  long ia = 0, ib = 0;
  for (int i = 0; i < 30; ++i) {
    a.step();
    b.step();
    EXPECT_EQ(b.last_step_stats().halvings, 0);
    ia += a.last_step_stats().cg_iterations;
    ib += b.last_step_stats().cg_iterations;
  }
  EXPECT_LT((a.positions() - b.positions()).cwiseAbs().maxCoeff(), 1e-6);  // m; flag 0.81 m
  Scene tight = grid_flag(rows, preconditioner, drag);
  tight.integrator.cg_tolerance = 1e-9;
  Scene tight_j = tight;
  tight_j.integrator.preconditioner = Preconditioner::kJacobi;
  Simulation c(tight), d(tight_j);
  c.step(30);
  d.step(30);
  EXPECT_LT((c.positions() - d.positions()).cwiseAbs().maxCoeff(), 1e-10);
  return {ia, ib};
}

TEST_P(Multigrid32, SsorSameMotionAsBlockJacobiInFewerIterations) {
  const auto [jacobi, ssor] = expect_same_motion_as_block_jacobi(8, "ssor", GetParam());
  EXPECT_LT(2 * ssor, jacobi);
}

// Both preconditioners solve the same system to the same relative residual: after 30 steps the
// flags agree far below the flag's size, at the level the CG tolerance allows.
TEST_P(Multigrid32, SameMotionAsBlockJacobiToTheCgTolerance) {
  expect_same_motion_as_block_jacobi(32, "multigrid", GetParam());
}

INSTANTIATE_TEST_SUITE_P(Drag, Multigrid32, ::testing::Values("paper", "triangle"));

// CG iterations per step grow like sqrt(k h^2 / m) ~ rows with block Jacobi, and stay nearly
// flat with the multigrid cycle.
TEST(Multigrid, FarFewerCgIterationsOnFineFlags) {
  for (int rows : {64, 128}) {
    Simulation j(grid_flag(rows, "jacobi")), m(grid_flag(rows, "multigrid"));
    long ij = 0, im = 0;
    for (int k = 0; k < 3; ++k) {
      j.step();
      m.step();
      ij += j.last_step_stats().cg_iterations;
      im += m.last_step_stats().cg_iterations;
    }
    EXPECT_LT(3 * im, ij) << rows << " x " << rows;
    EXPECT_LT(10 * im, ij) << rows << " x " << rows;
  }
}

TEST(Multigrid, RerunIsBitIdentical) {
  Simulation a(grid_flag(48, "multigrid")), b(grid_flag(48, "multigrid"));
  a.step(10);
  b.step(10);
  EXPECT_EQ(std::memcmp(a.positions().data(), b.positions().data(),
                        sizeof(double) * a.positions().size()),
            0);
}

// The neighbour-block kernel (CG product and fine smoother) gives the same bits on 32-byte AVX
// vectors as on 16-byte ones: multigrid on a 33 x 33 flag (vertices with 5 to 12 neighbours, so
// scalar tails at both widths), block Jacobi and SSOR (its substitutions) on 8 x 8, each with both
// drag models.
TEST(Multigrid, SameBitsAtEveryVectorWidth) {
  if (vector_bytes() < 32) GTEST_SKIP() << "this CPU has one vector width only (no AVX)";
  for (const char* drag : {"paper", "triangle"})
    for (const char* preconditioner : {"multigrid", "jacobi", "ssor"}) {
      const int rows = std::string(preconditioner) == "multigrid" ? 33 : 8;
      auto run = [&](int cap) {
        vector_bytes(cap);
        Simulation sim(grid_flag(rows, preconditioner, drag));
        sim.step(10);
        vector_bytes(0);
        return MatX3(sim.positions());
      };
      const MatX3 wide = run(0), narrow = run(16);
      EXPECT_EQ(std::memcmp(wide.data(), narrow.data(), sizeof(double) * wide.size()), 0)
          << drag << " drag, " << preconditioner << ", " << rows << " rows";
    }
}

TEST(Multigrid, AutoPicksSsorOnThePaperFlag) {
  Simulation a(grid_flag(8, "auto")), j(grid_flag(8, "ssor"));
  a.step(5);
  j.step(5);
  EXPECT_EQ((a.positions() - j.positions()).cwiseAbs().maxCoeff(), 0.0);
}

}  // namespace
}  // namespace flagsim
