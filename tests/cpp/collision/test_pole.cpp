#include "collision/pole.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace flagsim {
namespace {

PoleParams pole() {
  PoleParams p;
  p.radius = 0.05;
  p.height = 2.0;
  p.base = Vec3(0.0, -1.0, 0.0);
  return p;
}

double radial(const PoleParams& p, const MatX3& x, Index i) {
  return std::hypot(x(i, 0) - p.base.x(), x(i, 2) - p.base.z());
}

TEST(Pole, VertexEndingInsideSlidesOnTheSurfaceWithoutInwardVelocity) {
  const PoleParams p = pole();
  MatX3 x0(1, 3), x(1, 3), v(1, 3);
  x0 << -0.2, 0.0, 0.01;
  x << -0.02, 0.0, 0.03;  // inside
  v << 18.0, 0.0, 2.0;
  const VecX w = VecX::Ones(1);
  EXPECT_EQ(collide_pole(p, x0, x, v, w), 1);
  EXPECT_FALSE(inside_pole(p, x.row(0).transpose()));
  // Stopped where it entered, then slid in the tangent plane there (outside the cylinder).
  EXPECT_GE(radial(p, x, 0), p.radius);
  EXPECT_LT(radial(p, x, 0), 1.05 * p.radius);
  EXPECT_LT(x(0, 0), 0.0);  // stayed on the side it came from
  const Vec3 n = Vec3(x(0, 0), 0, x(0, 2)).normalized();
  EXPECT_GE(v.row(0).dot(n.transpose()), -1e-12);
  EXPECT_GT(v.row(0).norm(), 0.1);  // the tangential part is kept
}

TEST(Pole, ThirtyMetresPerSecondDoesNotTunnel) {
  const PoleParams p = pole();
  // 30 m/s for 0.01 s: 0.3 m, six radii, straight through the axis.
  MatX3 x0(1, 3), x(1, 3), v(1, 3);
  x0 << -0.15, 0.2, 0.0;
  x << 0.15, 0.2, 0.0;
  v << 30.0, 0.0, 0.0;
  EXPECT_EQ(collide_pole(p, x0, x, v, VecX::Ones(1)), 1);
  EXPECT_LT(x(0, 0), -p.radius * (1 - 1e-9));  // stopped on the entry side
  EXPECT_NEAR(x(0, 0), -p.radius, 1e-8);
  EXPECT_NEAR(v(0, 0), 0.0, 1e-12);
}

TEST(Pole, CapsPinsAndOutsidePathsAreRespected) {
  const PoleParams p = pole();
  MatX3 x0(3, 3), x(3, 3), v = MatX3::Zero(3, 3);
  x0 << 0.01, 1.2, 0.0,  // above the top cap, falls into it
      0.0, 0.0, 0.0,     // pinned on the axis (inside): left alone
      0.3, 0.0, 0.0;     // passes beside the pole
  x << 0.01, 0.95, 0.0, 0.0, 0.0, 0.0, 0.3, 0.0, 0.4;
  v.row(0) << 0, -25, 0;
  VecX w(3);
  w << 1, 0, 1;
  const MatX3 before = x;
  EXPECT_EQ(collide_pole(p, x0, x, v, w), 1);
  EXPECT_NEAR(x(0, 1), 1.0, 1e-8);
  EXPECT_GE(x(0, 1), 1.0);
  EXPECT_GE(v(0, 1), 0.0);
  EXPECT_EQ(x.row(1), before.row(1));
  EXPECT_EQ(x.row(2), before.row(2));
}

// Paths beside the pole's bounding box are left alone without the entry test; paths that reach
// into the box are tested in full: one that cuts the cylinder's rim diagonally (its end in the
// box's corner, outside the cylinder) is stopped, one that only skims the box's corner past the
// cylinder and one just outside the box are not.
TEST(Pole, PathsNearTheBoundingBoxAreTestedInFull) {
  const PoleParams p = pole();
  const double R = p.radius;
  MatX3 x0(4, 3), x(4, 3), v = MatX3::Zero(4, 3);
  x0 << -0.2, 0.0, -0.2,   // diagonally through the rim, ends in the box's corner outside
      -0.2, 0.0, 0.9 * R,  // along x, 0.9 R to the side: through the cylinder near its edge
      0.9 * R, 0.0, -0.2,  // along z at x = 0.9 R, stops short of the cylinder in the corner
      -0.2, 0.0, 1.001 * R + 1e-6;  // along x just outside the grown box
  x << 0.9 * R, 0.0, 0.9 * R,       // (0.9 R, 0.9 R): 1.27 R from the axis, outside the cylinder
      0.2, 0.0, 0.9 * R,            //
      0.9 * R, 0.0, -0.7 * R,       // radius 1.14 R
      0.2, 0.0, 1.001 * R + 1e-6;
  v.col(0).setConstant(1.0);
  const MatX3 before = x;
  EXPECT_EQ(collide_pole(p, x0, x, v, VecX::Ones(4)), 2);
  EXPECT_NE(x.row(0), before.row(0));  // stopped where it entered the side
  EXPECT_NE(x.row(1), before.row(1));
  EXPECT_EQ(x.row(2), before.row(2));
  EXPECT_EQ(x.row(3), before.row(3));
  for (Index i = 0; i < 4; ++i) EXPECT_FALSE(inside_pole(p, x.row(i).transpose())) << i;
}

TEST(Pole, NoVertexInsideAfterRandomFastMotion) {
  const PoleParams p = pole();
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(-0.4, 0.4);
  const Index n = 4000;
  MatX3 x0(n, 3), x(n, 3), v(n, 3);
  for (Index i = 0; i < n; ++i) {
    do x0.row(i) << u(rng), u(rng), u(rng);
    while (inside_pole(p, x0.row(i).transpose()));
    v.row(i) << 30 * u(rng), 30 * u(rng), 30 * u(rng);
    x.row(i) = x0.row(i) + 0.01 * v.row(i);
  }
  collide_pole(p, x0, x, v, VecX::Ones(n));
  for (Index i = 0; i < n; ++i) EXPECT_FALSE(inside_pole(p, x.row(i).transpose())) << i;
}

// A pole moving at U into a vertex at rest stops it against its surface: the vertex leaves with
// the surface's normal velocity U, kinetic energy m U^2 / 2, and the pole did m dv . U = m U^2 of
// work on it (the rest is the inelastic stop), which collide_pole reports for the ledger's `pins`
// as collide_solid does for a moving solid.
TEST(Pole, AMovingPoleReportsItsWorkOnTheVerticesItStops) {
  const PoleParams p = pole();
  const double U = 2.0, h = 0.01, m = 0.3;
  RigidMotion motion;
  motion.h = h;
  motion.to.t = Vec3(U * h, 0.0, 0.0);
  MatX3 x0(2, 3), x(2, 3), v = MatX3::Zero(2, 3);
  x0 << 0.06, 0.0, 0.0,  // 1 cm ahead of the surface: the pole's 2 cm reach it
      -0.5, 0.0, 0.0;    // far behind: left alone
  x = x0;
  const VecX w = VecX::Constant(2, 1 / m), mass = VecX::Constant(2, m);
  double work = 0;
  EXPECT_EQ(collide_pole(p, x0, x, v, w, nullptr, &motion, &mass, &work), 1);
  EXPECT_NEAR(v(0, 0), U, 1e-12);
  EXPECT_NEAR(x(0, 0), U * h + p.radius, 1e-3 * p.radius);  // on the surface where it ends
  EXPECT_NEAR(work, m * U * U, 1e-12);
  EXPECT_GE(work, 0.5 * m * v.row(0).squaredNorm());
  // At rest the pole does no work, and asking for it changes nothing.
  MatX3 xs = x0, vs = MatX3::Zero(2, 3);
  xs(0, 0) = 0.04;  // inside
  double none = 0;
  EXPECT_EQ(collide_pole(p, x0, xs, vs, w, nullptr, nullptr, &mass, &none), 1);
  EXPECT_EQ(none, 0.0);
}

// In the frame a pole translating at U is at rest in (x0 carried to the piece's end, as
// self-collision's sweeps run), collide_pole_carried is collide_pole at rest moved along: the same
// positions shifted by the pole's end translation, the same velocities plus U, vertex by vertex
// (Galilean invariance, to round-off). A vertex entering the pole, one ending inside, one passing.
TEST(Pole, ACarriedPoleIsThePoleAtRestMovedAlong) {
  const PoleParams p = pole();
  const Vec3 U(5.0, 0.0, -1.0);
  const double h = 0.01, t = 0.37;
  RigidMotion motion;
  motion.h = h;
  motion.from.t = U * t;
  motion.to.t = U * (t + h);
  MatX3 x0(3, 3), x(3, 3), v(3, 3);
  x0 << -0.2, 0.0, 0.01, 0.1, 0.3, 0.0, 0.3, 0.0, 0.3;
  x << -0.02, 0.0, 0.03, -0.1, 0.3, 0.01, 0.35, 0.0, 0.3;
  v << 18.0, 0.0, 2.0, -20.0, 0.0, 1.0, 5.0, 0.0, 0.0;
  const VecX w = VecX::Ones(3);
  MatX3 xc = x, vc = v, x0c = x0;
  for (Index i = 0; i < 3; ++i) {
    x0c.row(i) += motion.to.t.transpose();
    xc.row(i) += motion.to.t.transpose();
    vc.row(i) += U.transpose();
  }
  EXPECT_EQ(collide_pole(p, x0, x, v, w), 2);
  EXPECT_EQ(collide_pole_carried(p, motion, x0c, xc, vc, w), 2);
  for (Index i = 0; i < 3; ++i) {
    EXPECT_NEAR((xc.row(i) - motion.to.t.transpose() - x.row(i)).norm(), 0, 1e-14) << i;
    EXPECT_NEAR((vc.row(i) - U.transpose() - v.row(i)).norm(), 0, 1e-12) << i;
  }
}

}  // namespace
}  // namespace flagsim
