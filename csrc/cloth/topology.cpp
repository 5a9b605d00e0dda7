#include "cloth/topology.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

namespace flagsim {

namespace {

void add_spring(ClothTopology& t, std::vector<std::array<int32_t, 2>>& s, int a, int b,
                SpringKind kind) {
  s.push_back({a, b});
  t.spring_kind.push_back(kind);
}

// Nearest pinned vertex at rest: a k-d tree over the pins (median splits on the widest axis,
// each range's bounding box kept for pruning), O(N log P) for N queries where the direct search
// was O(N P) (a 40,000 x 6 flag pinned along its long edge took ~50 s). The distance is the
// direct search's expression and ties go to the lowest pin index, so anchors and lengths are
// bit-identical to it.
class NearestPin {
 public:
  NearestPin(const MatX3& x, std::vector<int> pins)
      : x_(x), pins_(std::move(pins)), lo_(pins_.size(), 3), hi_(pins_.size(), 3) {
    if (!pins_.empty()) build(0, int(pins_.size()));
  }

  /// (pin index, distance); (-1, inf) without pins.
  std::pair<int, double> operator()(int i) const {
    best_ = -1;
    best_d_ = std::numeric_limits<double>::infinity();
    if (!pins_.empty()) search(0, int(pins_.size()), i);
    return {best_, best_d_};
  }

 private:
  const MatX3& x_;
  std::vector<int> pins_;  // in tree order: the range [lo, hi) has its median at (lo + hi) / 2
  MatX3 lo_, hi_;          // bounding box of the range whose median sits at this position
  mutable int best_ = -1;
  mutable double best_d_ = 0;

  void build(int lo, int hi) {
    if (hi <= lo) return;
    const int mid = (lo + hi) / 2;
    Vec3 mn = Vec3::Constant(std::numeric_limits<double>::infinity()), mx = -mn;
    for (int k = lo; k < hi; ++k) {
      mn = mn.cwiseMin(x_.row(pins_[k]).transpose());
      mx = mx.cwiseMax(x_.row(pins_[k]).transpose());
    }
    int axis = 0;
    (mx - mn).maxCoeff(&axis);
    std::nth_element(pins_.begin() + lo, pins_.begin() + mid, pins_.begin() + hi,
                     [&](int a, int b) {
                       return x_(a, axis) < x_(b, axis) || (x_(a, axis) == x_(b, axis) && a < b);
                     });
    lo_.row(mid) = mn.transpose();
    hi_.row(mid) = mx.transpose();
    build(lo, mid);
    build(mid + 1, hi);
  }

  void search(int lo, int hi, int i) const {
    if (hi <= lo) return;
    const int mid = (lo + hi) / 2;
    // A lower bound of the distance to any pin of the range; equal distances are visited (for
    // the lowest-index tie-break), with a margin for the bound's own rounding.
    const Vec3 q = x_.row(i).transpose();
    const Vec3 gap =
        (lo_.row(mid).transpose() - q).cwiseMax(q - hi_.row(mid).transpose()).cwiseMax(0.0);
    if (gap.norm() > best_d_ * (1 + 1e-12)) return;
    const int a = pins_[mid];
    const double d = (x_.row(i) - x_.row(a)).norm();
    if (d < best_d_ || (d == best_d_ && a < best_)) {
      best_d_ = d;
      best_ = a;
    }
    // the half nearer the query first
    const int left_mid = (lo + mid) / 2, right_mid = (mid + 1 + hi) / 2;
    const bool left_first =
        mid - lo > 0 &&
        (hi - mid - 1 <= 0 || (x_.row(i) - x_.row(pins_[left_mid])).squaredNorm() <=
                                  (x_.row(i) - x_.row(pins_[right_mid])).squaredNorm());
    search(left_first ? lo : mid + 1, left_first ? mid : hi, i);
    search(left_first ? mid + 1 : lo, left_first ? hi : mid, i);
  }
};

// Rest positions on the grid (row 0 at the top, column 0 at the pole) and texture coordinates.
void place_grid(const FlagParams& p, ClothTopology& t) {
  const int R = t.rows, C = t.cols, N = R * C;
  const double dx = p.width / (C - 1), dy = p.height / (R - 1);
  t.rest_positions.resize(N, 3);
  t.uv.resize(N, 2);
  for (int r = 0; r < R; ++r)
    for (int c = 0; c < C; ++c) {
      t.rest_positions.row(r * C + c) = p.origin + Vec3(c * dx, -r * dy, 0.0);
      t.uv.row(r * C + c) << double(c) / (C - 1), 1.0 - double(r) / (R - 1);
    }
}

// Two triangles per quad, both counter-clockwise seen from +z: (a, c, d) and (a, d, b) with
// a = (r, c), b = (r, c+1), c = (r+1, c), d = (r+1, c+1).
void add_triangles(ClothTopology& t) {
  const int R = t.rows, C = t.cols;
  auto id = [C](int r, int c) { return r * C + c; };
  t.triangles.resize(2 * (R - 1) * (C - 1), 3);
  Index k = 0;
  for (int r = 0; r + 1 < R; ++r)
    for (int c = 0; c + 1 < C; ++c) {
      const int a = id(r, c), b = id(r, c + 1), cc = id(r + 1, c), d = id(r + 1, c + 1);
      t.triangles.row(k++) << a, cc, d;
      t.triangles.row(k++) << a, d, b;
    }
}

// Structural, shear and bend springs (paper eq. 4), their rest lengths, stiffness and damping.
void add_springs(const FlagParams& p, ClothTopology& t) {
  const int R = t.rows, C = t.cols;
  auto id = [C](int r, int c) { return r * C + c; };
  std::vector<std::array<int32_t, 2>> s;
  for (int r = 0; r < R; ++r)
    for (int c = 0; c < C; ++c) {
      if (c + 1 < C) add_spring(t, s, id(r, c), id(r, c + 1), SpringKind::kStructural);
      if (r + 1 < R) add_spring(t, s, id(r, c), id(r + 1, c), SpringKind::kStructural);
      if (r + 1 < R && c + 1 < C) {
        add_spring(t, s, id(r, c), id(r + 1, c + 1), SpringKind::kShear);
        add_spring(t, s, id(r, c + 1), id(r + 1, c), SpringKind::kShear);
      }
      if (c + 2 < C) add_spring(t, s, id(r, c), id(r, c + 2), SpringKind::kBend);
      if (r + 2 < R) add_spring(t, s, id(r, c), id(r + 2, c), SpringKind::kBend);
    }
  const Index S = static_cast<Index>(s.size());
  t.springs.resize(S, 2);
  t.rest_length.resize(S);
  t.stiffness.resize(S);
  t.damping.setConstant(S, p.damping);
  for (Index j = 0; j < S; ++j) {
    t.springs.row(j) << s[j][0], s[j][1];
    t.rest_length[j] = (t.rest_positions.row(s[j][1]) - t.rest_positions.row(s[j][0])).norm();
    switch (t.spring_kind[j]) {
      case SpringKind::kStructural: t.stiffness[j] = p.stretch_stiffness; break;
      case SpringKind::kShear: t.stiffness[j] = p.shear_stiffness; break;
      case SpringKind::kBend: t.stiffness[j] = p.bend_stiffness; break;
    }
  }
}

// Lumped area: a third of every adjacent triangle's rest area; mass = areal density x area.
// Pinned vertices get inv_mass 0.
void lump_mass_and_pin(const FlagParams& p, ClothTopology& t) {
  const int R = t.rows, C = t.cols, N = R * C;
  auto id = [C](int r, int c) { return r * C + c; };
  t.area.setZero(N);
  for (Index f = 0; f < t.triangles.rows(); ++f) {
    const Vec3 e1 =
        t.rest_positions.row(t.triangles(f, 1)) - t.rest_positions.row(t.triangles(f, 0));
    const Vec3 e2 =
        t.rest_positions.row(t.triangles(f, 2)) - t.rest_positions.row(t.triangles(f, 0));
    const double a3 = 0.5 * e1.cross(e2).norm() / 3.0;
    for (int q = 0; q < 3; ++q) t.area[t.triangles(f, q)] += a3;
  }
  t.mass = p.areal_density * t.area;
  t.inv_mass = t.mass.cwiseInverse();
  if (!p.pinned_vertices.empty()) {
    for (int i : p.pinned_vertices) t.inv_mass[i] = 0.0;
  } else if (p.pin == Pin::kPole) {
    for (int r = 0; r < R; ++r) t.inv_mass[id(r, 0)] = 0.0;
  } else if (p.pin == Pin::kGrommets) {
    t.inv_mass[id(0, 0)] = 0.0;
    t.inv_mass[id(R - 1, 0)] = 0.0;
  } else if (p.pin == Pin::kTop) {
    for (int c = 0; c < C; ++c) t.inv_mass[id(0, c)] = 0.0;
  }
}

// The pin farthest from pin `from` at rest (the lowest index among equals).
int farthest_pin(const MatX3& x, const std::vector<int>& pins, int from) {
  int best = pins.front();
  double best_d = -1;
  for (int p : pins) {
    const double d = (x.row(p) - x.row(from)).squaredNorm();
    if (d > best_d) best = p, best_d = d;
  }
  return best;
}

// Tethers to the nearest pin at rest, and to the two pins farthest apart: e0, the farthest from
// the first pin, and e1, the farthest from e0 (the ends of a line of pins).
void attach_tethers(ClothTopology& t) {
  const int N = t.rows * t.cols;
  std::vector<int> pins;
  for (int i = 0; i < N; ++i)
    if (t.inv_mass[i] == 0.0) pins.push_back(i);
  t.tether_anchor.assign(N, -1);
  t.tether_length.setZero(N);
  t.tether_end_anchor.assign(2 * size_t(N), -1);
  t.tether_end_length.setZero(2 * N);
  if (pins.empty()) return;
  const int e0 = farthest_pin(t.rest_positions, pins, pins.front());
  const int ends[2] = {e0, farthest_pin(t.rest_positions, pins, e0)};
  const NearestPin nearest(t.rest_positions, std::move(pins));
  for (int i = 0; i < N; ++i) {
    if (t.inv_mass[i] == 0.0) continue;
    const auto [a, d] = nearest(i);
    t.tether_anchor[i] = a;
    t.tether_length[i] = d;
    for (int k = 0; k < 2; ++k) {
      if (ends[k] == a || (k == 1 && ends[1] == ends[0])) continue;
      t.tether_end_anchor[2 * size_t(i) + k] = ends[k];
      t.tether_end_length[2 * i + k] =
          (t.rest_positions.row(i) - t.rest_positions.row(ends[k])).norm();
    }
  }
}

// Vertex -> spring and vertex -> triangle adjacency (CSR), each in index order for each vertex.
void build_adjacency(ClothTopology& t) {
  const int N = t.rows * t.cols;
  const Index S = t.springs.rows();
  t.adj_offset.assign(N + 1, 0);
  for (Index j = 0; j < S; ++j) {
    ++t.adj_offset[t.springs(j, 0) + 1];
    ++t.adj_offset[t.springs(j, 1) + 1];
  }
  for (int i = 0; i < N; ++i) t.adj_offset[i + 1] += t.adj_offset[i];
  t.adj_spring.resize(2 * S);
  t.adj_other.resize(2 * S);
  std::vector<int32_t> fill(t.adj_offset.begin(), t.adj_offset.end() - 1);
  for (Index j = 0; j < S; ++j) {
    const int a = t.springs(j, 0), b = t.springs(j, 1);
    t.adj_spring[fill[a]] = int32_t(j);
    t.adj_other[fill[a]++] = b;
    t.adj_spring[fill[b]] = int32_t(j);
    t.adj_other[fill[b]++] = a;
  }
  t.tri_adj_offset.assign(N + 1, 0);
  for (Index f = 0; f < t.triangles.rows(); ++f)
    for (int q = 0; q < 3; ++q) ++t.tri_adj_offset[t.triangles(f, q) + 1];
  for (int i = 0; i < N; ++i) t.tri_adj_offset[i + 1] += t.tri_adj_offset[i];
  t.tri_adj.resize(3 * t.triangles.rows());
  fill.assign(t.tri_adj_offset.begin(), t.tri_adj_offset.end() - 1);
  for (Index f = 0; f < t.triangles.rows(); ++f)
    for (int q = 0; q < 3; ++q) t.tri_adj[fill[t.triangles(f, q)]++] = int32_t(f);
}

}  // namespace

ClothTopology build_flag_topology(const FlagParams& p) {
  ClothTopology t;
  t.rows = p.rows;
  t.cols = p.cols;
  place_grid(p, t);
  add_triangles(t);
  add_springs(p, t);
  lump_mass_and_pin(p, t);
  attach_tethers(t);
  build_adjacency(t);
  return t;
}

void compute_vertex_normals(const ClothTopology& topo, const MatX3& x, MatX3& n) {
  n.setZero(x.rows(), 3);
  for (Index f = 0; f < topo.triangles.rows(); ++f) {
    const int a = topo.triangles(f, 0), b = topo.triangles(f, 1), c = topo.triangles(f, 2);
    const Vec3 e1 = x.row(b) - x.row(a), e2 = x.row(c) - x.row(a);
    const Vec3 an = e1.cross(e2);  // |an| = 2 x area: area weighting for free
    n.row(a) += an;
    n.row(b) += an;
    n.row(c) += an;
  }
  for (Index i = 0; i < n.rows(); ++i) {
    const double len = n.row(i).norm();
    if (len > 0)
      n.row(i) /= len;
    else
      n.row(i) << 0, 0, 1;
  }
}

namespace {
// SplitMix64 (Steele, Lea, Flood 2014): a counter-based generator, one independent draw per key.
uint64_t splitmix64(uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
}  // namespace

MatX3 initial_positions(const ClothTopology& topo, const FlagParams& p) {
  MatX3 x = topo.rest_positions;
  if (p.imperfection <= 0) return x;
  for (Index i = 0; i < x.rows(); ++i) {
    if (topo.pinned(i)) continue;
    const uint64_t r = splitmix64((uint64_t(p.imperfection_seed) << 32) ^ uint64_t(i));
    const double u = double(r >> 11) * 0x1.0p-53;  // [0, 1)
    x(i, 2) += p.imperfection * (2.0 * u - 1.0);
  }
  return x;
}

}  // namespace flagsim
