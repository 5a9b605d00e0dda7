// ScopedTimer (common/timer.h): what Fluid.stats' seconds_* add up.
#include <gtest/gtest.h>

#include <chrono>

#include "../test_util.h"
#include "common/timer.h"

using namespace flagsim;
using flagsim::testing::busy;

// Each scope adds its own wall time to the accumulator, which keeps what it held: two scopes of
// 2 and 3 ms on a sum that started at 1 s add at least 5 ms and at most the wall time around them.
TEST(ScopedTimer, AddsEachScopesWallTimeToTheSum) {
  double sum = 1.0;
  const auto t0 = std::chrono::steady_clock::now();
  {
    ScopedTimer t(sum);
    busy(0.002);
  }
  const double first = sum - 1.0;
  {
    ScopedTimer t(sum);
    busy(0.003);
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_GE(first, 0.002);
  EXPECT_GE(sum - 1.0 - first, 0.003);
  EXPECT_LE(sum - 1.0, wall);
}
