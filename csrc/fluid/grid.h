// Staggered (MAC) velocity grid (Harlow-Welch 1965; Bridson, "Fluid Simulation" ch. 2), and the
// small array helpers the fluid kernels share.
//
// Domain: nx x ny x nz cubic cells of size h (m), min corner `origin` (m). Cell (i, j, k) spans
// origin + h * [i, i+1] x [j, j+1] x [k, k+1]. One flat array per velocity component, C order
// (k fastest), so numpy sees it as a (n0, n1, n2) view:
//   u: x-faces, point (i, j+1/2, k+1/2) h;  periodic nx x ny x nz,  bounded (nx+1) x ny x nz
//   v: y-faces, point (i+1/2, j, k+1/2) h;  periodic nx x ny x nz,  bounded nx x (ny+1) x nz
//   w: z-faces, point (i+1/2, j+1/2, k) h;  periodic nx x ny x nz,  bounded nx x ny x (nz+1)
// (m/s). In a periodic grid face n of an axis is face 0, so it is stored once.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <vector>

#include "common/memory.h"
#include "common/parallel.h"
#include "common/types.h"

namespace flagsim {

/// 64-byte aligned allocator: FFTW's new-array execute needs every buffer equally aligned. Counts
/// the bytes it holds (aligned_bytes_live, common/memory.h): allocations are rare (construction,
/// set-up; never in a step), so the atomic costs nothing measurable.
template <class T>
struct AlignedAllocator {
  using value_type = T;
  AlignedAllocator() = default;
  template <class U>
  AlignedAllocator(const AlignedAllocator<U>&) {}
  static std::size_t rounded(std::size_t n) {
    const std::size_t bytes = ((n * sizeof(T) + 63) / 64) * 64;
    return bytes == 0 ? 64 : bytes;
  }
  T* allocate(std::size_t n) {
    void* p = std::aligned_alloc(64, rounded(n));
    if (!p) throw std::bad_alloc();
    count_aligned_bytes(std::int64_t(rounded(n)));
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t n) {
    count_aligned_bytes(-std::int64_t(rounded(n)));  // before free: GCC 12 warns (falsely) of a
    std::free(p);                                    // use after free the other way round
  }
  template <class U>
  bool operator==(const AlignedAllocator<U>&) const {
    return true;
  }
  template <class U>
  bool operator!=(const AlignedAllocator<U>&) const {
    return false;
  }
};

template <class T>
using AlignedVector = std::vector<T, AlignedAllocator<T>>;

/// Shape of a 3-D array, C order (index (a*n1 + b)*n2 + c).
struct Shape3 {
  int n[3] = {0, 0, 0};
  std::size_t size() const { return std::size_t(n[0]) * n[1] * n[2]; }
  std::size_t index(int a, int b, int c) const { return (std::size_t(a) * n[1] + b) * n[2] + c; }
};

/// Geometry shared by every grid of one solver (no data).
struct GridGeometry {
  int nx = 0, ny = 0, nz = 0;  ///< cells
  double h = 0;                ///< m, cell size
  Vec3 origin{0, 0, 0};        ///< m, min corner
  bool periodic = true;        ///< false: bounded (tunnel) faces on both ends of every axis
  int n(int d) const { return d == 0 ? nx : (d == 1 ? ny : nz); }
  Shape3 cells() const { return Shape3{{nx, ny, nz}}; }
  /// Shape of velocity component c (0 = u, 1 = v, 2 = w), see the file comment.
  Shape3 face_shape(int c) const {
    Shape3 s = cells();
    if (!periodic) s.n[c] += 1;
    return s;
  }
  /// Staggering offset of component c along axis d, in cells: 0 on the face axis, 1/2 otherwise.
  static double offset(int c, int d) { return c == d ? 0.0 : 0.5; }
  /// World position of node (i, j, k) of component c.
  Vec3 face_position(int c, int i, int j, int k) const {
    return origin + h * Vec3(i + offset(c, 0), j + offset(c, 1), k + offset(c, 2));
  }
  Vec3 extent() const { return h * Vec3(nx, ny, nz); }
};

/// The three staggered velocity components of one grid, scalar T (float or double).
template <class T>
struct MacGrid {
  GridGeometry geo;
  std::array<Shape3, 3> shape;
  std::array<AlignedVector<T>, 3> comp;  ///< u, v, w; shapes in `shape`, m/s

  MacGrid() = default;
  explicit MacGrid(const GridGeometry& g) : geo(g) {
    for (int c = 0; c < 3; ++c) {
      shape[c] = g.face_shape(c);
      comp[c].assign(shape[c].size(), T(0));
    }
  }
  T& at(int c, int i, int j, int k) { return comp[c][shape[c].index(i, j, k)]; }
  T at(int c, int i, int j, int k) const { return comp[c][shape[c].index(i, j, k)]; }
};

/// Copies b into a (same shapes); no allocation.
template <class T>
void copy_grid(const MacGrid<T>& b, MacGrid<T>& a) {
  for (int c = 0; c < 3; ++c) std::copy(b.comp[c].begin(), b.comp[c].end(), a.comp[c].begin());
}

/// Sum of f(i) for i in [begin, end) in a fixed order: 8 interleaved partial sums (i mod 8, so
/// that the additions do not wait on each other and vectorise), added pairwise, then the tail.
template <class F>
double ordered_sum(std::size_t begin, std::size_t end, F& f) {
  double lane[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  std::size_t i = begin;
  for (; i + 8 <= end; i += 8)
    for (int l = 0; l < 8; ++l) lane[l] += f(i + l);
  double s =
      ((lane[0] + lane[1]) + (lane[2] + lane[3])) + ((lane[4] + lane[5]) + (lane[6] + lane[7]));
  for (; i < end; ++i) s += f(i);
  return s;
}

/// Sum of f(i) for i in [0, n), independent of the thread count: fixed blocks summed in parallel
/// (ordered_sum), block sums added in order.
template <class F>
double deterministic_sum(std::size_t n, F&& f) {
  constexpr std::size_t kBlock = 4096;
  constexpr int kMaxBlocks = 256;
  const std::size_t nblocks_needed = (n + kBlock - 1) / kBlock;
  const std::size_t block =
      nblocks_needed <= kMaxBlocks ? kBlock : (n + kMaxBlocks - 1) / kMaxBlocks;
  const long nb = long((n + block - 1) / block);
  double partial[kMaxBlocks];
  // A team only for grids past kGridParallelGrain: the block sums, not the thread count, fix the
  // order, so this changes no bit; a team per dot product of a small CG costs more than it saves
  // (a 7k-cell solve ran 10x slower on a loaded 2-core machine with one).
  parallel_for_if(Index(n) > kGridParallelGrain && nb > 1, nb, [&](Index b) {
    partial[b] = ordered_sum(std::size_t(b) * block, std::min(n, std::size_t(b + 1) * block), f);
  });
  double s = 0;
  for (long b = 0; b < nb; ++b) s += partial[b];
  return s;
}

/// max(0, max of f(i) over [0, n)), +inf if any f(i) is NaN; independent of the thread count.
template <class F>
double parallel_max(std::size_t n, F&& f) {
  auto fold = [&f](double m, long i) {
    const double v = f(std::size_t(i));
    return (v <= m) ? m : ((v == v) ? v : HUGE_VAL);  // a NaN reports as +inf
  };
  double m = 0;
  // No `if` clause: libgomp allocates one-thread teams (see use_team).
  if (use_team(Index(n) > kCopyParallelGrain)) {
#pragma omp parallel for schedule(static) reduction(max : m)
    for (long i = 0; i < long(n); ++i) m = fold(m, i);
  } else {
    for (long i = 0; i < long(n); ++i) m = fold(m, i);
  }
  return m;
}

}  // namespace flagsim
