#include <gtest/gtest.h>

#include "collision/solids.h"

namespace flagsim {

namespace {

// One free unit mass moving from a to b over h; the solid's response.
struct One {
  MatX3 x0, x, v;
  VecX inv_mass = VecX::Ones(1), mass = VecX::Ones(1);
  One(const Vec3& a, const Vec3& b, double h) : x0(1, 3), x(1, 3), v(1, 3) {
    x0.row(0) = a.transpose();
    x.row(0) = b.transpose();
    v.row(0) = ((b - a) / h).transpose();
  }
};

ClothSolid wall(double thickness, double friction = 0.0) {
  SolidGeometry g;
  g.half_size = Vec3(0.001, 1.0, 1.0);  // 2 mm thick, at x = 0
  return ClothSolid(g, thickness, friction);
}

}  // namespace

TEST(ClothSolids, AFastVertexStopsAtAThinWall) {
  // 30 m/s over a 10 ms step: 0.3 m, 150 times the wall's thickness.
  One o(Vec3(-0.1, 0.2, 0), Vec3(0.2, 0.2, 0), 0.01);
  const ClothSolid s = wall(0.005);
  EXPECT_EQ(collide_solid(s, nullptr, o.x0, o.x, o.v, o.inv_mass, o.mass).moved, 1);
  EXPECT_LT(o.x(0, 0), -0.001 - 0.005 * (1 - 2e-3));  // on the near side, thickness kept
  EXPECT_GT(o.x(0, 0), -0.0065);
  EXPECT_NEAR(o.v(0, 0), 0.0, 1e-12);  // inelastic: the normal velocity is gone
}

TEST(ClothSolids, FrictionTakesTangentialSpeedUpToMuTimesTheNormal) {
  // Into the wall at 1 m/s and along it at 3 m/s.
  for (double mu : {0.0, 0.5, 5.0}) {
    One o(Vec3(-0.01, 0, 0), Vec3(0.0, 0.03, 0), 0.01);
    o.v.row(0) = Vec3(1, 3, 0).transpose();
    collide_solid(wall(0.005, mu), nullptr, o.x0, o.x, o.v, o.inv_mass, o.mass);
    EXPECT_NEAR(o.v(0, 1), std::max(0.0, 3.0 - mu * 1.0), 1e-12) << mu;
  }
}

TEST(ClothSolids, AMovingWallPushesWithItsVelocityAndBooksItsWork) {
  // The wall moves +x at 1 m/s (at x = 0 at the start, 0.01 m at the end of a 10 ms piece); a
  // vertex at rest 6 mm in front of its face is met and pushed along at the wall's speed.
  RigidMotion m;
  m.h = 0.01;
  m.to.t = Vec3(0.01, 0, 0);
  One o(Vec3(0.007, 0, 0), Vec3(0.007, 0, 0), 0.01);
  o.v.setZero();
  const SolidContacts c = collide_solid(wall(0.005), &m, o.x0, o.x, o.v, o.inv_mass, o.mass);
  EXPECT_EQ(c.moved, 1);
  EXPECT_NEAR(o.x(0, 0), 0.01 + 0.001 + 0.005, 1e-8);
  EXPECT_NEAR(o.v(0, 0), 1.0, 1e-12);
  EXPECT_NEAR(c.wall_work, 1.0, 1e-12);  // m dv . v_wall = 1 kg x 1 m/s x 1 m/s
}

TEST(ClothSolids, PinnedAndFarVerticesAreLeftAlone) {
  One o(Vec3(-0.1, 0.2, 0), Vec3(0.2, 0.2, 0), 0.01);
  o.inv_mass[0] = 0;
  EXPECT_EQ(collide_solid(wall(0.005), nullptr, o.x0, o.x, o.v, o.inv_mass, o.mass).moved, 0);
  One far(Vec3(-0.1, 3, 0), Vec3(0.2, 3, 0), 0.01);
  EXPECT_EQ(collide_solid(wall(0.005), nullptr, far.x0, far.x, far.v, far.inv_mass, far.mass).moved,
            0);
  EXPECT_EQ(far.x(0, 0), 0.2);
}

}  // namespace flagsim
