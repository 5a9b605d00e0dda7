#include "collision/candidates.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <utility>
#include <vector>

#include "common/simd.h"
#include "crossing_checker.h"

namespace flagsim {
namespace {

using test_support::make_grid;

using PairList = std::vector<std::pair<int32_t, int32_t>>;

PairList as_list(const std::vector<CandidatePair>& pairs) {
  PairList out;
  for (const CandidatePair& p : pairs) out.emplace_back(p.a, p.b);
  return out;
}

void expect_same_pairs(const Candidates& got, const Candidates& want, const char* what) {
  EXPECT_EQ(as_list(got.pairs().vertex_triangle), as_list(want.pairs().vertex_triangle)) << what;
  EXPECT_EQ(as_list(got.pairs().edge_edge), as_list(want.pairs().edge_edge)) << what;
}

// A 12 x 16 sheet (5 cm, thickness 5 mm: the paper's ratio), every vertex jittered by up to
// 0.5 mm per coordinate, differently at each step k.
struct JitteredSheet {
  static constexpr double kThickness = 0.005;
  MatX3 rest;
  MatX3i tris;
  VecX w;
  JitteredSheet() {
    rest.resize(0, 3);
    tris.resize(0, 3);
    make_grid(12, 16, Vec3::Zero(), Vec3(0.05, 0, 0), Vec3(0, 0.05, 0), rest, tris);
    w = VecX::Ones(rest.rows());
  }
  MatX3 at(int k) const {
    MatX3 x = rest;
    for (Index i = 0; i < x.rows(); ++i)
      for (int d = 0; d < 3; ++d) x(i, d) += 0.0005 * std::sin(1.3 * double(i) + 2.1 * d + 0.7 * k);
    return x;
  }
};

TEST(Candidates, NeverPairsAVertexWithItsOwnTriangleNorEdgesSharingAVertex) {
  const JitteredSheet s;
  Candidates c(s.tris, s.rest.rows(), JitteredSheet::kThickness);
  c.collect(s.at(0), s.at(1), s.w, /*shifted=*/true);
  ASSERT_GT(c.pairs().vertex_triangle.size(), 0u);
  ASSERT_GT(c.pairs().edge_edge.size(), 0u);
  for (const CandidatePair& p : c.pairs().vertex_triangle)
    for (int k = 0; k < 3; ++k) EXPECT_NE(s.tris(p.b, k), p.a);
  const MatX2i& e = c.edges();
  for (const CandidatePair& p : c.pairs().edge_edge) {
    EXPECT_LT(p.a, p.b);
    const std::set<int32_t> four{e(p.a, 0), e(p.a, 1), e(p.b, 0), e(p.b, 1)};
    EXPECT_EQ(four.size(), 4u);
  }
  // Ordered by first item, then by second.
  const PairList vt = as_list(c.pairs().vertex_triangle), ee = as_list(c.pairs().edge_edge);
  EXPECT_TRUE(std::is_sorted(vt.begin(), vt.end()));
  EXPECT_TRUE(std::is_sorted(ee.begin(), ee.end()));
}

TEST(Candidates, PairsWithNoFreeVertexAreLeftOut) {
  const JitteredSheet s;
  Candidates c(s.tris, s.rest.rows(), JitteredSheet::kThickness);
  c.collect(s.at(0), s.at(1), VecX::Zero(s.rest.rows()), /*shifted=*/true);
  EXPECT_EQ(c.pairs().size(), 0u);
}

TEST(Candidates, MeshEdgesEachOnceLowerIndexFirst) {
  MatX3i tris(2, 3);
  tris << 0, 1, 2, 2, 1, 3;
  Candidates c(tris, 4, 0.01);
  MatX2i want(5, 2);
  want << 0, 1, 0, 2, 1, 2, 1, 3, 2, 3;
  EXPECT_EQ(c.edges(), want);
}

// Two triangles 1 mm apart (thickness 5 mm) are candidates; 10 cm apart they are not.
TEST(Candidates, ParallelTrianglesArePairedOnlyWhenClose) {
  MatX3i tris(2, 3);
  tris << 0, 1, 2, 3, 4, 5;
  for (const double gap : {0.001, 0.1}) {
    MatX3 x(6, 3);
    x << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, gap, 1, 0, gap, 0, 1, gap;
    Candidates c(tris, 6, 0.005);
    c.collect(x, x, VecX::Ones(6), /*shifted=*/true);
    EXPECT_EQ(c.pairs().vertex_triangle.size(), gap < 0.01 ? 6u : 0u) << gap;
    EXPECT_EQ(c.pairs().edge_edge.size(), gap < 0.01 ? 9u : 0u) << gap;
  }
}

TEST(Candidates, WithinBoxesAllowsOneThicknessOutsideTheSweptBox) {
  const JitteredSheet s;
  Candidates c(s.tris, s.rest.rows(), JitteredSheet::kThickness);
  const MatX3 x0 = s.rest;
  c.collect(x0, x0, s.w, /*shifted=*/false);
  MatX3 x = x0;
  x(5, 2) += 0.9 * JitteredSheet::kThickness;
  EXPECT_TRUE(c.within_boxes(x));
  x(5, 2) += 0.2 * JitteredSheet::kThickness;
  EXPECT_FALSE(c.within_boxes(x));
}

// The Verlet list: after the first (direct) queries it is built with a skin, then serves every
// collect while no vertex box has left its box at the build by more than the skin (3 mm extra on
// one vertex), and gives way to the trees when one has (7 mm), to be rebuilt after. Each collect
// gives exactly the pairs of a fresh object, which always queries the trees.
// The trees' candidates (queried in groups of neighbouring items) are exactly the pairs a test of
// every pair's boxes gives, in the documented order: a 12 x 16 sheet folded over itself (its two
// halves 3 mm apart, so far more pairs than mesh neighbours) and jittered, world frame.
TEST(Candidates, TreeQueriesGiveEveryPairWhoseBoxesMeetInOrder) {
  const JitteredSheet s;
  const double h = JitteredSheet::kThickness;
  auto folded = [&](int k) {
    MatX3 x = s.at(k);
    for (Index i = 0; i < x.rows(); ++i)
      if (x(i, 0) > 0.3) {  // fold at x = 0.3 m: the far part comes back 3 mm above
        x(i, 0) = 0.6 - x(i, 0);
        x(i, 2) += 0.003;
      }
    return x;
  };
  const MatX3 x0 = folded(0), x = folded(1);
  const Index N = x.rows(), T = s.tris.rows();
  auto box = [&](std::initializer_list<int32_t> vs, double grow, Vec3& lo, Vec3& hi) {
    lo = Vec3::Constant(1e300);
    hi = Vec3::Constant(-1e300);
    for (const int32_t v : vs) {
      lo = lo.cwiseMin(Vec3(x0.row(v))).cwiseMin(Vec3(x.row(v)));
      hi = hi.cwiseMax(Vec3(x0.row(v))).cwiseMax(Vec3(x.row(v)));
    }
    lo.array() -= grow;
    hi.array() += grow;
  };
  auto meet = [](const Vec3& a0, const Vec3& a1, const Vec3& b0, const Vec3& b1, double r) {
    return (b0.array() <= a1.array() + r).all() && (b1.array() >= a0.array() - r).all();
  };
  PairList vt, ee;
  for (Index i = 0; i < N; ++i)
    for (Index t = 0; t < T; ++t) {
      const int32_t a = s.tris(t, 0), b = s.tris(t, 1), c = s.tris(t, 2);
      if (a == i || b == i || c == i) continue;
      Vec3 v0, v1, t0, t1;
      box({int32_t(i)}, 0, v0, v1);
      box({a, b, c}, h, t0, t1);
      if (meet(v0, v1, t0, t1, 2 * h)) vt.emplace_back(int32_t(i), int32_t(t));
    }
  const MatX2i E = Candidates(s.tris, s.rest.rows(), h).edges();
  for (Index e = 0; e < E.rows(); ++e)
    for (Index f = e + 1; f < E.rows(); ++f) {
      const int32_t a = E(e, 0), b = E(e, 1), c = E(f, 0), d = E(f, 1);
      if (a == c || a == d || b == c || b == d) continue;
      Vec3 e0, e1, f0, f1;
      box({a, b}, h, e0, e1);
      box({c, d}, h, f0, f1);
      if (meet(e0, e1, f0, f1, h)) ee.emplace_back(int32_t(e), int32_t(f));
    }
  EXPECT_GT(vt.size(), size_t(4 * N)) << "the fold should pair far more than mesh neighbours";
  // At every vector width the queries' filter runs on (common/simd.h; 0: the widest).
  for (const int width : {0, 16}) {
    vector_bytes(width);
    Candidates got(s.tris, s.rest.rows(), h);
    got.collect(x0, x, s.w, /*shifted=*/false);
    vector_bytes(0);
    ASSERT_FALSE(got.from_list());
    EXPECT_EQ(as_list(got.pairs().vertex_triangle), vt) << "width " << width;
    EXPECT_EQ(as_list(got.pairs().edge_edge), ee) << "width " << width;
  }
}

TEST(Candidates, VerletListServesWhileNothingMovedMoreThanItsSkinAndIsRebuiltAfter) {
  const JitteredSheet s;
  const double h = JitteredSheet::kThickness;
  Candidates kept(s.tris, s.rest.rows(), h);
  int k = 0;
  auto collect = [&](double extra) {
    const MatX3 x0 = s.at(k);
    MatX3 x = s.at(k + 1);
    x(40, 2) += extra;
    ++k;
    kept.collect(x0, x, s.w, /*shifted=*/true);
    Candidates fresh(s.tris, s.rest.rows(), h);
    fresh.collect(x0, x, s.w, /*shifted=*/true);
    EXPECT_FALSE(fresh.from_list());
    expect_same_pairs(kept, fresh, "kept vs fresh");
  };
  while (kept.skin() == 0 && k < 100) {
    collect(0);
    EXPECT_FALSE(kept.from_list()) << "step " << k;
  }
  ASSERT_GT(kept.skin(), 0) << "the list was never built";
  EXPECT_DOUBLE_EQ(kept.skin(), h);  // slow motion: the smallest skin, one thickness
  for (int i = 0; i < 5; ++i) {
    collect(0);
    EXPECT_TRUE(kept.from_list()) << "step " << k;
  }
  collect(0.003);
  EXPECT_TRUE(kept.from_list()) << "3 mm is within the skin";
  collect(0.007);
  EXPECT_FALSE(kept.from_list()) << "7 mm is beyond the skin";
  // Rebuilt: once the motion is slow again (after at most a few direct queries if the fast step
  // counted as a miss), a new list serves.
  int waited = 0;
  do collect(0);
  while (!kept.from_list() && ++waited < 40);
  EXPECT_TRUE(kept.from_list());
}

}  // namespace
}  // namespace flagsim
