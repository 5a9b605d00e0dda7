#include "collision/edge_edge.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "collision/self_collision.h"

namespace flagsim {
namespace {

// Closest distance between segments by dense sampling of both (test-side reference).
double sampled_segment_distance(const Vec3& p1, const Vec3& p2, const Vec3& q1, const Vec3& q2) {
  double best = 1e300;
  const int n = 400;
  for (int i = 0; i <= n; ++i) {
    const Vec3 p = p1 + (p2 - p1) * (double(i) / n);
    // exact distance from p to segment q (a point-segment distance is elementary)
    const Vec3 d = q2 - q1;
    const double s = std::clamp((p - q1).dot(d) / d.squaredNorm(), 0.0, 1.0);
    best = std::min(best, (p - (q1 + s * d)).norm());
  }
  return best;
}

TEST(EdgeEdge, ClosestParametersMatchSampling) {
  std::mt19937 rng(6);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int k = 0; k < 300; ++k) {
    const Vec3 p1(u(rng), u(rng), u(rng)), p2(u(rng), u(rng), u(rng)), q1(u(rng), u(rng), u(rng)),
        q2(u(rng), u(rng), u(rng));
    const Vec2 w = closest_segment_parameters(p1, p2, q1, q2);
    const double d = ((p1 + w[0] * (p2 - p1)) - (q1 + w[1] * (q2 - q1))).norm();
    EXPECT_LE(d, sampled_segment_distance(p1, p2, q1, q2) + 1e-12);
    EXPECT_GE(d, sampled_segment_distance(p1, p2, q1, q2) - 2.0 / 400);
  }
  // Parallel segments: any closest pair at the right distance.
  const Vec2 w =
      closest_segment_parameters(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 1, 0), Vec3(2, 1, 0));
  EXPECT_NEAR(
      ((Vec3(0, 0, 0) + w[0] * Vec3(1, 0, 0)) - (Vec3(0.5, 1, 0) + w[1] * Vec3(1.5, 0, 0))).norm(),
      1.0, 1e-12);
}

TEST(EdgeEdge, CrossingEdgesAreFoundAtTheirTime) {
  double t;
  Vec2 su;
  // Edge q (along y, z = 0.1) moves down to z = -0.2 through edge p (along x, z = 0).
  const Vec3 p1(-1, 0, 0), p2(1, 0, 0), q1(0.2, -1, 0.1), q2(0.2, 1, 0.1), down(0, 0, -0.3);
  ASSERT_TRUE(edge_edge_ccd(p1, p2, q1, q2, p1, p2, q1 + down, q2 + down, t, su));
  EXPECT_NEAR(t, 1.0 / 3.0, 1e-12);
  EXPECT_NEAR(su[0], 0.6, 1e-9);
  EXPECT_NEAR(su[1], 0.5, 1e-9);
  // Passing beside the other edge's end: no crossing.
  EXPECT_FALSE(edge_edge_ccd(p1, p2, Vec3(1.5, -1, 0.1), Vec3(1.5, 1, 0.1), p1, p2,
                             Vec3(1.5, -1, -0.2), Vec3(1.5, 1, -0.2), t, su));
  // Parallel edges moving through each other's line: skipped (no single crossing point).
  EXPECT_FALSE(edge_edge_ccd(p1, p2, Vec3(-1, 0, 0.1), Vec3(1, 0, 0.1), p1, p2, Vec3(-1, 0, -0.1),
                             Vec3(1, 0, -0.1), t, su));
}

TEST(EdgeEdge, SelfCollisionStopsAnEdgeDrivenThroughAnEdgeAt30MetresPerSecond) {
  // Two vertical triangles in an X: triangle 0 in the plane y = 0 hanging below the x axis,
  // triangle 1 in the plane x = 0.2 above; triangle 1 falls at 30 m/s so its bottom edge passes
  // through triangle 0's top edge while no vertex ever passes through a triangle.
  MatX3 x0(6, 3);
  x0 << -1, 0, 0, 1, 0, 0, 0, 0, -1,  //
      0.2, -1, 0.1, 0.2, 1, 0.1, 0.2, 0, 1.1;
  MatX3i tris(2, 3);
  tris << 0, 1, 2, 3, 4, 5;
  MatX3 v = MatX3::Zero(6, 3);
  v.bottomRows(3).col(2).setConstant(-30.0);
  MatX3 x = x0 + 0.01 * v;
  VecX w = VecX::Ones(6);
  w.head(3).setZero();  // triangle 0 held
  SelfCollisionParams p;
  p.enabled = true;
  SelfCollision collide(tris, 6, p);
  const auto& st = collide.resolve(x0, x, v, w);
  double t;
  Vec2 su;
  EXPECT_FALSE(edge_edge_ccd(x0.row(0).transpose(), x0.row(1).transpose(), x0.row(3).transpose(),
                             x0.row(4).transpose(), x.row(0).transpose(), x.row(1).transpose(),
                             x.row(3).transpose(), x.row(4).transpose(), t, su));
  EXPECT_GE(st.crossings, 1);
  EXPECT_EQ(st.frozen, 0);
  // Stopped the thickness above the held edge, moving no more towards it.
  EXPECT_NEAR(x(3, 2), p.thickness, 1e-6);
  EXPECT_NEAR(x(4, 2), p.thickness, 1e-6);
  EXPECT_GE(v(3, 2), -1e-9);
  EXPECT_EQ(collide.edges().rows(), 6);
}

}  // namespace
}  // namespace flagsim
