// Bounding-box tree of axis-aligned boxes, the self-collision broad phase.
//
// The tree's shape is built once (median splits of the box centres along the widest axis, up to
// kLeafSize items per leaf) and afterwards only refitted to new boxes: a cloth keeps its
// neighbourhoods, so a tree built on one step's boxes stays tight for the steps after, and
// refitting is O(items) with no allocation. Nodes are stored in depth-first order with the index
// of the node after each subtree (its escape), so a query walks the array without a stack.
//
// Replaced a uniform-grid spatial hash (Teschner et al. 2003), whose queries scanned 8-27 cells
// of a few entries each: the paper scene's self-collision stage went from 150 to 70 us per step
// (docs/design.md, Self-collision: "Broad phase: box trees").
#pragma once
#include <cstdint>
#include <vector>

#include "common/types.h"

namespace flagsim {

class BoxTree {
 public:
  static constexpr int kLeafSize = 4;

  /// The tree's shape from the boxes [lo_i, hi_i] (items x 3), and their fit. Allocates.
  void build(const MatX3& lo, const MatX3& hi);

  /// Refit to new boxes of the same items (same count as build); no allocation.
  void refit(const MatX3& lo, const MatX3& hi);

  bool built() const { return built_; }
  Index items() const { return items_; }

  /// Calls visit(item) once for every item above `after` whose box overlaps [qlo, qhi] (closed
  /// boxes), in the tree's order (deterministic, not sorted). The boxes are those of the last
  /// build or refit, read from lo and hi at the time of the query.
  template <class Visit>
  void query(const MatX3& lo, const MatX3& hi, const Vec3& qlo, const Vec3& qhi, Visit&& visit,
             int32_t after = -1) const;

 private:
  struct Node {
    double lo[3], hi[3];
    int32_t escape;    // the next node once this subtree is done (depth-first order)
    int32_t first;     // leaf: its items are order_[first, first + count)
    int32_t count;     // 0 for an inner node (children: this + 1 and nodes_[this + 1].escape)
    int32_t max_item;  // the largest item index in the subtree
  };
  int32_t build_range(int32_t begin, int32_t end, const std::vector<double>& centre);

  bool built_ = false;
  Index items_ = 0;
  std::vector<Node> nodes_;
  std::vector<int32_t> order_;
};

template <class Visit>
void BoxTree::query(const MatX3& lo, const MatX3& hi, const Vec3& qlo, const Vec3& qhi,
                    Visit&& visit, int32_t after) const {
  const int32_t end = static_cast<int32_t>(nodes_.size());
  const double x0 = qlo[0], y0 = qlo[1], z0 = qlo[2], x1 = qhi[0], y1 = qhi[1], z1 = qhi[2];
  for (int32_t i = 0; i < end;) {
    const Node& n = nodes_[size_t(i)];
    if (n.max_item <= after || n.lo[0] > x1 || n.hi[0] < x0 || n.lo[1] > y1 || n.hi[1] < y0 ||
        n.lo[2] > z1 || n.hi[2] < z0) {
      i = n.escape;
      continue;
    }
    if (n.count == 0) {
      ++i;
      continue;
    }
    for (int32_t k = n.first; k < n.first + n.count; ++k) {
      const int32_t item = order_[size_t(k)];
      const double* l = lo.data() + 3 * Index(item);
      const double* h = hi.data() + 3 * Index(item);
      if (item > after && l[0] <= x1 && h[0] >= x0 && l[1] <= y1 && h[1] >= y0 && l[2] <= z1 &&
          h[2] >= z0)
        visit(item);
    }
    i = n.escape;
  }
}

}  // namespace flagsim
