#include "collision/spatial_hash.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace flagsim {
namespace {

TEST(SpatialHash, QueriesMatchBruteForceExactlyOnce) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> pos(-2, 2), size(0.0, 0.3);
  const Index n = 600;
  MatX3 lo(n, 3), hi(n, 3);
  for (Index i = 0; i < n; ++i) {
    for (int d = 0; d < 3; ++d) {
      lo(i, d) = pos(rng);
      hi(i, d) = lo(i, d) + size(rng);
    }
  }
  // A few long boxes (the side list) and a degenerate point box.
  hi.row(5) = lo.row(5).array() + 3.5;
  hi.row(17) << lo(17, 0) + 4, lo(17, 1) + 0.01, lo(17, 2) + 4;
  hi.row(40) = lo.row(40);
  SpatialHash hash;
  hash.reserve(n);
  hash.build(lo, hi, 0.1);
  for (int q = 0; q < 300; ++q) {
    Vec3 qlo(pos(rng), pos(rng), pos(rng));
    Vec3 qhi = qlo + Vec3::Constant(q < 290 ? size(rng) : 3.0);  // last ones: huge queries
    std::vector<int> seen(n, 0);
    hash.query(qlo, qhi, [&](int32_t item) { ++seen[item]; });
    for (Index i = 0; i < n; ++i) {
      const bool overlap = (lo.row(i).transpose().array() <= qhi.array()).all() &&
                           (hi.row(i).transpose().array() >= qlo.array()).all();
      EXPECT_EQ(seen[i], overlap ? 1 : 0) << "query " << q << " item " << i;
    }
  }
}

TEST(SpatialHash, RebuildReusesStorage) {
  const Index n = 100;
  MatX3 lo = MatX3::Zero(n, 3), hi = MatX3::Constant(n, 3, 0.05);
  for (Index i = 0; i < n; ++i) lo.row(i).array() += 0.1 * i, hi.row(i).array() += 0.1 * i;
  SpatialHash hash;
  hash.reserve(n);
  hash.build(lo, hi, 0.1);
  const Index entries = hash.entries();
  hash.build(lo, hi, 0.1);
  EXPECT_EQ(hash.entries(), entries);
  int count = 0;
  hash.query(Vec3::Constant(0.52), Vec3::Constant(0.53), [&](int32_t item) {
    EXPECT_EQ(item, 5);
    ++count;
  });
  EXPECT_EQ(count, 1);
}

}  // namespace
}  // namespace flagsim
