#include "cloth/stencil9.h"

#include <gtest/gtest.h>

#include <vector>

namespace flagsim {

TEST(Stencil9, SlotsAreRowMajorAndMirrorThroughTheCentre) {
  EXPECT_EQ(stencil_slot(0, 0), kStencilCentre);
  EXPECT_EQ(stencil_slot(-1, -1), 0);
  EXPECT_EQ(stencil_slot(1, 1), 8);
  for (int dr = -1; dr <= 1; ++dr)
    for (int dc = -1; dc <= 1; ++dc) EXPECT_EQ(stencil_slot(-dr, -dc), 8 - stencil_slot(dr, dc));
}

// Corners see 4 nodes, edges 6, the interior 9, each once and in increasing slot order.
TEST(Stencil9, VisitsTheNeighboursInsideTheGridInSlotOrder) {
  const int rows = 3, cols = 4;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      std::vector<int> slots;
      for_each_stencil_neighbour(rows, cols, r, c, [&](int dr, int dc) {
        EXPECT_TRUE(r + dr >= 0 && r + dr < rows && c + dc >= 0 && c + dc < cols);
        slots.push_back(stencil_slot(dr, dc));
      });
      const int inside_r = 3 - (r == 0) - (r == rows - 1);
      const int inside_c = 3 - (c == 0) - (c == cols - 1);
      EXPECT_EQ(int(slots.size()), inside_r * inside_c) << r << ", " << c;
      for (size_t k = 1; k < slots.size(); ++k) EXPECT_LT(slots[k - 1], slots[k]);
    }
}

// A known operator: the 9-point Laplacian (centre -8, neighbours 1) of a linear field is 0 inside
// and, with the missing neighbours dropped, minus their values at the corners; the interior
// variant gives the same sums.
TEST(Stencil9, AppliesANinePointOperator) {
  const int rows = 5, cols = 6;
  auto f = [](int r, int c) { return 2.0 * r + 3.0 * c + 1.0; };
  auto laplace = [&](int r, int c, auto visit) {
    double s = 0;
    visit(rows, cols, r, c,
          [&](int dr, int dc) { s += (dr == 0 && dc == 0 ? -8.0 : 1.0) * f(r + dr, c + dc); });
    return s;
  };
  auto bounded = [](int R, int C, int r, int c, auto g) {
    for_each_stencil_neighbour(R, C, r, c, g);
  };
  auto interior = [](int R, int C, int r, int c, auto g) {
    for_each_stencil_neighbour<true>(R, C, r, c, g);
  };
  for (int r = 1; r + 1 < rows; ++r)
    for (int c = 1; c + 1 < cols; ++c) {
      EXPECT_EQ(laplace(r, c, bounded), 0.0);
      EXPECT_EQ(laplace(r, c, interior), 0.0);
    }
  // Corner (0, 0): the 5 missing neighbours (-1, -1..1) and (0..1, -1) are dropped.
  double missing = 0;
  for (int dc = -1; dc <= 1; ++dc) missing += f(-1, dc);
  missing += f(0, -1) + f(1, -1);
  EXPECT_EQ(laplace(0, 0, bounded), -missing);
}

}  // namespace flagsim
