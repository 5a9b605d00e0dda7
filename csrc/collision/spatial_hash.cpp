#include "collision/spatial_hash.h"

#include <algorithm>
#include <cmath>

namespace flagsim {

void SpatialHash::reserve(Index items) {
  uint64_t table = 64;
  while (table < 2 * static_cast<uint64_t>(items)) table <<= 1;
  mask_ = table - 1;
  cell_lo_.resize(3 * static_cast<size_t>(items));
  cell_hi_.resize(3 * static_cast<size_t>(items));
  big_.resize(static_cast<size_t>(items));
  start_.assign(table + 1, 0);
  fill_.assign(table, 0);
  // A box about the cell size spans up to 2 x 2 x 2 cells, a few larger ones more: room for 27
  // cells each keeps growth (an allocation) out of ordinary steps.
  entries_.resize(27 * static_cast<size_t>(items));
  oversized_.reserve(static_cast<size_t>(items));
}

int64_t SpatialHash::coord(double x) const {
  // Clamp so that far-flung (but finite) coordinates cannot overflow the integer cell index.
  const double c = std::floor(x / cell_);
  return static_cast<int64_t>(std::clamp(c, -1e15, 1e15));
}

void SpatialHash::build(const MatX3& lo, const MatX3& hi, double cell) {
  const Index n = lo.rows();
  if (static_cast<Index>(big_.size()) < n) reserve(n);
  lo_ = &lo;
  hi_ = &hi;
  cell_ = cell;
  oversized_.clear();
  std::fill(start_.begin(), start_.end(), 0);
  // Pass 1: cell ranges and bucket counts.
  size_t total = 0;
  for (Index item = 0; item < n; ++item) {
    int64_t* c0 = &cell_lo_[3 * static_cast<size_t>(item)];
    int64_t* c1 = &cell_hi_[3 * static_cast<size_t>(item)];
    int64_t span = 1;
    for (int d = 0; d < 3; ++d) {
      c0[d] = coord(lo(item, d));
      c1[d] = coord(hi(item, d));
      const int64_t extent = std::min<int64_t>(c1[d] - c0[d] + 1, kMaxCellsPerItem + 1);
      span = std::min<int64_t>(span * extent, kMaxCellsPerItem + 1);
    }
    big_[item] = span > kMaxCellsPerItem;
    if (big_[item]) {
      oversized_.push_back(static_cast<int32_t>(item));
      continue;
    }
    for (int64_t i = c0[0]; i <= c1[0]; ++i)
      for (int64_t j = c0[1]; j <= c1[1]; ++j)
        for (int64_t k = c0[2]; k <= c1[2]; ++k) ++start_[bucket(i, j, k) + 1];
    total += static_cast<size_t>(span);
  }
  // Prefix sum: start_[b] is where bucket b begins.
  for (size_t b = 1; b < start_.size(); ++b) start_[b] += start_[b - 1];
  if (entries_.size() < total) entries_.resize(total);
  entries_used_ = static_cast<Index>(total);
  // Pass 2: fill in item order, so each bucket lists its items ascending.
  std::copy(start_.begin(), start_.end() - 1, fill_.begin());
  for (Index item = 0; item < n; ++item) {
    if (big_[item]) continue;
    const int64_t* c0 = &cell_lo_[3 * static_cast<size_t>(item)];
    const int64_t* c1 = &cell_hi_[3 * static_cast<size_t>(item)];
    for (int64_t i = c0[0]; i <= c1[0]; ++i)
      for (int64_t j = c0[1]; j <= c1[1]; ++j)
        for (int64_t k = c0[2]; k <= c1[2]; ++k)
          entries_[fill_[bucket(i, j, k)]++] = static_cast<int32_t>(item);
  }
}

}  // namespace flagsim
