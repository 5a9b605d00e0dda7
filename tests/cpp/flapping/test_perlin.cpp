#include "flapping/perlin.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

namespace flagsim {
namespace {

// The definition in perlin.h, written out again here from its text (not calling the library).
struct ReferenceNoise {
  int perm[256];
  explicit ReferenceNoise(uint32_t seed) {
    for (int i = 0; i < 256; ++i) perm[i] = i;
    uint64_t state = seed;
    for (int k = 255; k >= 1; --k) {
      state += 0x9E3779B97F4A7C15ull;
      uint64_t z = state;
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
      z ^= z >> 31;
      const int j = static_cast<int>(z % static_cast<uint64_t>(k + 1));
      std::swap(perm[k], perm[j]);
    }
  }
  double grad(long i) const {
    const int h = perm[((i % 256) + 256) % 256];
    const double g[4] = {1.0, 0.75, 0.5, 0.25};
    return (h % 2 ? -1.0 : 1.0) * g[(h / 2) % 4];
  }
  double operator()(double x) const {
    const long i = static_cast<long>(std::floor(x));
    const double f = x - static_cast<double>(i);
    const double s = 10 * f * f * f - 15 * f * f * f * f + 6 * f * f * f * f * f;
    return 2 * ((1 - s) * grad(i) * f + s * grad(i + 1) * (f - 1));
  }
};

TEST(Perlin, FadeIsQuinticSmoothstep) {
  EXPECT_DOUBLE_EQ(perlin_fade(0.0), 0.0);
  EXPECT_DOUBLE_EQ(perlin_fade(1.0), 1.0);
  EXPECT_DOUBLE_EQ(perlin_fade(0.5), 0.5);
  const double e = 1e-4;
  // First and second derivatives vanish at both ends (Perlin 2002's reason for the quintic).
  EXPECT_NEAR((perlin_fade(e) - perlin_fade(0)) / e, 0.0, 1e-7);
  EXPECT_NEAR((perlin_fade(1) - perlin_fade(1 - e)) / e, 0.0, 1e-7);
  EXPECT_NEAR((perlin_fade(2 * e) - 2 * perlin_fade(e) + perlin_fade(0)) / (e * e), 0.0, 1e-2);
}

TEST(Perlin, PermutationIsAPermutationAndDependsOnSeed) {
  for (uint32_t seed : {0u, 1u, 42u, 0xFFFFFFFFu}) {
    const auto p = perlin_permutation(seed);
    std::set<int> values(p.begin(), p.end());
    EXPECT_EQ(values.size(), 256u);
  }
  EXPECT_NE(perlin_permutation(0), perlin_permutation(1));
}

TEST(Perlin, ZeroAtEveryLatticePoint) {
  for (uint32_t seed : {0u, 7u, 123456u}) {
    const Perlin1D n(seed);
    for (int i = -1000; i <= 1000; ++i) EXPECT_EQ(n(i), 0.0) << "seed " << seed << " x " << i;
    EXPECT_EQ(n(1e12), 0.0);
    EXPECT_EQ(n(-3e15), 0.0);
  }
}

TEST(Perlin, BoundedByOneAndTheBoundIsReached) {
  double peak = 0;
  for (uint32_t seed : {0u, 1u, 2u, 99u}) {
    const Perlin1D n(seed);
    for (int k = 0; k <= 256 * 400; ++k) {
      const double v = n(k / 400.0 - 3.0);
      ASSERT_LE(std::abs(v), 1.0);
      peak = std::max(peak, std::abs(v));
    }
  }
  // g_i = -g_{i+1} = +-1 occurs in 256 cells: |n(i + 1/2)| = 1 there.
  EXPECT_GT(peak, 0.999);
}

TEST(Perlin, FirstDerivativeIsContinuousAcrossCells) {
  const Perlin1D n(5);
  const double e = 1e-6;
  for (int i = -20; i <= 20; ++i) {
    const double left = (n(i) - n(i - e)) / e, right = (n(i + e) - n(i)) / e;
    EXPECT_NEAR(left, right, 1e-5) << "at " << i;
    // Slope at a lattice point is 2 g_i: one of the 8 gradient values times 2.
    const double slope = 0.5 * (left + right) / 2.0;
    EXPECT_NEAR(std::abs(slope) * 4, std::round(std::abs(slope) * 4), 1e-4);
  }
  // Inside cells: central differences at two step sizes agree (smooth, no kinks anywhere).
  for (int k = 0; k < 2000; ++k) {
    const double x = -10 + k * 0.01 + 0.003;
    const double d1 = (n(x + 1e-4) - n(x - 1e-4)) / 2e-4, d2 = (n(x + 2e-4) - n(x - 2e-4)) / 4e-4;
    EXPECT_NEAR(d1, d2, 1e-5) << x;
  }
}

TEST(Perlin, SameSeedSameValuesDifferentSeedDifferentValues) {
  const Perlin1D a(3), b(3), c(4);
  int differ = 0;
  for (int k = 0; k < 1000; ++k) {
    const double x = k * 0.37 + 0.01;
    EXPECT_EQ(a(x), b(x));
    differ += a(x) != c(x);
  }
  EXPECT_GT(differ, 900);
}

TEST(Perlin, MatchesTheWrittenDefinition) {
  for (uint32_t seed : {0u, 1u, 31337u, 4000000000u}) {
    const Perlin1D n(seed);
    const ReferenceNoise ref(seed);
    for (int k = -3000; k <= 3000; ++k) {
      const double x = k * 0.173;
      EXPECT_NEAR(n(x), ref(x), 1e-14) << "seed " << seed << " x " << x;
    }
  }
}

TEST(Perlin, PeriodIs256) {
  const Perlin1D n(11);
  for (int k = 0; k < 500; ++k) {
    const double x = k * 0.731 - 100;
    EXPECT_NEAR(n(x), n(x + 256), 1e-11);
  }
}

}  // namespace
}  // namespace flagsim
