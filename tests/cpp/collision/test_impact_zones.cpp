#include "collision/impact_zones.h"

#include <gtest/gtest.h>

#include "collision/pole.h"

namespace flagsim {
namespace {

// Five vertices at x0 = (i, 0, 0), moved to x = x0 + (0, 0, 1), with velocities along x.
struct Cloud {
  MatX3 x0{5, 3}, x{5, 3}, v{5, 3};
  VecX w{5};
  Cloud() {
    for (Index i = 0; i < 5; ++i) {
      x0.row(i) << double(i), 0, 0;
      x.row(i) << double(i), 0, 1;
      v.row(i) << double(i + 1), 0, 0;
    }
    w << 1, 0.5, 0.25, 1, 1;  // masses 1, 2, 4, 1, 1 kg
  }
};

TEST(ImpactZones, FreezingAGroupSendsItBackToX0AndKeepsItsMomentum) {
  Cloud c;
  ImpactZones zones(5);
  const int32_t group[4] = {0, 1, 2, 3};
  const Vec3 momentum = c.v.row(0) / 1 + c.v.row(1) * 2 + c.v.row(2) * 4 + c.v.row(3) / 1;
  EXPECT_EQ(zones.freeze(group, c.x0, c.x, c.v, c.w), 4);
  const Vec3 common = momentum / 8;  // (1 + 4 + 12 + 4) / 8 along x
  for (const int32_t i : group) {
    EXPECT_EQ(c.x.row(i), c.x0.row(i));
    EXPECT_NEAR((c.v.row(i).transpose() - common).norm(), 0, 1e-15);
    EXPECT_TRUE(zones.still(i, c.w));
  }
  EXPECT_EQ(c.x(4, 2), 1);  // not in the group: untouched
  EXPECT_FALSE(zones.still(4, c.w));
  // Frozen again in another group: moved again, counted once.
  const int32_t overlap[4] = {2, 3, 4, 0};
  EXPECT_EQ(zones.freeze(overlap, c.x0, c.x, c.v, c.w), 1);
  zones.clear();
  EXPECT_FALSE(zones.still(0, c.w));
}

// The group moves with its pin: at rest with a pin at rest, and with a moving pin's velocity
// (the pins' frame; the Simulation passes x0 carried by the pins' pose).
TEST(ImpactZones, AGroupHoldingAPinnedVertexMovesWithThePin) {
  Cloud c;
  c.w[1] = 0;  // pinned, and (as the caller may have done) displaced, moving at (2, 0, 0)
  ImpactZones zones(5);
  const int32_t group[4] = {0, 1, 2, 3};
  EXPECT_EQ(zones.freeze(group, c.x0, c.x, c.v, c.w), 3);
  for (const int32_t i : {0, 2, 3}) {
    EXPECT_EQ(c.x.row(i), c.x0.row(i));
    EXPECT_EQ(c.v.row(i), c.v.row(1));
  }
  Cloud still;
  still.w[1] = 0;
  still.v.row(1).setZero();
  zones.clear();
  zones.freeze(group, still.x0, still.x, still.v, still.w);
  for (const int32_t i : {0, 2, 3}) EXPECT_EQ(still.v.row(i).norm(), 0);
  EXPECT_EQ(c.x(1, 2), 1);  // a pinned vertex is never moved
  EXPECT_EQ(c.v(1, 0), 2);
  EXPECT_TRUE(zones.still(1, c.w));  // nor can be
}

// A vertex moved from 10 cm off the pole's axis to 2 cm off it (inside the 5.5 cm radius).
TEST(ImpactZones, AVertexInThePoleGoesBackWithoutItsInwardVelocity) {
  PoleParams pole;
  MatX3 x0(2, 3), x(2, 3), v(2, 3);
  x0 << 0.1, 0, 0, 0.1, 0, 0.1;
  x << 0.02, 0, 0, 0.02, 0, 0.1;  // vertex 1 stays outside
  v << -3, 1, 2, -3, 1, 2;
  VecX w = VecX::Ones(2);
  ImpactZones zones(2);
  EXPECT_TRUE(zones.any_in_pole(pole, x, w));
  EXPECT_EQ(zones.freeze_in_pole(pole, x0, x, v, w), 1);
  EXPECT_EQ(x.row(0), x0.row(0));
  EXPECT_NEAR((v.row(0).transpose() - Vec3(0, 1, 2)).norm(), 0, 1e-15);  // radial part gone
  EXPECT_EQ(v.row(1).transpose(), Vec3(-3, 1, 2));
  EXPECT_FALSE(zones.any_in_pole(pole, x, w));
  EXPECT_TRUE(zones.still(0, w));
  // A pinned vertex in the pole is not the fallback's to move.
  zones.clear();
  x(0, 0) = 0.02;
  w[0] = 0;
  EXPECT_FALSE(zones.any_in_pole(pole, x, w));
  EXPECT_EQ(zones.freeze_in_pole(pole, x0, x, v, w), 0);
}

// The same with the pole carried at U (x0 carried with it, as in self-collision's sweeps): the
// vertex goes back to x0 and loses its inward velocity relative to the pole, keeping U.
TEST(ImpactZones, AVertexInACarriedPoleGoesBackWithThePolesVelocity) {
  PoleParams pole;
  const Vec3 U(5.0, 0.0, 0.0);
  RigidMotion motion;
  motion.h = 0.01;
  motion.from.t = U;
  motion.to.t = U * 1.01;
  MatX3 x0(2, 3), x(2, 3), v(2, 3);
  x0 << 0.1, 0, 0, 0.1, 0, 0.1;
  x << 0.02, 0, 0, 0.02, 0, 0.1;
  v << -3, 1, 2, -3, 1, 2;
  for (Index i = 0; i < 2; ++i) {
    x0.row(i) += motion.to.t.transpose();
    x.row(i) += motion.to.t.transpose();
    v.row(i) += U.transpose();
  }
  VecX w = VecX::Ones(2);
  ImpactZones zones(2);
  EXPECT_FALSE(zones.any_in_pole(pole, x, w));  // the pole at rest is 5 m behind
  EXPECT_TRUE(zones.any_in_pole(pole, x, w, &motion));
  EXPECT_EQ(zones.freeze_in_pole(pole, x0, x, v, w, &motion), 1);
  EXPECT_EQ(x.row(0), x0.row(0));
  EXPECT_NEAR((v.row(0).transpose() - Vec3(5, 1, 2)).norm(), 0, 1e-12);  // radial part gone
  EXPECT_EQ(v.row(1).transpose(), Vec3(2, 1, 2));
  EXPECT_FALSE(zones.any_in_pole(pole, x, w, &motion));
}

}  // namespace
}  // namespace flagsim
