#include "collision/vertex_triangle.h"

#include <gtest/gtest.h>

#include <random>

#include "crossing_checker.h"

namespace flagsim {
namespace {

const Vec3 A(0, 0, 0), B(1, 0, 0), C(0, 1, 0);

TEST(ClosestPoint, FaceEdgeAndVertexRegions) {
  bool interior;
  Vec3 b = closest_point_barycentric(Vec3(0.25, 0.25, 0.7), A, B, C, interior);
  EXPECT_TRUE(interior);
  EXPECT_TRUE(b.isApprox(Vec3(0.5, 0.25, 0.25)));
  b = closest_point_barycentric(Vec3(0.5, -0.3, 0.1), A, B, C, interior);  // edge AB
  EXPECT_FALSE(interior);
  EXPECT_TRUE(b.isApprox(Vec3(0.5, 0.5, 0.0)));
  b = closest_point_barycentric(Vec3(0.8, 0.8, -0.2), A, B, C, interior);  // edge BC
  EXPECT_TRUE(b.isApprox(Vec3(0.0, 0.5, 0.5)));
  b = closest_point_barycentric(Vec3(-0.5, -0.5, 0.3), A, B, C, interior);  // vertex A
  EXPECT_TRUE(b.isApprox(Vec3(1, 0, 0)));
  b = closest_point_barycentric(Vec3(2.0, -0.1, 0.0), A, B, C, interior);  // vertex B
  EXPECT_TRUE(b.isApprox(Vec3(0, 1, 0)));
  // Against the independent distance on random points.
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  for (int k = 0; k < 2000; ++k) {
    const Vec3 p(u(rng), u(rng), u(rng)), a(u(rng), u(rng), u(rng)), bb(u(rng), u(rng), u(rng)),
        c(u(rng), u(rng), u(rng));
    const Vec3 w = closest_point_barycentric(p, a, bb, c, interior);
    const double d = (p - (w[0] * a + w[1] * bb + w[2] * c)).norm();
    EXPECT_NEAR(d, test_support::point_triangle_distance(p, a, bb, c), 1e-12);
  }
}

TEST(Ccd, VertexThroughTheFaceHitsAtTheCrossingTime) {
  double t;
  Vec3 bary;
  // p goes from z = 0.3 to z = -0.1: plane at t = 0.75, at (0.2, 0.3).
  ASSERT_TRUE(
      vertex_triangle_ccd(Vec3(0.2, 0.3, 0.3), A, B, C, Vec3(0.2, 0.3, -0.1), A, B, C, t, bary));
  EXPECT_NEAR(t, 0.75, 1e-12);
  EXPECT_TRUE(bary.isApprox(Vec3(0.5, 0.2, 0.3), 1e-12));
  // Beside the triangle: no hit.
  EXPECT_FALSE(
      vertex_triangle_ccd(Vec3(0.8, 0.8, 0.3), A, B, C, Vec3(0.8, 0.8, -0.1), A, B, C, t, bary));
  // Stops short of the plane: no hit.
  EXPECT_FALSE(
      vertex_triangle_ccd(Vec3(0.2, 0.2, 0.3), A, B, C, Vec3(0.2, 0.2, 1e-6), A, B, C, t, bary));
  // The triangle sweeps through a resting vertex.
  const Vec3 up(0, 0, 1);
  ASSERT_TRUE(vertex_triangle_ccd(Vec3(0.1, 0.1, 0.5), A, B, C, Vec3(0.1, 0.1, 0.5), A + up, B + up,
                                  C + up, t, bary));
  EXPECT_NEAR(t, 0.5, 1e-12);
}

TEST(Ccd, AgreesWithTheSamplingChecker) {
  // Random rotating and translating triangles and vertices: every crossing the independent
  // sampler finds, the cubic finds too (the cubic may also find double crossings it misses).
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  MatX3i tri(1, 3);
  tri << 1, 2, 3;
  int found = 0, through_and_back = 0;
  for (int k = 0; k < 3000; ++k) {
    MatX3 x0(4, 3), x1(4, 3);
    for (int i = 0; i < 4; ++i) {
      x0.row(i) << u(rng), u(rng), u(rng);
      x1.row(i) = x0.row(i) + 0.8 * Eigen::RowVector3d(u(rng), u(rng), u(rng));
    }
    const long sampled = test_support::count_crossings(x0, x1, tri, 64);
    double t;
    Vec3 bary;
    const bool hit =
        vertex_triangle_ccd(x0.row(0).transpose(), x0.row(1).transpose(), x0.row(2).transpose(),
                            x0.row(3).transpose(), x1.row(0).transpose(), x1.row(1).transpose(),
                            x1.row(2).transpose(), x1.row(3).transpose(), t, bary);
    if (sampled) {
      EXPECT_TRUE(hit) << "case " << k;
      ++found;
      const Eigen::Vector4d f =
          coplanarity_cubic(x0.row(0).transpose(), x0.row(1).transpose(), x0.row(2).transpose(),
                            x0.row(3).transpose(), x1.row(0).transpose(), x1.row(1).transpose(),
                            x1.row(2).transpose(), x1.row(3).transpose());
      through_and_back += (f[0] > 0) == (f.sum() > 0);  // same side at both ends
    }
    if (hit) {
      EXPECT_GE(t, 0.0);
      EXPECT_LE(t, 1.0);
      EXPECT_GE(bary.minCoeff(), -1e-9);
    }
  }
  EXPECT_GT(found, 100);           // the sample exercises real crossings
  EXPECT_GT(through_and_back, 0);  // including through-and-back ones, invisible at the ends
}

}  // namespace
}  // namespace flagsim
