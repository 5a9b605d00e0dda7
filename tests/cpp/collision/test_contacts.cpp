#include "collision/contacts.h"

#include <gtest/gtest.h>

#include <cmath>

namespace flagsim {
namespace {

constexpr double kH = 0.005;  // thickness, m

void set(PairPoints& p, const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  p[0] = a, p[1] = b, p[2] = c, p[3] = d;
}

void expect_g(const Contact& ct, double g0, double g1, double g2, double g3) {
  EXPECT_NEAR(ct.g[0], g0, 1e-12);
  EXPECT_NEAR(ct.g[1], g1, 1e-12);
  EXPECT_NEAR(ct.g[2], g2, 1e-12);
  EXPECT_NEAR(ct.g[3], g3, 1e-12);
}

// Triangle (0,0,0), (1,0,0), (0,1,0) in z = 0; the vertex 3 mm above its point (0.2, 0.3):
// barycentric (0.5, 0.2, 0.3).
TEST(VertexTriangleContact, ProximityOverTheFaceHasTheFaceNormalAndBarycentricPoint) {
  PairPoints x;
  set(x, Vec3(0.2, 0.3, 0.003), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  Contact ct;
  VertexTriangleContact::detect(x, x, kH, ct);
  ASSERT_EQ(ct.kind, Contact::kProximity);
  EXPECT_NEAR((ct.n - Vec3(0, 0, 1)).norm(), 0, 1e-12);
  expect_g(ct, 1, -0.5, -0.2, -0.3);
  EXPECT_NEAR(ct.C, 0.003 - kH, 1e-15);
  EXPECT_NEAR(VertexTriangleContact::distance(x), 0.003, 1e-15);
  EXPECT_TRUE(VertexTriangleContact::closer_than(x, kH));
  EXPECT_FALSE(VertexTriangleContact::closer_than(x, 0.5 * kH));
}

// The vertex 3 mm beside edge ca, level with its midpoint (0, 0.5, 0): the closest point is on
// the edge, the direction along -x.
TEST(VertexTriangleContact, ProximityBesideAnEdgeUsesTheEdgePoint) {
  PairPoints x;
  set(x, Vec3(-0.003, 0.5, 0), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  Contact ct;
  VertexTriangleContact::detect(x, x, kH, ct);
  ASSERT_EQ(ct.kind, Contact::kProximity);
  EXPECT_NEAR((ct.n - Vec3(-1, 0, 0)).norm(), 0, 1e-12);
  expect_g(ct, 1, -0.5, 0, -0.5);
  EXPECT_NEAR(VertexTriangleContact::distance(x), 0.003, 1e-15);
}

// The vertex falls from 10 cm above (0.2, 0.3) to 10 cm below: it crosses at t = 0.5, and is
// the thickness above the face at t = 0.475.
TEST(VertexTriangleContact, CrossingAtTheKnownTimeAndPoint) {
  PairPoints x0, x1;
  set(x0, Vec3(0.2, 0.3, 0.1), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  set(x1, x0[0], x0[1], x0[2], x0[3]);
  x1[0].z() = -0.1;
  double t;
  ASSERT_TRUE(VertexTriangleContact::crossing(x0, x1, t));
  EXPECT_NEAR(t, 0.5, 1e-12);
  EXPECT_NEAR(VertexTriangleContact::separation(x0, x1, t, kH), 0.475, 1e-8);
  Contact ct;
  VertexTriangleContact::detect(x0, x1, kH, ct);
  ASSERT_EQ(ct.kind, Contact::kCrossing);
  EXPECT_NEAR((ct.n - Vec3(0, 0, 1)).norm(), 0, 1e-12);  // towards the side it came from
  expect_g(ct, 1, -0.5, -0.2, -0.3);
}

TEST(VertexTriangleContact, NothingBeyondTheThickness) {
  PairPoints x;
  set(x, Vec3(0.2, 0.3, 0.006), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  Contact ct;
  VertexTriangleContact::detect(x, x, kH, ct);
  EXPECT_EQ(ct.kind, Contact::kNone);
  double t;
  EXPECT_FALSE(VertexTriangleContact::crossing(x, x, t));
  EXPECT_FALSE(VertexTriangleContact::closer_than(x, kH));
}

// Edge (0,0,3 mm) - (1,0,3 mm) along x over edge (0.5,-0.5,0) - (0.5,0.5,0) along y: closest at
// the middle of both (s = u = 0.5), 3 mm apart along +z.
TEST(EdgeEdgeContact, ProximityOfCrossedEdgesAtTheirMidpoints) {
  PairPoints x;
  set(x, Vec3(0, 0, 0.003), Vec3(1, 0, 0.003), Vec3(0.5, -0.5, 0), Vec3(0.5, 0.5, 0));
  Contact ct;
  EdgeEdgeContact::detect(x, x, kH, ct);
  ASSERT_EQ(ct.kind, Contact::kProximity);
  EXPECT_NEAR((ct.n - Vec3(0, 0, 1)).norm(), 0, 1e-12);
  expect_g(ct, 0.5, 0.5, -0.5, -0.5);
  EXPECT_NEAR(ct.C, 0.003 - kH, 1e-15);
  EXPECT_NEAR(EdgeEdgeContact::distance(x), 0.003, 1e-15);
  // Edges alone never trip the fallback by proximity.
  EXPECT_FALSE(EdgeEdgeContact::closer_than(x, kH));
}

// The upper edge at the quarter point of the lower: (s, u) = (0.25, 0.75) after moving it.
TEST(EdgeEdgeContact, CrossingAtTheKnownTimeAndPoints) {
  PairPoints x0, x1;
  set(x0, Vec3(0.5, 0.25, 0.1), Vec3(0.5, 1.25, 0.1), Vec3(0, 0.5, 0), Vec3(1, 0.5, 0));
  set(x1, x0[0], x0[1], x0[2], x0[3]);
  x1[0].z() = x1[1].z() = -0.1;
  double t;
  ASSERT_TRUE(EdgeEdgeContact::crossing(x0, x1, t));
  EXPECT_NEAR(t, 0.5, 1e-12);
  EXPECT_NEAR(EdgeEdgeContact::separation(x0, x1, t, kH), 0.475, 1e-8);
  Contact ct;
  EdgeEdgeContact::detect(x0, x1, kH, ct);
  ASSERT_EQ(ct.kind, Contact::kCrossing);
  EXPECT_NEAR(std::abs(ct.n.z()), 1, 1e-12);
  EXPECT_GT(ct.n.z(), 0);  // towards the side the first edge came from
  expect_g(ct, 0.75, 0.25, -0.5, -0.5);
}

TEST(EdgeEdgeContact, NothingBeyondTheThickness) {
  PairPoints x;
  set(x, Vec3(0, 0, 0.006), Vec3(1, 0, 0.006), Vec3(0.5, -0.5, 0), Vec3(0.5, 0.5, 0));
  Contact ct;
  EdgeEdgeContact::detect(x, x, kH, ct);
  EXPECT_EQ(ct.kind, Contact::kNone);
}

// reach: the largest relative displacement between the two sides; motion_bound bounds it from
// the vertices' own displacements.
TEST(Contacts, ReachIsTheLargestRelativeDisplacementAndMotionBoundsIt) {
  PairPoints d;
  set(d, Vec3(1, 0, 0), Vec3(0, 0, 0), Vec3(-1, 0, 0), Vec3(0, 2, 0));
  const int32_t idx[4] = {0, 1, 2, 3};
  const double m[4] = {d[0].norm(), d[1].norm(), d[2].norm(), d[3].norm()};
  EXPECT_DOUBLE_EQ(VertexTriangleContact::reach(d), std::sqrt(5.0));  // vertex against corner 3
  EXPECT_DOUBLE_EQ(VertexTriangleContact::motion_bound(m, idx), 3);
  EXPECT_DOUBLE_EQ(EdgeEdgeContact::reach(d), std::sqrt(5.0));  // corners 0 and 3
  EXPECT_DOUBLE_EQ(EdgeEdgeContact::motion_bound(m, idx), 3);
  set(d, Vec3(1, 0, 0), Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(-2, 0, 0));
  EXPECT_DOUBLE_EQ(EdgeEdgeContact::reach(d), 3);  // corners 0 and 3
  EXPECT_DOUBLE_EQ(VertexTriangleContact::reach(d), 3);
}

TEST(Contacts, CornersOfAVertexTrianglePairAndAnEdgePair) {
  MatX3i tris(2, 3);
  tris << 0, 1, 2, 2, 1, 3;
  const Candidates mesh(tris, 4, kH);  // edges (0,1) (0,2) (1,2) (1,3) (2,3)
  int32_t idx[4];
  VertexTriangleContact::corners(mesh, CandidatePair{3, 0}, idx);
  EXPECT_EQ(idx[0], 3);
  EXPECT_EQ(idx[1], 0);
  EXPECT_EQ(idx[2], 1);
  EXPECT_EQ(idx[3], 2);
  EdgeEdgeContact::corners(mesh, CandidatePair{1, 3}, idx);
  EXPECT_EQ(idx[0], 0);
  EXPECT_EQ(idx[1], 2);
  EXPECT_EQ(idx[2], 1);
  EXPECT_EQ(idx[3], 3);
}

}  // namespace
}  // namespace flagsim
