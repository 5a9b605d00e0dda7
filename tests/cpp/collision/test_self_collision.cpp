#include "collision/self_collision.h"

#include <gtest/gtest.h>

#include <random>

#include "collision/pole.h"
#include "common/parallel.h"
#include "crossing_checker.h"

namespace flagsim {
namespace {

using test_support::count_crossings;
using test_support::make_grid;
using test_support::min_distance_nonadjacent;

SelfCollisionParams params(double thickness = 0.005, double friction = 0.0, int iterations = 8) {
  SelfCollisionParams p;
  p.enabled = true;
  p.thickness = thickness;
  p.friction = friction;
  p.iterations = iterations;
  return p;
}

// One pinned triangle (vertices 1..3) in z = 0 and a free vertex 0 above it.
struct OneTriangle {
  MatX3 x0{4, 3}, x{4, 3}, v = MatX3::Zero(4, 3);
  MatX3i tris{1, 3};
  VecX w{4};
  OneTriangle() {
    x0 << 0.2, 0.3, 0.05, 0, 0, 0, 1, 0, 0, 0, 1, 0;
    tris << 1, 2, 3;
    w << 1, 0, 0, 0;
  }
};

TEST(SelfCollision, VertexDrivenThroughATriangleAt30MetresPerSecondStopsAtTheThickness) {
  OneTriangle s;
  s.v.row(0) << 0, 0, -30;
  s.x = s.x0 + 0.01 * s.v;  // ends 0.25 m below the triangle
  SelfCollision collide(s.tris, 4, params());
  const auto& stats = collide.resolve(s.x0, s.x, s.v, s.w);
  EXPECT_NEAR(s.x(0, 2), 0.005, 1e-9);  // stopped on its way down, the thickness above
  EXPECT_EQ(s.x(0, 0), 0.2);
  EXPECT_EQ(s.x(0, 1), 0.3);
  EXPECT_EQ(s.v(0, 2), 0.0);
  EXPECT_EQ(s.x.bottomRows(3), s.x0.bottomRows(3));  // pinned
  EXPECT_GE(stats.crossings, 1);
  EXPECT_EQ(stats.frozen, 0);
}

// A triangle that collapses to a point over the step, onto which the vertex lands: no contact
// has a normal to push along (detect leaves it), so the fallback must still see the vertex on
// the triangle and freeze the four of them at x0.
TEST(SelfCollision, VertexLandingOnATriangleCollapsedToAPointIsFrozen) {
  OneTriangle s;
  s.w.setOnes();
  for (int i = 0; i < 4; ++i) s.x.row(i) << 0.2, 0.3, 0.0;
  s.v = (s.x - s.x0) / 0.01;
  SelfCollision collide(s.tris, 4, params());
  const auto& stats = collide.resolve(s.x0, s.x, s.v, s.w);
  EXPECT_EQ(stats.contacts + stats.crossings, 0);  // nothing detect could respond to
  EXPECT_EQ(stats.frozen, 4);
  EXPECT_EQ(s.x, s.x0);
}

TEST(SelfCollision, FreeTriangleSharesThePushByMassAndKeepsMomentum) {
  OneTriangle s;
  s.w << 1.0, 2.0, 2.0, 2.0;  // vertex 1 kg, triangle corners 0.5 kg
  s.v.row(0) << 0, 0, -30;
  s.v.bottomRows(3).col(2).setConstant(5.0);
  s.x = s.x0 + 0.01 * s.v;
  auto momentum = [&] {
    Vec3 m = Vec3::Zero();
    for (int i = 0; i < 4; ++i) m += s.v.row(i).transpose() / s.w[i];
    return m;
  };
  const Vec3 before = momentum();
  SelfCollision collide(s.tris, 4, params());
  collide.resolve(s.x0, s.x, s.v, s.w);
  EXPECT_TRUE(momentum().isApprox(before, 1e-12));
  // The vertex ends the thickness from the (now tilted) triangle, over its face, and does not
  // approach it any more.
  const Vec3 p = s.x.row(0).transpose(), a = s.x.row(1).transpose(), b = s.x.row(2).transpose(),
             c = s.x.row(3).transpose();
  ASSERT_TRUE(test_support::projects_inside(p, a, b, c));
  EXPECT_NEAR(test_support::plane_distance(p, a, b, c), 0.005, 1e-9);
  const Vec3 n = (b - a).cross(c - a).normalized();
  const double nn = (b - a).cross(c - a).squaredNorm();
  const double wa = (b - p).cross(c - p).dot((b - a).cross(c - a)) / nn;
  const double wb = (c - p).cross(a - p).dot((b - a).cross(c - a)) / nn;
  const Vec3 vq = wa * s.v.row(1).transpose() + wb * s.v.row(2).transpose() +
                  (1 - wa - wb) * s.v.row(3).transpose();
  EXPECT_GE((s.v.row(0).transpose() - vq).dot(n), -1e-9);
  EXPECT_LT(s.x(1, 2), s.x0(1, 2) + 0.05);  // the triangle was pushed down by the vertex
}

TEST(SelfCollision, CoulombFrictionTakesMuTimesTheNormalImpulse) {
  OneTriangle s;
  s.x0(0, 2) = 0.004;  // already within the thickness
  s.v.row(0) << 5, 0, -10;
  s.x = s.x0;  // a contact at rest position: only the velocity matters
  SelfCollision collide(s.tris, 4, params(0.005, 0.3));
  collide.resolve(s.x0, s.x, s.v, s.w);
  EXPECT_NEAR(s.v(0, 2), 0.0, 1e-12);
  EXPECT_NEAR(s.v(0, 0), 5 - 0.3 * 10, 1e-12);
  EXPECT_NEAR(s.x(0, 2), 0.005, 1e-12);
}

TEST(SelfCollision, NeverTestsAVertexAgainstItsOwnTriangles) {
  MatX3 x0(3, 3), v(3, 3);
  x0 << 0, 0, 0, 0.01, 0, 0, 0, 0.01, 0;  // a tiny triangle, all vertices within thickness
  MatX3i tris(1, 3);
  tris << 0, 1, 2;
  v << 0, 0, 3, 0, 0, -3, 1, 0, 0;
  MatX3 x = x0 + 0.01 * v;
  const MatX3 expected = x, v0 = v;
  SelfCollision collide(tris, 3, params());
  const auto& stats = collide.resolve(x0, x, v, VecX::Ones(3));
  EXPECT_EQ(stats.candidates, 0);
  EXPECT_EQ(x, expected);
  EXPECT_EQ(v, v0);
}

// Kinematic steps (x += v dt, v += g dt) of a set of sheets through the collision stage, checked
// by the independent crossing counter and distance after every step.
struct KinematicRun {
  long crossings = 0;
  double min_distance = 1e9;
  SelfCollisionStats totals;
  MatX3 x;
};

KinematicRun run(MatX3 x, MatX3 v, const MatX3i& tris, const VecX& w, const SelfCollisionParams& p,
                 int steps, const PoleParams* pole = nullptr) {
  KinematicRun out;
  SelfCollision collide(tris, x.rows(), p);
  const double dt = 0.01;
  const Vec3 g(0, 0, -9.81);
  for (int s = 0; s < steps; ++s) {
    const MatX3 x0 = x;
    for (Index i = 0; i < x.rows(); ++i)
      if (w[i] > 0) v.row(i) += dt * g.transpose();
    for (Index i = 0; i < x.rows(); ++i) x.row(i) += (w[i] > 0 ? dt : 0.0) * v.row(i);
    const auto& st = collide.resolve(x0, x, v, w, pole);
    out.totals.crossings += st.crossings;
    out.totals.contacts += st.contacts;
    out.totals.frozen += st.frozen;
    out.crossings += count_crossings(x0, x, tris);
    out.min_distance = std::min(out.min_distance, min_distance_nonadjacent(x, tris));
  }
  out.x = x;
  return out;
}

// Sheet A pinned in z = 0 (11 x 11, 5 cm), sheet B (8 x 8) 4 cm above, offset by half a cell,
// falling at 30 m/s with random jitter (+-3 m/s vertical, +-0.6 m/s sideways, so that every
// vertex stays over sheet A).
void two_sheets(MatX3& x, MatX3& v, MatX3i& tris, VecX& w) {
  x.resize(0, 3);
  tris.resize(0, 3);
  make_grid(11, 11, Vec3(0, 0, 0), Vec3(0.05, 0, 0), Vec3(0, 0.05, 0), x, tris);
  const Index nA = x.rows();
  make_grid(8, 8, Vec3(0.075, 0.075, 0.04), Vec3(0.05, 0, 0), Vec3(0, 0.05, 0), x, tris);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> jitter(-3, 3);
  v = MatX3::Zero(x.rows(), 3);
  w = VecX::Ones(x.rows());
  w.head(nA).setZero();
  for (Index i = nA; i < x.rows(); ++i)
    v.row(i) << 0.2 * jitter(rng), 0.2 * jitter(rng), -30 + jitter(rng);
}

TEST(SelfCollision, SheetFallingThroughASheetAt30MetresPerSecondNeverCrosses) {
  MatX3 x, v;
  MatX3i tris;
  VecX w;
  two_sheets(x, v, tris, w);
  const KinematicRun r = run(x, v, tris, w, params(), 8);
  EXPECT_EQ(r.crossings, 0);
  EXPECT_GE(r.min_distance, 0.0025);
  EXPECT_GT(r.totals.crossings, 0);  // the response was exercised
  for (Index i = 121; i < r.x.rows(); ++i) EXPECT_GT(r.x(i, 2), 0.0) << i;
}

TEST(SelfCollision, OneSweepStillNeverCrossesThroughTheFallback) {
  MatX3 x, v;
  MatX3i tris;
  VecX w;
  two_sheets(x, v, tris, w);
  const KinematicRun r = run(x, v, tris, w, params(0.005, 0.0, 1), 8);
  EXPECT_EQ(r.crossings, 0);
  EXPECT_GE(r.min_distance, 0.0025);
}

// One 8 x 24 sheet folded over itself: columns 0..11 flat in z = 0, columns 12..23 back over
// them at z = 3 cm, shifted by half a cell; the upper layer is thrown down at 30 m/s and the
// lower one jitters; column 0 is pinned.
void folded(MatX3& x, MatX3& v, MatX3i& tris, VecX& w) {
  const int rows = 8, cols = 24;
  const double s = 0.04;
  x.resize(0, 3);
  tris.resize(0, 3);
  make_grid(rows, cols, Vec3::Zero(), Vec3(s, 0, 0), Vec3(0, s, 0), x, tris);
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> jitter(-1, 1);
  v = MatX3::Zero(x.rows(), 3);
  w = VecX::Ones(x.rows());
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const int i = r * cols + c;
      if (c >= 12) {
        x.row(i) << (23 - c) * s + 0.5 * s, r * s, 0.03;
        v.row(i) << 3 * jitter(rng), 3 * jitter(rng), -30 + 3 * jitter(rng);
      } else {
        v.row(i) << jitter(rng), jitter(rng), jitter(rng);
      }
      if (c == 0) w[i] = 0, v.row(i).setZero();
    }
}

TEST(SelfCollision, FoldedSheetThrownOntoItselfNeverCrosses) {
  MatX3 x, v;
  MatX3i tris;
  VecX w;
  folded(x, v, tris, w);
  ASSERT_GE(min_distance_nonadjacent(x, tris), 0.005);
  const KinematicRun r = run(x, v, tris, w, params(), 10);
  EXPECT_EQ(r.crossings, 0);
  EXPECT_GE(r.min_distance, 0.0025);
  EXPECT_GT(r.totals.crossings + r.totals.contacts, 0);
}

TEST(SelfCollision, ResultsDoNotDependOnTheThreadCount) {
  // A folded 48 x 96 sheet (4608 vertices): large enough that the broad phase and the pair loops
  // run on the OpenMP team.
  const int rows = 48, cols = 96;
  const double s = 0.01;
  MatX3 x(0, 3);
  MatX3i tris(0, 3);
  make_grid(rows, cols, Vec3::Zero(), Vec3(s, 0, 0), Vec3(0, s, 0), x, tris);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> jitter(-1, 1);
  MatX3 v = MatX3::Zero(x.rows(), 3);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const int i = r * cols + c;
      if (c >= cols / 2) {
        x.row(i) << (cols - 1 - c) * s + 0.5 * s, r * s, 0.02;
        v.row(i) << 0.2 * jitter(rng), 0.2 * jitter(rng), -3 + 0.2 * jitter(rng);
      }
    }
  const VecX w = VecX::Ones(x.rows());
  auto run_with = [&](int threads, SelfCollisionStats& st) {
    const int before = num_threads();
    set_num_threads(threads);
    SelfCollision collide(tris, x.rows(), params(0.003, 0.2));
    MatX3 xs = x, vs = v;
    for (int step = 0; step < 1; ++step) {
      const MatX3 x0 = xs;
      xs += 0.01 * vs;
      st = collide.resolve(x0, xs, vs, w);
    }
    set_num_threads(before);
    return xs;
  };
  SelfCollisionStats one_stats, two_stats;
  const MatX3 one = run_with(1, one_stats), two = run_with(2, two_stats);
  EXPECT_GE(one_stats.candidates, 4 * kParallelGrain) << "the pair loops should run in parallel";
  EXPECT_GT(one_stats.crossings + one_stats.contacts, 0);
  EXPECT_EQ(one, two);  // bitwise
}

constexpr double kPi = 3.14159265358979323846;

// The driven tests' mesh: a rows x cols sheet of spacing s in z = 0.
void flat_sheet(int rows, int cols, double s, MatX3& rest, MatX3i& tris) {
  rest.resize(0, 3);
  tris.resize(0, 3);
  make_grid(rows, cols, Vec3::Zero(), Vec3(s, 0, 0), Vec3(0, s, 0), rest, tris);
}

// A step's input driven to a target: v = (target - x0) / dt, x = x0 + dt v. Returns x0.
MatX3 drive(const MatX3& target, double dt, MatX3& x, MatX3& v) {
  const MatX3 x0 = x;
  v = (target - x0) / dt;
  x = x0 + dt * v;
  return x0;
}

// The pair list kept from step to step (a Verlet list) must give exactly the candidates a fresh
// query gives. A 12 x 16 sheet (5 cm, thickness 5 mm: the paper's ratio) is driven through a
// travelling wave with a sideways drift, with a burst of fast motion (steps 60-80: the list
// misses and the object falls back to direct queries); then the wave fades while a 3 x 3 patch
// (part of the same mesh) comes down from 10 cm to 4 mm above the sheet (steps 100-140) and
// slides along it (to step 300: contacts every step). Each step, one SelfCollision kept for the
// whole run and one made for that step alone (its first queries are direct) answer the same
// input: same positions, velocities and statistics, bit for bit. The same holds for the start
// gaps: the kept object bounds them from a snapshot of an earlier step, the new one computes
// every one it needs, and the answers must not differ.
TEST(SelfCollision, PairListGivesWhatAFreshQueryGives) {
  const int rows = 12, cols = 16;
  const double s = 0.05, dt = 0.01;
  MatX3 rest;
  MatX3i tris;
  flat_sheet(rows, cols, s, rest, tris);
  const Index sheet = rest.rows();
  make_grid(3, 3, Vec3(0.2, 0.2, 0.1), Vec3(0.04, 0, 0), Vec3(0, 0.04, 0), rest, tris);
  const VecX w = VecX::Ones(rest.rows());
  auto target = [&](int step) {
    const double t = step * dt;
    const double phase = step < 60   ? 1.5 * t
                         : step < 80 ? 1.5 * 0.6 + 12 * (t - 0.6)
                                     : 1.5 * (t - 0.2) + 9.6 * 0.2;
    const double wave = step < 100 ? 0.03 : std::max(0.0, 1 - (step - 100) / 40.0) * 0.03;
    const double height = step < 100 ? 0.1 : 0.004 + std::max(0.0, 1 - (step - 100) / 40.0) * 0.096;
    const double slide = step < 140 ? 0.0 : 0.1 * (step - 140) * dt;
    MatX3 x = rest;
    for (Index i = 0; i < x.rows(); ++i) {
      const double u = rest(i, 0);
      const Vec3 p = i < sheet ? Vec3(u, rest(i, 1),
                                      wave * std::sin(2 * kPi * (u / 0.4 - phase)) * u / (cols * s))
                               : Vec3(u + slide, rest(i, 1), height);
      x.row(i) = (p + Vec3(0, 0.5 * t, 0)).transpose();
    }
    return x;
  };
  SelfCollision kept(tris, rest.rows(), params());
  MatX3 x = target(0), v = MatX3::Zero(x.rows(), 3);
  int listed_steps = 0, listed_contacts = 0, direct_later = 0;
  int bounded_steps = 0, computed_with_contacts = 0;
  for (int step = 1; step <= 300; ++step) {
    const MatX3 x0 = drive(target(step), dt, x, v);
    MatX3 xf = x, vf = v;
    SelfCollision fresh(tris, rest.rows(), params());
    const SelfCollisionStats sf = fresh.resolve(x0, xf, vf, w);
    const SelfCollisionStats sk = kept.resolve(x0, x, v, w);
    ASSERT_EQ(sk.candidates, sf.candidates) << "step " << step;
    ASSERT_EQ(sk.contacts, sf.contacts) << "step " << step;
    ASSERT_EQ(sk.crossings, sf.crossings) << "step " << step;
    ASSERT_EQ(sk.frozen, sf.frozen) << "step " << step;
    ASSERT_EQ(sk.broad_phases, sf.broad_phases) << "step " << step;
    ASSERT_EQ(x, xf) << "step " << step;  // bitwise
    ASSERT_EQ(v, vf) << "step " << step;
    EXPECT_EQ(sf.tree_queries, sf.broad_phases);  // a new object queries the trees
    if (sk.tree_queries < sk.broad_phases) {
      ++listed_steps;
      listed_contacts += sk.contacts + sk.crossings > 0;
    }
    direct_later += step > 20 && sk.tree_queries > 0;
    // Start gaps: a new object snapshots x0 and computes each one a pass asks for; the kept one
    // bounds them from its snapshot and computes only those the bound leaves open.
    EXPECT_GT(sf.exact_gaps, 0) << "step " << step;
    bounded_steps += 4 * sk.exact_gaps < sk.candidates;
    computed_with_contacts += sk.exact_gaps > 0 && sk.contacts + sk.crossings > 0;
  }
  EXPECT_GT(listed_steps, 100);    // the list served most steps
  EXPECT_GT(listed_contacts, 10);  // including steps with contacts
  EXPECT_GT(direct_later, 10);     // and was rebuilt, or skipped for direct queries, later on
  EXPECT_GT(bounded_steps, 150);   // the snapshot's bounds decided most pairs on most steps
  EXPECT_GT(computed_with_contacts, 10);  // and left the close ones to the exact gaps
}

// The pair list filtered on the OpenMP team: a 64 x 96 sheet (1 cm, thickness 0.5 mm) in a slow
// travelling wave, 40 steps on 1 and on 2 threads, serves the same broad phases with the same
// candidates (counted each step) and the same positions. There are no contacts here, so this
// test cannot see the candidates' order; the filter keeps it by concatenating static blocks in
// thread order, as the direct query does (whose order ResultsDoNotDependOnTheThreadCount checks).
TEST(SelfCollision, PairListResultsDoNotDependOnTheThreadCount) {
  const double dt = 0.01;
  MatX3 rest;
  MatX3i tris;
  flat_sheet(64, 96, 0.01, rest, tris);
  const VecX w = VecX::Ones(rest.rows());
  auto target = [&](int step) {
    MatX3 x = rest;
    for (Index i = 0; i < x.rows(); ++i)
      x(i, 2) = 0.02 * std::sin(2 * kPi * (rest(i, 0) / 0.3 - 0.5 * step * dt));
    return x;
  };
  auto run_with = [&](int threads, int& listed, Index& most, std::vector<Index>& cands) {
    const int before = num_threads();
    set_num_threads(threads);
    SelfCollision collide(tris, rest.rows(), params(0.0005));
    MatX3 x = target(0), v = MatX3::Zero(x.rows(), 3);
    listed = 0;
    most = 0;
    for (int step = 1; step <= 40; ++step) {
      const MatX3 x0 = drive(target(step), dt, x, v);
      const SelfCollisionStats& st = collide.resolve(x0, x, v, w);
      listed += st.tree_queries < st.broad_phases;
      most = std::max(most, st.candidates);
      cands.push_back(st.candidates);
    }
    set_num_threads(before);
    return x;
  };
  int listed_one = 0, listed_two = 0;
  Index most = 0;
  std::vector<Index> cands_one, cands_two;
  const MatX3 one = run_with(1, listed_one, most, cands_one),
              two = run_with(2, listed_two, most, cands_two);
  EXPECT_EQ(cands_one, cands_two);
  EXPECT_GE(most, 4 * kParallelGrain) << "the list filter should run on the team";
  EXPECT_GT(listed_one, 20);
  EXPECT_EQ(listed_one, listed_two);
  EXPECT_EQ(one, two);  // bitwise
}

TEST(SelfCollision, PoleAndSelfCollisionTogether) {
  // The folded sheet thrown sideways into a pole standing in its way.
  MatX3 x, v;
  MatX3i tris;
  VecX w;
  folded(x, v, tris, w);
  PoleParams pole;
  pole.radius = 0.03;
  pole.height = 1.0;
  pole.base = Vec3(0.3, -0.5, -0.04);
  for (Index i = 0; i < x.rows(); ++i)
    if (w[i] > 0) v(i, 2) -= 15;
  const KinematicRun r = run(x, v, tris, w, params(), 8, &pole);
  EXPECT_EQ(r.crossings, 0);
  EXPECT_GE(r.min_distance, 0.0025);
  for (Index i = 0; i < r.x.rows(); ++i) EXPECT_FALSE(inside_pole(pole, r.x.row(i).transpose()));
}

}  // namespace
}  // namespace flagsim
