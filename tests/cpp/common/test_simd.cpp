// on_widest_lanes: the lanes and the compile-time row length a kernel is bound to.
#include <gtest/gtest.h>

#include "common/simd.h"

namespace flagsim {
namespace {

// The bound kernel reports what it was compiled for: bytes per vector (8: scalars) and N.
const auto kReport = [](auto c, int bias) FLAGSIM_INLINE_LAMBDA {
  using C = decltype(c);
  return 1000 * (C::W * int(sizeof(double))) + C::N + bias;
};

int bound(int rows) { return on_widest_lanes<double, int(int)>(kReport, rows)(0); }
int bound_without_rows() { return on_widest_lanes<double, int(int)>(kReport)(0); }

// On 32-byte lanes, rows of 16 and 32 become the kernel's N (the 16^3 and 32^3 grids' rows
// unrolled), other lengths 0; capped at 16 bytes the kernel gets no row length; without rows, 0.
TEST(OnWidestLanes, BindsTheWidestLanesAndTheRowLengthsOf16And32) {
  if (vector_bytes() < 32) GTEST_SKIP() << "this CPU has one vector width only (no AVX)";
  EXPECT_EQ(bound(16), 32016);
  EXPECT_EQ(bound(32), 32032);
  EXPECT_EQ(bound(24), 32000);
  EXPECT_EQ(bound(0), 32000);
  EXPECT_EQ(bound_without_rows(), 32000);
  vector_bytes(16);
  EXPECT_EQ(bound(16), 16000);
  EXPECT_EQ(bound(32), 16000);
  EXPECT_EQ(bound_without_rows(), 16000);
  vector_bytes(0);
  // The arguments reach the kernel; the choice is made when bound, not when called.
  const auto kernel = on_widest_lanes<double, int(int)>(kReport, 32);
  vector_bytes(16);
  EXPECT_EQ(kernel(5), 32037);
  vector_bytes(0);
}

}  // namespace
}  // namespace flagsim
