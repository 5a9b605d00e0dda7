// Forces and their Jacobians against finite differences; topology invariants.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "cloth/forces.h"
#include "cloth/topology.h"
#include "common/parallel.h"

namespace flagsim {
namespace {

ClothTopology small_flag() {
  FlagParams p;
  p.rows = 4;
  p.cols = 5;
  p.stretch_stiffness = 120;
  p.shear_stiffness = 30;
  p.bend_stiffness = 7;
  p.damping = 0.05;
  return build_flag_topology(p);
}

MatX3 random_rows(Index n, double scale, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-scale, scale);
  MatX3 m(n, 3);
  for (Index i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) m(i, k) = d(rng);
  return m;
}

TEST(Topology, MassAndAreaAddUpAndPinsHaveZeroInverseMass) {
  FlagParams p;
  const ClothTopology t = build_flag_topology(p);
  EXPECT_NEAR(t.area.sum(), p.width * p.height, 1e-12);
  EXPECT_NEAR(t.mass.sum(), p.areal_density * p.width * p.height, 1e-12);
  for (int r = 0; r < p.rows; ++r) EXPECT_TRUE(t.pinned(r * p.cols));
  EXPECT_FALSE(t.pinned(1));
  // structural + shear + bend counts of an R x C grid
  const int R = p.rows, C = p.cols;
  EXPECT_EQ(t.num_springs(),
            R * (C - 1) + (R - 1) * C + 2 * (R - 1) * (C - 1) + R * (C - 2) + (R - 2) * C);
  // every rest triangle faces +z
  MatX3 n;
  compute_vertex_normals(t, t.rest_positions, n);
  for (Index i = 0; i < n.rows(); ++i) EXPECT_NEAR(n(i, 2), 1.0, 1e-12);
}

TEST(Forces, SpringAndDampingForcesConserveMomentum) {
  const ClothTopology t = small_flag();
  const MatX3 x = t.rest_positions + random_rows(t.num_vertices(), 0.01, 1);
  const MatX3 v = random_rows(t.num_vertices(), 0.3, 2);
  MatX3 f = MatX3::Zero(t.num_vertices(), 3);
  add_spring_forces(t, x, v, f);
  // internal forces: no net force (momentum conservation)
  EXPECT_LT(f.colwise().sum().norm(), 1e-12);
}

TEST(Forces, PositionJacobianMatchesCentralDifferences) {
  const ClothTopology t = small_flag();
  const Index n = t.num_vertices();
  // A stretched and compressed state, so both signs of (1 - L/l) occur.
  const MatX3 x = t.rest_positions * 1.05 + random_rows(n, 0.02, 3);
  const MatX3 v = MatX3::Zero(n, 3);
  const MatX3 p = random_rows(n, 1.0, 4);
  std::vector<SpringBlock> K;
  spring_position_jacobians(t, x, /*clamp_compression=*/false, K);
  MatX3 jp;
  apply_position_jacobian(t, K, p, jp);
  const double eps = 1e-6;
  MatX3 fp = MatX3::Zero(n, 3), fm = MatX3::Zero(n, 3);
  MatX3 zero_damping_v = v;
  add_spring_forces(t, x + eps * p, zero_damping_v, fp);
  add_spring_forces(t, x - eps * p, zero_damping_v, fm);
  const MatX3 fd = (fp - fm) / (2 * eps);
  EXPECT_LT((fd - jp).norm() / fd.norm(), 1e-7);
}

class DragJacobian : public ::testing::TestWithParam<const char*> {};

TEST_P(DragJacobian, VelocityJacobianMatchesCentralDifferences) {
  const ClothTopology t = small_flag();
  const Index n = t.num_vertices();
  DragParams drag;
  drag.model = parse_enum<DragModel>("drag.model", GetParam());
  drag.tangential_coefficient = 0.3;
  const double rho = 1.2;
  const MatX3 x = t.rest_positions + random_rows(n, 0.03, 5);
  const MatX3 v = random_rows(n, 2.0, 6);
  MatX3 u = random_rows(n, 1.0, 7);
  u.col(0).array() += 5.0;
  const MatX3 p = random_rows(n, 1.0, 8);
  std::vector<Mat3> Dv, Jw;
  // "paper" adds a stabilising c S |u| I to its Jacobian; with u = 0 it is the exact one (and
  // eq. 3's force depends on u only through the v-independent |u| u).
  const MatX3 u_jac = drag.model == DragModel::kPaper ? MatX3::Zero(n, 3) : u;
  drag_velocity_jacobians(t, drag, rho, x, v, u_jac, Dv, Jw);
  if (drag.model == DragModel::kPaper) {
    std::vector<Mat3> Ds, Jws;
    drag_velocity_jacobians(t, drag, rho, x, v, u, Ds, Jws);
    for (Index i = 0; i < n; ++i) {
      const Mat3 extra =
          0.5 * drag.coefficient * rho * t.area[i] * Vec3(u.row(i)).norm() * Mat3::Identity();
      EXPECT_LT((Ds[i] - Dv[i] - extra).norm(), 1e-14);
    }
  }
  MatX3 jp;
  apply_velocity_jacobian(t, Dv, Jw, p, jp);
  auto forces = [&](const MatX3& vv) {
    MatX3 f = MatX3::Zero(n, 3);
    add_drag(t, drag, rho, x, vv, u, f);
    add_spring_forces(t, x, vv, f);  // damping k_d (v2 - v1) is in here
    return f;
  };
  const double eps = 1e-6;
  const MatX3 fd = (forces(v + eps * p) - forces(v - eps * p)) / (2 * eps);
  EXPECT_LT((fd - jp).norm() / fd.norm(), 1e-7) << name_of(drag.model);
}

INSTANTIATE_TEST_SUITE_P(Models, DragJacobian, ::testing::Values("paper", "relative", "triangle"));

TEST(Forces, PaperDragIsEquation3) {
  const ClothTopology t = small_flag();
  const Index n = t.num_vertices();
  DragParams drag;  // paper, C_D = 1
  const MatX3 x = t.rest_positions;
  MatX3 u(n, 3), v(n, 3);
  u.rowwise() = Vec3(3, 0, 4).transpose();  // |u| = 5
  v.rowwise() = Vec3(0, 1, 0).transpose();  // |v| = 1
  MatX3 f = MatX3::Zero(n, 3);
  add_drag(t, drag, 1.2, x, v, u, f);
  for (Index i = 0; i < n; ++i) {
    const Vec3 want = 0.5 * 1.0 * 1.2 * t.area[i] * (5.0 * Vec3(3, 0, 4) - 1.0 * Vec3(0, 1, 0));
    EXPECT_LT((Vec3(f.row(i)) - want).norm(), 1e-15);
  }
}

TEST(Forces, TriangleDragIsTwoSidedAndVanishesEdgeOn) {
  const ClothTopology t = small_flag();
  const Index n = t.num_vertices();
  DragParams drag;
  drag.model = DragModel::kTriangle;
  drag.tangential_coefficient = 0.0;
  const MatX3 v = MatX3::Zero(n, 3);
  MatX3 u(n, 3);
  MatX3 f = MatX3::Zero(n, 3);
  u.rowwise() = Vec3(4, 0, 0).transpose();  // in the flag's plane: no normal pressure
  add_drag(t, drag, 1.2, t.rest_positions, v, u, f);
  EXPECT_LT(f.norm(), 1e-15);
  u.rowwise() = Vec3(0, 0, 4).transpose();
  add_drag(t, drag, 1.2, t.rest_positions, v, u, f);
  const Vec3 total = f.colwise().sum();
  // flat plate: 1/2 rho C_D A |u|^2 along the flow, A = flag area
  EXPECT_NEAR(total.z(), 0.5 * 1.2 * t.area.sum() * 16.0, 1e-12);
  MatX3 g = MatX3::Zero(n, 3);
  u.rowwise() = Vec3(0, 0, -4).transpose();
  add_drag(t, drag, 1.2, t.rest_positions, v, u, g);
  EXPECT_NEAR(g.colwise().sum().z(), -total.z(), 1e-12);
}

// A 64 x 64 flag (24k springs, many reduction chunks), moved off its rest shape.
struct FineFlag {
  ClothTopology t;
  MatX3 x, v;
};
FineFlag fine_flag() {
  FlagParams p;
  p.rows = p.cols = 64;
  FineFlag f{build_flag_topology(p), {}, {}};
  f.x = f.t.rest_positions + random_rows(f.t.num_vertices(), 0.004, 3);
  f.v = random_rows(f.t.num_vertices(), 2.0, 4);
  return f;
}

// The strain of spring s, as max_strain computes it.
double strain_of(const ClothTopology& t, const MatX3& x, Index s) {
  const double L = t.rest_length[s];
  return ((x.row(t.springs(s, 1)) - x.row(t.springs(s, 0))).norm() - L) / L;
}

TEST(Energy, ChunkedSumsAreTheSameOnOneAndTwoThreadsAndAgreeWithOneLoop) {
  const FineFlag f = fine_flag();
  const Vec3 g(0, -9.81, 0);
  const int threads = num_threads();
  set_num_threads(1);
  const ClothEnergy one = cloth_energy(f.t, g, f.x, f.v);
  set_num_threads(2);
  const ClothEnergy two = cloth_energy(f.t, g, f.x, f.v);
  set_num_threads(threads);
  EXPECT_EQ(one.kinetic, two.kinetic);
  EXPECT_EQ(one.gravity, two.gravity);
  EXPECT_EQ(one.spring, two.spring);
  ClothEnergy loop;  // one loop in index order: the same sums up to rounding
  for (Index i = 0; i < f.t.num_vertices(); ++i) {
    loop.kinetic += 0.5 * f.t.mass[i] * f.v.row(i).squaredNorm();
    loop.gravity -= f.t.mass[i] * g.dot(Vec3(f.x.row(i)));
  }
  for (Index s = 0; s < f.t.num_springs(); ++s) {
    const double dl = strain_of(f.t, f.x, s) * f.t.rest_length[s];
    loop.spring += 0.5 * f.t.stiffness[s] * dl * dl;
  }
  EXPECT_NEAR(one.kinetic, loop.kinetic, 1e-13 * loop.kinetic);
  EXPECT_NEAR(one.gravity, loop.gravity, 1e-13 * std::abs(loop.gravity));
  EXPECT_NEAR(one.spring, loop.spring, 1e-10 * loop.spring);
}

TEST(Energy, MaxStrainFindsTheFirstLargestAsOneLoopOnAnyThreadCount) {
  FineFlag f = fine_flag();
  double m = 0;
  Index w = -1;
  for (Index s = 0; s < f.t.num_springs(); ++s) {
    const double e = strain_of(f.t, f.x, s);
    if (e > m) {
      m = e;
      w = s;
    }
  }
  ASSERT_GT(w, 1024);  // not in the first chunk
  for (int threads : {1, 2}) {
    const int before = num_threads();
    set_num_threads(threads);
    Index worst = -2;
    EXPECT_EQ(max_strain(f.t, f.x, &worst), m);
    EXPECT_EQ(worst, w);
    // at rest: nothing above 0
    EXPECT_EQ(max_strain(f.t, f.t.rest_positions, &worst), 0.0);
    EXPECT_EQ(worst, -1);
    set_num_threads(before);
  }
  // a NaN position: NaN, at the first spring that reads it
  const Index bad = f.t.num_vertices() - 5;
  f.x(bad, 1) = std::numeric_limits<double>::quiet_NaN();
  Index first = -1;
  for (Index s = 0; s < f.t.num_springs() && first < 0; ++s)
    if (f.t.springs(s, 0) == bad || f.t.springs(s, 1) == bad) first = s;
  Index worst = -2;
  EXPECT_TRUE(std::isnan(max_strain(f.t, f.x, &worst)));
  EXPECT_EQ(worst, first);
}

TEST(Energy, OnePassGivesTheBitsOfEnergyAndMaxStrainApart) {
  const FineFlag f = fine_flag();
  const Vec3 g(0, -9.81, 0);
  for (int threads : {1, 2}) {
    const int before = num_threads();
    set_num_threads(threads);
    double strain = -1;
    Index worst = -2, worst_apart = -3;
    const ClothEnergy e = cloth_energy_and_max_strain(f.t, g, f.x, f.v, strain, &worst);
    const ClothEnergy apart = cloth_energy(f.t, g, f.x, f.v);
    EXPECT_EQ(e.kinetic, apart.kinetic);
    EXPECT_EQ(e.gravity, apart.gravity);
    EXPECT_EQ(e.spring, apart.spring);
    EXPECT_EQ(strain, max_strain(f.t, f.x, &worst_apart));
    EXPECT_EQ(worst, worst_apart);
    EXPECT_EQ(e.total(), total_energy(f.t, g, f.x, f.v));
    set_num_threads(before);
  }
}

}  // namespace
}  // namespace flagsim
