#include "collision/box_tree.h"

#include <algorithm>
#include <numeric>

namespace flagsim {

static_assert(MatX3::IsRowMajor, "BoxTree::query reads a box's three bounds as one row");

void BoxTree::build(const MatX3& lo, const MatX3& hi) {
  items_ = lo.rows();
  order_.resize(size_t(items_));
  std::iota(order_.begin(), order_.end(), 0);
  std::vector<double> centre(3 * size_t(items_));
  for (Index i = 0; i < items_; ++i)
    for (int d = 0; d < 3; ++d) centre[3 * size_t(i) + d] = 0.5 * (lo(i, d) + hi(i, d));
  nodes_.clear();
  nodes_.reserve(size_t(2 * (items_ / kLeafSize + 1)));
  if (items_ > 0) build_range(0, int32_t(items_), centre);
  built_ = true;
  refit(lo, hi);
}

int32_t BoxTree::build_range(int32_t begin, int32_t end, const std::vector<double>& centre) {
  const auto id = int32_t(nodes_.size());
  nodes_.push_back(Node{});
  if (end - begin <= kLeafSize) {
    nodes_[size_t(id)].first = begin;
    nodes_[size_t(id)].count = end - begin;
  } else {
    // Split at the median centre along the axis where the centres spread most (ties by index,
    // so the shape does not depend on the sort's implementation details beyond the order).
    double cmin[3], cmax[3];
    for (int d = 0; d < 3; ++d) cmin[d] = cmax[d] = centre[3 * size_t(order_[size_t(begin)]) + d];
    for (int32_t k = begin; k < end; ++k)
      for (int d = 0; d < 3; ++d) {
        const double c = centre[3 * size_t(order_[size_t(k)]) + d];
        cmin[d] = std::min(cmin[d], c);
        cmax[d] = std::max(cmax[d], c);
      }
    int axis = 0;
    for (int d = 1; d < 3; ++d)
      if (cmax[d] - cmin[d] > cmax[axis] - cmin[axis]) axis = d;
    const int32_t mid = begin + (end - begin) / 2;
    std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                     [&](int32_t a, int32_t b) {
                       const double ca = centre[3 * size_t(a) + axis],
                                    cb = centre[3 * size_t(b) + axis];
                       return ca < cb || (!(cb < ca) && a < b);
                     });
    build_range(begin, mid, centre);
    build_range(mid, end, centre);
  }
  nodes_[size_t(id)].escape = int32_t(nodes_.size());
  return id;
}

void BoxTree::refit(const MatX3& lo, const MatX3& hi) {
  // Reverse depth-first order: children (id + 1 and its escape) before their parent.
  for (auto i = int32_t(nodes_.size()) - 1; i >= 0; --i) {
    Node& n = nodes_[size_t(i)];
    if (n.count > 0) {
      int32_t top = -1;
      for (int d = 0; d < 3; ++d) {
        n.lo[d] = lo(order_[size_t(n.first)], d);
        n.hi[d] = hi(order_[size_t(n.first)], d);
      }
      for (int32_t k = n.first; k < n.first + n.count; ++k) {
        const int32_t item = order_[size_t(k)];
        top = std::max(top, item);
        for (int d = 0; d < 3; ++d) {
          n.lo[d] = std::min(n.lo[d], lo(item, d));
          n.hi[d] = std::max(n.hi[d], hi(item, d));
        }
      }
      n.max_item = top;
    } else {
      const Node& a = nodes_[size_t(i) + 1];
      const Node& b = nodes_[size_t(a.escape)];
      for (int d = 0; d < 3; ++d) {
        n.lo[d] = std::min(a.lo[d], b.lo[d]);
        n.hi[d] = std::max(a.hi[d], b.hi[d]);
      }
      n.max_item = std::max(a.max_item, b.max_item);
    }
  }
}

}  // namespace flagsim
