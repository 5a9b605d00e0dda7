// Uniform-grid spatial hash of axis-aligned boxes, the self-collision broad phase
// (Teschner et al., "Optimized Spatial Hashing for Collision Detection of Deformable Objects",
// VMV 2003): cells of side `cell`, integer cell coordinates hashed into a power-of-two table,
// buckets laid out by a counting sort. Build O(items + entries), query O(cells + hits): expected
// O(N) for a cloth whose cell size is about the primitive size.
// Memory is allocated by reserve(); build() allocates only when a step needs more entries than
// any step before (a box spanning many cells). Boxes spanning more than kMaxCellsPerItem cells are
// kept in a side list checked by every query, so one fast-moving item cannot blow up the table.
#pragma once
#include <algorithm>
#include <cstdint>
#include <vector>

#include "common/types.h"

namespace flagsim {

class SpatialHash {
 public:
  static constexpr int64_t kMaxCellsPerItem = 512;

  /// Preallocate for `items` boxes (table size: the power of two >= 2 * items).
  void reserve(Index items);

  /// Hash the boxes [lo_i, hi_i] (items x 3, m) into cells of side `cell` (m, > 0).
  /// Keeps pointers to lo and hi: they must outlive the queries.
  void build(const MatX3& lo, const MatX3& hi, double cell);

  /// Calls visit(item) once for every item whose box overlaps [qlo, qhi] (closed boxes), in a
  /// deterministic order (not sorted).
  template <class Visit>
  void query(const Vec3& qlo, const Vec3& qhi, Visit&& visit) const;

  double cell() const { return cell_; }
  Index entries() const { return entries_used_; }

 private:
  int64_t coord(double x) const;
  uint32_t bucket(int64_t i, int64_t j, int64_t k) const {
    // Teschner et al. 2003 hash: large primes, xor, modulo the table size (a power of two).
    const auto h = static_cast<uint64_t>(i) * 73856093ull ^ static_cast<uint64_t>(j) * 19349663ull ^
                   static_cast<uint64_t>(k) * 83492791ull;
    return static_cast<uint32_t>((h ^ (h >> 29)) & mask_);
  }
  bool overlaps(Index item, const Vec3& qlo, const Vec3& qhi) const {
    return (lo_->row(item).transpose().array() <= qhi.array()).all() &&
           (hi_->row(item).transpose().array() >= qlo.array()).all();
  }

  const MatX3* lo_ = nullptr;
  const MatX3* hi_ = nullptr;
  double cell_ = 1.0;
  uint64_t mask_ = 0;
  Index entries_used_ = 0;
  std::vector<int64_t> cell_lo_, cell_hi_;  // items x 3 cell ranges (inclusive)
  std::vector<uint8_t> big_;                // 1 if the item is in oversized_
  std::vector<int32_t> start_;              // table + 1 bucket offsets into entries_
  std::vector<int32_t> fill_;               // table, fill cursor
  std::vector<int32_t> entries_;            // item ids, grouped by bucket, ascending in a bucket
  std::vector<int32_t> oversized_;          // items spanning > kMaxCellsPerItem cells
};

template <class Visit>
void SpatialHash::query(const Vec3& qlo, const Vec3& qhi, Visit&& visit) const {
  const Index n = lo_ ? lo_->rows() : 0;
  if (n == 0) return;
  for (int32_t item : oversized_)
    if (overlaps(item, qlo, qhi)) visit(item);
  int64_t q0[3], q1[3];
  int64_t span = 1;
  for (int d = 0; d < 3; ++d) {
    q0[d] = coord(qlo[d]);
    q1[d] = coord(qhi[d]);
    span *= q1[d] - q0[d] + 1;
    if (span > kMaxCellsPerItem) break;
  }
  if (span > kMaxCellsPerItem) {  // huge query box: a linear scan is cheaper than its cells
    for (Index item = 0; item < n; ++item)
      if (!big_[item] && overlaps(item, qlo, qhi)) visit(static_cast<int32_t>(item));
    return;
  }
  for (int64_t i = q0[0]; i <= q1[0]; ++i)
    for (int64_t j = q0[1]; j <= q1[1]; ++j)
      for (int64_t k = q0[2]; k <= q1[2]; ++k) {
        const uint32_t b = bucket(i, j, k);
        int32_t previous = -1;
        for (int32_t e = start_[b]; e < start_[b + 1]; ++e) {
          const int32_t item = entries_[e];
          if (item == previous) continue;  // the item hashed twice into this bucket
          previous = item;
          // Report a pair only from the lowest cell the item and the query share.
          const int64_t* lo = &cell_lo_[3 * static_cast<size_t>(item)];
          if (std::max(lo[0], q0[0]) != i || std::max(lo[1], q0[1]) != j ||
              std::max(lo[2], q0[2]) != k)
            continue;
          if (overlaps(item, qlo, qhi)) visit(item);
        }
      }
}

}  // namespace flagsim
