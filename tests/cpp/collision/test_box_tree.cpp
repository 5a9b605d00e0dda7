#include "collision/box_tree.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace flagsim {
namespace {

bool overlap(const MatX3& lo, const MatX3& hi, Index i, const Vec3& qlo, const Vec3& qhi) {
  return (lo.row(i).transpose().array() <= qhi.array()).all() &&
         (hi.row(i).transpose().array() >= qlo.array()).all();
}

// Every query reports exactly the items a linear scan finds, each once, above `after`.
void expect_brute_force(const BoxTree& tree, const MatX3& lo, const MatX3& hi, std::mt19937& rng) {
  const Index n = lo.rows();
  std::uniform_real_distribution<double> pos(-2, 2), size(0.0, 0.3);
  std::uniform_int_distribution<int> pick(-1, int(n) - 1);
  for (int q = 0; q < 300; ++q) {
    const Vec3 qlo(pos(rng), pos(rng), pos(rng));
    const Vec3 qhi = qlo + Vec3::Constant(q < 290 ? size(rng) : 3.0);  // the last ones: huge
    const int32_t after = q % 2 ? pick(rng) : -1;
    std::vector<int> seen(size_t(n), 0);
    tree.query(lo, hi, qlo, qhi, [&](int32_t item) { ++seen[size_t(item)]; }, after);
    for (Index i = 0; i < n; ++i)
      ASSERT_EQ(seen[size_t(i)], i > after && overlap(lo, hi, i, qlo, qhi) ? 1 : 0)
          << "query " << q << " item " << i << " after " << after;
  }
}

TEST(BoxTree, QueriesMatchBruteForceExactlyOnceBeforeAndAfterRefit) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> pos(-2, 2), size(0.0, 0.3), step(-0.5, 0.5);
  const Index n = 600;
  MatX3 lo(n, 3), hi(n, 3);
  for (Index i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d) {
      lo(i, d) = pos(rng);
      hi(i, d) = lo(i, d) + size(rng);
    }
  hi.row(5) = lo.row(5).array() + 3.5;  // a long box and a point box
  hi.row(40) = lo.row(40);
  BoxTree tree;
  EXPECT_FALSE(tree.built());
  tree.build(lo, hi);
  EXPECT_TRUE(tree.built());
  expect_brute_force(tree, lo, hi, rng);
  // Move every box (the shape stays, the fit follows) and grow a few a lot.
  for (Index i = 0; i < n; ++i) {
    const Vec3 d(step(rng), step(rng), step(rng));
    lo.row(i) += d.transpose();
    hi.row(i) += d.transpose();
  }
  hi.row(7).array() += 2.0;
  lo.row(300).array() -= 1.5;
  tree.refit(lo, hi);
  expect_brute_force(tree, lo, hi, rng);
}

TEST(BoxTree, DegenerateSetsStillAnswerExactly) {
  std::mt19937 rng(5);
  BoxTree empty;
  empty.build(MatX3(0, 3), MatX3(0, 3));
  int count = 0;
  empty.query(MatX3(0, 3), MatX3(0, 3), Vec3::Constant(-9), Vec3::Constant(9),
              [&](int32_t) { ++count; });
  EXPECT_EQ(count, 0);
  // All centres coincide (the split has nothing to go by): a valid tree all the same.
  const Index n = 37;
  MatX3 lo = MatX3::Zero(n, 3), hi = MatX3::Constant(n, 3, 0.1);
  BoxTree tree;
  tree.build(lo, hi);
  expect_brute_force(tree, lo, hi, rng);
  // Then spread out: refit alone must stay exact, however poor the shape has become.
  for (Index i = 0; i < n; ++i)
    lo.row(i).array() += 0.1 * double(i) - 1.8, hi.row(i).array() += 0.1 * double(i) - 1.8;
  tree.refit(lo, hi);
  expect_brute_force(tree, lo, hi, rng);
}

}  // namespace
}  // namespace flagsim
