// FlapStage (flapping/flap_stage.h): eq. 5 as a drift, a force or a displacement of the exported
// geometry, and the wave it has applied across pieces and rollbacks.
#include <gtest/gtest.h>

#include "cloth/topology.h"
#include "flapping/flap_stage.h"

using namespace flagsim;

namespace {

struct Fixture {
  FlagParams fp;
  ClothTopology topo;
  FlappingParams p;
  MatX3 n;
  Fixture() {
    fp.rows = 6;
    fp.cols = 9;
    topo = build_flag_topology(fp);
    p.mode = FlapMode::kDisplace;
    p.ramp = 0;  // the whole wave from t = 0, so z is not zero at the first evaluation
    n = MatX3::Zero(topo.num_vertices(), 3);
    n.col(2).setOnes();  // the rest flag's normal, +z
  }
  // eq. 5 directly, with the inputs the stage documents
  VecX z_at(double u_p, double t) const {
    VecX L(topo.num_vertices());
    for (Index i = 0; i < L.size(); ++i) L[i] = topo.pinned(i) ? 0.0 : topo.tether_length[i];
    VecX z;
    flapping_displacement(Perlin1D(p.seed), topo.uv, L, u_p, t, p, z);
    return z;
  }
};

}  // namespace

TEST(FlapStage, DriftMovesEachFreeVertexOntoTheWaveOverThePiece) {
  Fixture f;
  FlapStage s(f.topo, f.p);
  const double h = 0.01, u_p = 2.0;
  MatX3 drift(f.topo.num_vertices(), 3);
  s.drift(f.topo, f.n, u_p, 0.3, h, drift);
  const VecX z = f.z_at(u_p, 0.3);
  ASSERT_GT(z.cwiseAbs().maxCoeff(), 1e-4);  // a wave to follow
  for (Index i = 0; i < f.topo.num_vertices(); ++i) {
    const Vec3 expect = f.topo.pinned(i) ? Vec3::Zero() : Vec3(0, 0, z[i]);
    EXPECT_NEAR((h * drift.row(i).transpose() - expect).norm(), 0.0, 1e-15) << i;
  }
  // committed, the next piece drifts only by the change of z
  s.commit();
  s.drift(f.topo, f.n, u_p, 0.31, h, drift);
  const VecX z2 = f.z_at(u_p, 0.31);
  for (Index i = 0; i < f.topo.num_vertices(); ++i)
    if (!f.topo.pinned(i)) {
      EXPECT_NEAR(h * drift(i, 2), z2[i] - z[i], 1e-15) << i;
    }
}

TEST(FlapStage, RollbackReturnsToTheWaveAppliedAtTheStepStart) {
  Fixture f;
  FlapStage s(f.topo, f.p);
  MatX3 a(f.topo.num_vertices(), 3), b(f.topo.num_vertices(), 3);
  s.save_step_start();                      // nothing applied yet
  s.drift(f.topo, f.n, 2.0, 0.3, 0.01, a);  // a piece that passes ...
  s.commit();
  s.restore_step_start();  // ... in a step that is rolled back
  s.drift(f.topo, f.n, 2.0, 0.3, 0.01, b);
  EXPECT_TRUE(a == b);  // the redone piece starts from the same applied wave
}

TEST(FlapStage, ForceIsMassTimesTheWavesAccelerationAndNoneOnPins) {
  Fixture f;
  f.p.mode = FlapMode::kForce;
  FlapStage s(f.topo, f.p);
  const double h = 0.01, t1 = 0.5, u_p = 3.0;
  MatX3 force(f.topo.num_vertices(), 3);
  s.force(f.topo, f.n, u_p, t1, h, force);
  const VecX z0 = f.z_at(u_p, t1 - h), z1 = f.z_at(u_p, t1), z2 = f.z_at(u_p, t1 + h);
  for (Index i = 0; i < f.topo.num_vertices(); ++i) {
    const double expect =
        f.topo.pinned(i) ? 0.0 : f.topo.mass[i] * (z2[i] - 2 * z1[i] + z0[i]) / (h * h);
    EXPECT_NEAR(force(i, 2), expect, 1e-12 * (1 + std::abs(expect))) << i;
    EXPECT_EQ(force(i, 0), 0.0);
  }
}

TEST(FlapStage, DisplaceMovesTheGeometryAlongTheNormalsAndPinsStay) {
  Fixture f;
  f.p.mode = FlapMode::kVisual;
  FlapStage s(f.topo, f.p);
  MatX3 render(f.topo.num_vertices(), 3);
  s.displace(f.topo.rest_positions, f.n, 2.0, 0.4, render);
  const VecX z = f.z_at(2.0, 0.4);
  EXPECT_TRUE(s.z() == z);
  for (Index i = 0; i < f.topo.num_vertices(); ++i) {
    EXPECT_EQ(render(i, 2), f.topo.rest_positions(i, 2) + z[i]);
    if (f.topo.pinned(i)) {
      EXPECT_EQ(z[i], 0.0);  // L = 0 at a pin: A(0) = 0
    }
  }
  const MatX3 edge = FlapStage::pole_edge_points(f.topo);
  ASSERT_EQ(edge.rows(), f.fp.rows);
  for (int r = 0; r < f.fp.rows; ++r)
    EXPECT_TRUE(edge.row(r) == f.topo.rest_positions.row(r * f.fp.cols));
}
