// Flag topology: nearest-pin and end tethers against a brute-force search (bit-identical, ties to
// the lowest pin index) for every pin mode, explicit pins with ties, a tall thin flag and random
// pins; and the basic invariants (counts, lumped masses and areas, rest lengths).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "cloth/topology.h"

namespace flagsim {
namespace {

/// The pinned vertices `p` describes: pinned_vertices when non-empty, else the pin mode's.
std::set<int> expected_pins(const FlagParams& p) {
  std::set<int> pins;
  const int R = p.rows, C = p.cols;
  if (!p.pinned_vertices.empty()) {
    pins.insert(p.pinned_vertices.begin(), p.pinned_vertices.end());
  } else if (p.pin == Pin::kPole) {
    for (int r = 0; r < R; ++r) pins.insert(r * C);
  } else if (p.pin == Pin::kGrommets) {
    pins.insert(0);
    pins.insert((R - 1) * C);
  } else if (p.pin == Pin::kTop) {
    for (int c = 0; c < C; ++c) pins.insert(c);
  }
  return pins;
}

/// Tethers and invariants of build_flag_topology(p) against a direct search written here.
void check_topology(const FlagParams& p, const std::string& label) {
  SCOPED_TRACE(label);
  p.validate();  // the cases themselves must be valid flags
  const ClothTopology t = build_flag_topology(p);
  const int R = p.rows, C = p.cols, N = R * C;

  // Counts.
  ASSERT_EQ(t.rows, R);
  ASSERT_EQ(t.cols, C);
  ASSERT_EQ(t.num_vertices(), N);
  ASSERT_EQ(t.triangles.rows(), 2 * Index(R - 1) * (C - 1));
  ASSERT_EQ(t.mass.size(), N);
  ASSERT_EQ(t.area.size(), N);
  ASSERT_EQ(t.inv_mass.size(), N);
  ASSERT_EQ(t.tether_anchor.size(), size_t(N));
  ASSERT_EQ(t.tether_length.size(), N);
  ASSERT_EQ(t.rest_length.size(), t.num_springs());

  // Lumped masses and areas: mass = areal density x area, the areas add up to the rectangle.
  for (int i = 0; i < N; ++i) {
    EXPECT_GT(t.area[i], 0.0) << "vertex " << i;
    EXPECT_DOUBLE_EQ(t.mass[i], p.areal_density * t.area[i]) << "vertex " << i;
  }
  const double total = t.area.sum(), rect = p.width * p.height;
  EXPECT_LE(std::fabs(total - rect), 1e-12 * rect) << "total area " << total << " vs " << rect;
  for (Index j = 0; j < t.num_springs(); ++j) {
    EXPECT_GT(t.rest_length[j], 0.0) << "spring " << j;
    if (!(t.rest_length[j] > 0.0)) break;  // one report is enough
  }

  // Pins: exactly the vertices the parameters name have inverse mass 0.
  const std::set<int> pin_set = expected_pins(p);
  for (int i = 0; i < N; ++i) {
    ASSERT_EQ(t.pinned(i), pin_set.count(i) == 1) << "vertex " << i;
    if (!t.pinned(i)) {
      EXPECT_GT(t.inv_mass[i], 0.0) << "vertex " << i;
    }
  }

  // Tethers: for each unpinned vertex the first pin (in increasing index) at strictly smaller
  // distance, by the same expression; -1 and 0 for pinned vertices and when nothing is pinned.
  const std::vector<int> pins(pin_set.begin(), pin_set.end());  // ascending
  int mismatches = 0;
  for (int i = 0; i < N && mismatches < 5; ++i) {
    int best = -1;
    double best_d = std::numeric_limits<double>::infinity();
    if (!pin_set.count(i)) {
      for (int a : pins) {
        const double d = (t.rest_positions.row(i) - t.rest_positions.row(a)).norm();
        if (d < best_d) {
          best_d = d;
          best = a;
        }
      }
    }
    const double length = best >= 0 ? best_d : 0.0;
    EXPECT_EQ(t.tether_anchor[size_t(i)], best) << "vertex " << i;
    EXPECT_EQ(t.tether_length[i], length) << "vertex " << i;  // bit-identical, not near
    if (t.tether_anchor[size_t(i)] != best || !(t.tether_length[i] == length)) ++mismatches;
  }

  // End tethers: to the two pins farthest apart, e0 (farthest from the lowest-index pin) and e1
  // (farthest from e0), each at its rest distance, except where it is the nearest pin (or e1 is
  // e0); -1 and 0 for pinned vertices and when nothing is pinned.
  ASSERT_EQ(t.tether_end_anchor.size(), 2 * size_t(N));
  ASSERT_EQ(t.tether_end_length.size(), 2 * N);
  int ends[2] = {-1, -1};
  if (!pins.empty()) {
    const auto farthest = [&](int from) {
      int f = pins.front();
      for (int a : pins)
        if ((t.rest_positions.row(a) - t.rest_positions.row(from)).squaredNorm() >
            (t.rest_positions.row(f) - t.rest_positions.row(from)).squaredNorm())
          f = a;
      return f;
    };
    ends[0] = farthest(pins.front());
    ends[1] = farthest(ends[0]);
  }
  for (int i = 0; i < N; ++i) {
    for (int k = 0; k < 2; ++k) {
      const bool none = pin_set.count(i) || ends[k] < 0 || ends[k] == t.tether_anchor[size_t(i)] ||
                        (k == 1 && ends[1] == ends[0]);
      const int want = none ? -1 : ends[k];
      const double length =
          none ? 0.0 : (t.rest_positions.row(i) - t.rest_positions.row(want)).norm();
      ASSERT_EQ(t.tether_end_anchor[2 * size_t(i) + k], want) << "vertex " << i << " end " << k;
      ASSERT_EQ(t.tether_end_length[2 * i + k], length) << "vertex " << i << " end " << k;
    }
  }
}

/// A flag whose rest positions are exact binary fractions (origin 0, spacing a power of two), so
/// symmetric pins give exactly equal distances: true ties.
FlagParams exact_grid(int rows, int cols) {
  FlagParams p;
  p.rows = rows;
  p.cols = cols;
  p.origin = Vec3::Zero();
  p.width = 0.125 * (cols - 1);
  p.height = 0.125 * (rows - 1);
  return p;
}

TEST(FlagTopology, PinModesMatchBruteForceTethers) {
  for (const char* mode : {"pole", "grommets", "top", "none"}) {
    FlagParams p;  // the paper's 8 x 11 flag
    p.pin = parse_enum<Pin>("pin", mode);
    check_topology(p, std::string("8 x 11, pin ") + mode);
    FlagParams q = exact_grid(9, 7);  // odd rows: the middle row is equidistant from both grommets
    q.pin = parse_enum<Pin>("pin", mode);
    check_topology(q, std::string("exact 9 x 7, pin ") + mode);
  }
}

TEST(FlagTopology, EndTethersGoToBothEndsOfThePole) {
  FlagParams p = exact_grid(9, 7);
  p.pin = Pin::kPole;
  const ClothTopology t = build_flag_topology(p);
  const int top = 0, bottom = 8 * 7;  // column 0 of the first and the last row
  for (int r = 0; r < 9; ++r)
    for (int c = 1; c < 7; ++c) {
      const size_t i = size_t(r * 7 + c);
      std::set<int> anchors = {t.tether_anchor[i], t.tether_end_anchor[2 * i],
                               t.tether_end_anchor[2 * i + 1]};
      anchors.erase(-1);
      // Its own row's pin and both ends of the pole: three tethers, two in the end rows.
      const std::set<int> want = {r * 7, top, bottom};
      EXPECT_EQ(anchors, want) << "row " << r << " col " << c;
    }
}

TEST(FlagTopology, NoPinsGiveNoTethers) {
  FlagParams p;
  p.pin = Pin::kNone;
  const ClothTopology t = build_flag_topology(p);
  for (Index i = 0; i < t.num_vertices(); ++i) {
    EXPECT_EQ(t.tether_anchor[size_t(i)], -1);
    EXPECT_EQ(t.tether_length[i], 0.0);
    EXPECT_EQ(t.tether_end_anchor[2 * size_t(i)], -1);
    EXPECT_EQ(t.tether_end_anchor[2 * size_t(i) + 1], -1);
  }
}

TEST(FlagTopology, ExplicitPinsWithTiesGoToTheLowestIndex) {
  {
    // The four corners of an exact 5 x 5 grid: the centre (12) and the edge midpoints are
    // equidistant from two or four corners. Listed out of order and with a duplicate.
    FlagParams p = exact_grid(5, 5);
    p.pinned_vertices = {24, 0, 20, 4, 0};
    check_topology(p, "exact 5 x 5, four corners");
    const ClothTopology t = build_flag_topology(p);
    EXPECT_EQ(t.tether_anchor[12], 0);   // four-way tie
    EXPECT_EQ(t.tether_anchor[2], 0);    // top middle: tie between 0 and 4
    EXPECT_EQ(t.tether_anchor[14], 4);   // right middle: tie between 4 and 24
    EXPECT_EQ(t.tether_anchor[22], 20);  // bottom middle: tie between 20 and 24
  }
  {
    // The same pins on the paper's spacing and origin (near-ties decided by rounding).
    FlagParams p;
    p.rows = 5;
    p.cols = 5;
    p.pinned_vertices = {0, 4, 20, 24};
    check_topology(p, "paper 5 x 5, four corners");
  }
  {
    // A checkerboard of pins: every free vertex has four equidistant pinned neighbours.
    FlagParams p = exact_grid(12, 13);
    for (int r = 0; r < p.rows; ++r)
      for (int c = 0; c < p.cols; ++c)
        if ((r + c) % 2 == 0) p.pinned_vertices.push_back(r * p.cols + c);
    check_topology(p, "exact 12 x 13 checkerboard");
  }
  {
    // Two pins mirrored about the middle column, and a single pin.
    FlagParams p = exact_grid(6, 9);
    p.pinned_vertices = {3 * 9 + 1, 3 * 9 + 7};
    check_topology(p, "exact 6 x 9, mirrored pair");
    p.pinned_vertices = {17};
    check_topology(p, "exact 6 x 9, one pin");
  }
  {
    // Every vertex pinned: no tethers at all.
    FlagParams p;
    p.rows = 3;
    p.cols = 4;
    for (int i = 0; i < 12; ++i) p.pinned_vertices.push_back(i);
    check_topology(p, "3 x 4, all pinned");
  }
}

TEST(FlagTopology, TallThinPoleFlag) {
  FlagParams p;
  p.rows = 2000;
  p.cols = 3;
  p.height = 20.0;
  p.width = 0.3;
  check_topology(p, "2000 x 3, pole");
  p.pin = Pin::kGrommets;
  check_topology(p, "2000 x 3, grommets");
}

TEST(FlagTopology, RandomPinsMatchBruteForceTethers) {
  std::mt19937 rng(20240611);
  for (int trial = 0; trial < 12; ++trial) {
    const bool exact = trial % 2 == 0;  // exact grids make ties common
    std::uniform_int_distribution<int> dim(2, 40);
    const int rows = dim(rng), cols = dim(rng);
    FlagParams p = exact_grid(rows, cols);
    if (!exact) {
      std::uniform_real_distribution<double> u(-3.0, 3.0), len(0.05, 4.0);
      p.width = len(rng);
      p.height = len(rng);
      p.origin = Vec3(u(rng), u(rng), u(rng));
    }
    const int N = p.rows * p.cols;
    std::uniform_int_distribution<int> count(1, std::max(1, N / 4)), vertex(0, N - 1);
    const int k = count(rng);
    for (int j = 0; j < k; ++j) p.pinned_vertices.push_back(vertex(rng));
    check_topology(p, "trial " + std::to_string(trial) + ": " + std::to_string(p.rows) + " x " +
                          std::to_string(p.cols) + ", " + std::to_string(k) + " random pins");
  }
}

}  // namespace
}  // namespace flagsim
