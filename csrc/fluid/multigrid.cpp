#include "fluid/multigrid.h"

#include <algorithm>
#include <cmath>

#include "common/errors.h"
#include "common/parallel.h"
#include "common/simd.h"

namespace flagsim {

namespace {

/// Position of cell k in a row of n2 cells stored as its even k, then its odd k.
inline int split_pos(int k, int n2) { return (k & 1) ? (n2 + 1) / 2 + (k >> 1) : (k >> 1); }

/// Each row of n2 values of v (C order) to its even k, then its odd k (at split_pos).
template <class V>
void split_rows(AlignedVector<V>& v, int n2) {
  if (v.empty()) return;
  AlignedVector<V> row(static_cast<std::size_t>(n2));
  for (std::size_t r = 0; r < v.size() / std::size_t(n2); ++r) {
    V* p = v.data() + r * std::size_t(n2);
    for (int k = 0; k < n2; ++k) row[std::size_t(split_pos(k, n2))] = p[k];
    std::copy(row.begin(), row.end(), p);
  }
}

/// The other two axes of axis d, in order: a face of axis d is indexed (i_a * n_b + i_b).
inline void other_axes(int d, int& a, int& b) {
  a = d == 0 ? 1 : 0;
  b = d == 2 ? 1 : 2;
}

/// Build-time companion of a level: which cells are fluid and the Dirichlet (GhostZero)
/// conductance of each cell on the six domain sides, ghost[2 d + hi] over that side's face.
struct LevelGeometry {
  std::vector<uint8_t> fluid;
  std::array<std::vector<double>, 6> ghost;
};

inline std::size_t face_index(const Shape3& sh, int d, const int ijk[3]) {
  int a, b;
  other_axes(d, a, b);
  return std::size_t(ijk[a]) * sh.n[b] + ijk[b];
}

/// Index of m along an axis of n cells: wrapped when periodic, -1 beyond a bounded end.
inline int wrap(int m, int n, bool periodic) {
  if (m >= 0 && m < n) return m;
  if (!periodic) return -1;
  return ((m % n) + n) % n;
}

/// diag = the six conductances + the Dirichlet ones; inv_diag = 1 / diag on fluid cells.
template <class T>
void finish_operator(MultigridLevel<T>& L, const LevelGeometry& g) {
  const Shape3& sh = L.shape;
  const std::size_t n = sh.size();
  L.diag.assign(n, T(0));
  L.inv_diag.assign(n, T(0));
  for (int i = 0; i < sh.n[0]; ++i)
    for (int j = 0; j < sh.n[1]; ++j)
      for (int k = 0; k < sh.n[2]; ++k) {
        const int ijk[3] = {i, j, k};
        const std::size_t q = sh.index(i, j, k);
        if (!g.fluid[q]) continue;
        double d = 0;
        for (int a = 0; a < 3; ++a) {
          d += double(L.c[a][q]);
          int m[3] = {i, j, k};
          m[a] = wrap(ijk[a] - 1, sh.n[a], L.periodic[a]);
          if (m[a] >= 0) d += double(L.c[a][sh.index(m[0], m[1], m[2])]);
          if (ijk[a] == 0) d += g.ghost[2 * a][face_index(sh, a, ijk)];
          if (ijk[a] == sh.n[a] - 1) d += g.ghost[2 * a + 1][face_index(sh, a, ijk)];
        }
        L.diag[q] = T(d);
        L.inv_diag[q] = d > 0 ? T(1.0 / d) : T(0);
      }
}

/// Level 0 from K: conductance 1 between two fluid cells that are distinct neighbours, ghost 1
/// on a fluid cell beside a GhostZero side.
template <class T>
LevelGeometry fine_level(const Laplace7& op, MultigridLevel<T>& L) {
  const Shape3& sh = op.shape;
  L.shape = sh;
  LevelGeometry g;
  const std::size_t n = sh.size();
  g.fluid.assign(n, 1);
  if (op.solid)
    for (std::size_t q = 0; q < n; ++q) g.fluid[q] = op.solid[q] ? 0 : 1;
  for (int d = 0; d < 3; ++d) {
    L.periodic[d] = op.lo[d] == Side::kPeriodic;
    L.dirichlet[d][0] = op.lo[d] == Side::kGhostZero;
    L.dirichlet[d][1] = op.hi[d] == Side::kGhostZero;
    L.c[d].assign(n, T(0));
    int a, b;
    other_axes(d, a, b);
    for (int s = 0; s < 2; ++s) {
      g.ghost[2 * d + s].assign(std::size_t(sh.n[a]) * sh.n[b], 0.0);
      if ((s == 0 ? op.lo[d] : op.hi[d]) != Side::kGhostZero) continue;
      for (int ia = 0; ia < sh.n[a]; ++ia)
        for (int ib = 0; ib < sh.n[b]; ++ib) {
          int ijk[3];
          ijk[d] = s == 0 ? 0 : sh.n[d] - 1;
          ijk[a] = ia;
          ijk[b] = ib;
          if (g.fluid[sh.index(ijk[0], ijk[1], ijk[2])])
            g.ghost[2 * d + s][std::size_t(ia) * sh.n[b] + ib] = 1.0;
        }
    }
  }
  for (int i = 0; i < sh.n[0]; ++i)
    for (int j = 0; j < sh.n[1]; ++j)
      for (int k = 0; k < sh.n[2]; ++k) {
        const std::size_t q = sh.index(i, j, k);
        if (!g.fluid[q]) continue;
        const int ijk[3] = {i, j, k};
        for (int d = 0; d < 3; ++d) {
          if (sh.n[d] == 1) continue;  // its own neighbour: no coupling
          int m[3] = {i, j, k};
          m[d] = wrap(ijk[d] + 1, sh.n[d], L.periodic[d]);
          if (m[d] >= 0 && g.fluid[sh.index(m[0], m[1], m[2])]) L.c[d][q] = T(1);
        }
      }
  finish_operator(L, g);
  return g;
}

/// Which axes of level F halve (see the header); false everywhere: F is the coarsest.
void choose_halving(const Shape3& sh, const bool periodic[3], const int scale[3], bool halve[3]) {
  int smallest = 1 << 30;
  for (int d = 0; d < 3; ++d)
    if (sh.n[d] > 1) smallest = std::min(smallest, scale[d]);
  for (int d = 0; d < 3; ++d) {
    const bool can = sh.n[d] > 1 && (!periodic[d] || sh.n[d] % 2 == 0);
    halve[d] = can && scale[d] <= smallest;
  }
}

/// Level C (coarse) from level F: fluid when a child is; conductance across a coarse face = the
/// sum of the fine conductances across it times (fine distance / coarse distance) along the
/// face's axis (1/2 when that axis halved). A Dirichlet side holds 0 half a fine cell beyond the
/// domain's face (level 0's ghost cell centre), at (s + 1) / 2 fine cells from the centre of a
/// boundary cell of size s: its conductance scales by (s_F + 1) / (s_C + 1).
template <class T>
LevelGeometry coarse_level(const MultigridLevel<T>& F, const LevelGeometry& gf,
                           MultigridLevel<T>& C) {
  const Shape3& fs = F.shape;
  Shape3 cs;
  for (int d = 0; d < 3; ++d) {
    cs.n[d] = F.halved[d] ? (fs.n[d] + 1) / 2 : fs.n[d];
    C.periodic[d] = F.periodic[d];
    C.dirichlet[d][0] = F.dirichlet[d][0];
    C.dirichlet[d][1] = F.dirichlet[d][1];
    C.scale[d] = F.halved[d] ? 2 * F.scale[d] : F.scale[d];
  }
  C.shape = cs;
  const std::size_t n = cs.size();
  LevelGeometry g;
  g.fluid.assign(n, 0);
  // Children of coarse index I along axis d: [first, last] fine indices.
  auto first = [&](int d, int I) { return F.halved[d] ? 2 * I : I; };
  auto last = [&](int d, int I) { return F.halved[d] ? std::min(2 * I + 1, fs.n[d] - 1) : I; };
  for (int I = 0; I < cs.n[0]; ++I)
    for (int J = 0; J < cs.n[1]; ++J)
      for (int K = 0; K < cs.n[2]; ++K) {
        uint8_t any = 0;
        for (int i = first(0, I); i <= last(0, I); ++i)
          for (int j = first(1, J); j <= last(1, J); ++j)
            for (int k = first(2, K); k <= last(2, K); ++k)
              any |= F.inv_diag[fs.index(i, j, k)] != T(0) ? 1 : 0;
        g.fluid[cs.index(I, J, K)] = any;
      }
  for (int d = 0; d < 3; ++d) {
    C.c[d].assign(n, T(0));
    const double ratio = F.halved[d] ? 0.5 : 1.0;
    const double ghost_ratio = double(F.scale[d] + 1) / double(C.scale[d] + 1);
    int a, b;
    other_axes(d, a, b);
    for (int s = 0; s < 2; ++s) g.ghost[2 * d + s].assign(std::size_t(cs.n[a]) * cs.n[b], 0.0);
    for (int I = 0; I < cs.n[0]; ++I)
      for (int J = 0; J < cs.n[1]; ++J)
        for (int K = 0; K < cs.n[2]; ++K) {
          const int IJK[3] = {I, J, K};
          const std::size_t q = cs.index(I, J, K);
          if (!g.fluid[q]) continue;
          // The fine faces on C's +d side start from the children with the last index along d;
          // on its -d (domain) side from those with the first.
          int lo[3], hi[3];
          for (int e = 0; e < 3; ++e) {
            lo[e] = first(e, IJK[e]);
            hi[e] = last(e, IJK[e]);
          }
          const bool own_neighbour = cs.n[d] == 1;  // periodic, one cell: the face is inside it
          double cond = 0, ghost_lo = 0, ghost_hi = 0;
          for (int i = lo[0]; i <= hi[0]; ++i)
            for (int j = lo[1]; j <= hi[1]; ++j)
              for (int k = lo[2]; k <= hi[2]; ++k) {
                const int ijk[3] = {i, j, k};
                if (ijk[d] == hi[d] && !own_neighbour) cond += double(F.c[d][fs.index(i, j, k)]);
                if (IJK[d] == 0 && ijk[d] == 0) ghost_lo += gf.ghost[2 * d][face_index(fs, d, ijk)];
                if (IJK[d] == cs.n[d] - 1 && ijk[d] == fs.n[d] - 1)
                  ghost_hi += gf.ghost[2 * d + 1][face_index(fs, d, ijk)];
              }
          // Padded odd axis: the last coarse cell's +d face is the domain end (F.c is 0 there).
          C.c[d][q] = T(cond * ratio);
          if (IJK[d] == 0) g.ghost[2 * d][face_index(cs, d, IJK)] = ghost_lo * ghost_ratio;
          if (IJK[d] == cs.n[d] - 1)
            g.ghost[2 * d + 1][face_index(cs, d, IJK)] = ghost_hi * ghost_ratio;
        }
  }
  finish_operator(C, g);
  return g;
}

/// Transfer tables of the pair (F, C = next coarser level) along axis d. Restriction: for each
/// coarse index, 4 (fine index, weight) entries when d halves (weights 1/4 3/4 3/4 1/4, cell
/// centres at (2I + 1/2 +- 1/2 +- 1) fine cells), else 1 (I, 1). Prolongation: for each fine
/// index, 2 (coarse index, weight) entries (3/4 parent, 1/4 its other neighbour), else 1.
/// Entries beyond a bounded end get weight 0 (and a valid index). p_norm: the weight each
/// prolongation entry adds to the normaliser: its own, or beyond a Dirichlet end the weight
/// that makes the interpolation linear to 0 at the Dirichlet point, so the parent's share is
/// (s_F + 1) / (s_C + 1) (see coarse_level); beyond a Neumann end 0 (constant extrapolation).
struct AxisTransfer {
  int r_count = 1, p_count = 1;
  std::vector<int32_t> r_idx, p_idx;
  std::vector<double> r_w, p_w, p_norm;
};

template <class T>
AxisTransfer axis_transfer(const MultigridLevel<T>& F, int d, int nc, int scale_c) {
  const int nf = F.shape.n[d];
  const bool periodic = F.periodic[d];
  AxisTransfer t;
  if (!F.halved[d]) {
    t.r_idx.resize(std::size_t(nc));
    for (int I = 0; I < nc; ++I) t.r_idx[std::size_t(I)] = I;
    t.p_idx = t.r_idx;
    t.r_w.assign(std::size_t(nc), 1.0);
    t.p_w.assign(std::size_t(nf), 1.0);
    t.p_norm = t.p_w;
    return t;
  }
  t.r_count = 4;
  t.p_count = 2;
  t.r_idx.resize(std::size_t(4 * nc));
  t.r_w.resize(std::size_t(4 * nc));
  const double w4[4] = {0.25, 0.75, 0.75, 0.25};
  for (int I = 0; I < nc; ++I)
    for (int e = 0; e < 4; ++e) {
      const int f = wrap(2 * I - 1 + e, nf, periodic);
      t.r_idx[std::size_t(4 * I + e)] = f >= 0 ? f : 0;
      t.r_w[std::size_t(4 * I + e)] = f >= 0 ? w4[e] : 0.0;
    }
  const double parent_share = double(F.scale[d] + 1) / double(scale_c + 1);
  const double dirichlet_weight = 0.75 * (1.0 / parent_share - 1.0);
  t.p_idx.resize(std::size_t(2 * nf));
  t.p_w.resize(std::size_t(2 * nf));
  t.p_norm.resize(std::size_t(2 * nf));
  for (int f = 0; f < nf; ++f) {
    const int I = f / 2;
    const int toward = f % 2 == 0 ? I - 1 : I + 1;
    const int other = wrap(toward, nc, periodic);
    t.p_idx[std::size_t(2 * f)] = I;
    t.p_w[std::size_t(2 * f)] = 0.75;
    t.p_norm[std::size_t(2 * f)] = 0.75;
    t.p_idx[std::size_t(2 * f + 1)] = other >= 0 ? other : I;
    t.p_w[std::size_t(2 * f + 1)] = other >= 0 ? 0.25 : 0.0;
    t.p_norm[std::size_t(2 * f + 1)] =
        other >= 0 ? 0.25 : (F.dirichlet[d][toward < 0 ? 0 : 1] ? dirichlet_weight : 0.0);
  }
  return t;
}

}  // namespace

// ---- set-up
// --------------------------------------------------------------------------------------

namespace {

/// Throws unless op is a pressure operator the hierarchy handles (see build).
void check_sides(const Laplace7& op) {
  for (int d = 0; d < 3; ++d) {
    if (op.lo[d] == Side::kFixed || op.hi[d] == Side::kFixed)
      throw InvalidArgument("multigrid: the operator should have no Fixed side (pressure only)");
    if ((op.lo[d] == Side::kPeriodic) != (op.hi[d] == Side::kPeriodic))
      throw InvalidArgument("multigrid: a periodic axis should be periodic on both sides");
  }
}

/// Level 0 from op, then coarser levels until one is small enough or cannot halve.
template <class T>
std::vector<MultigridLevel<T>> coarsen(const Laplace7& op) {
  std::vector<MultigridLevel<T>> levels(1);
  LevelGeometry geo = fine_level(op, levels[0]);
  while (true) {
    MultigridLevel<T>& F = levels.back();
    if (F.shape.size() <= kCoarsestCells) break;
    choose_halving(F.shape, F.periodic, F.scale, F.halved);
    if (!(F.halved[0] || F.halved[1] || F.halved[2])) break;
    MultigridLevel<T> C;
    geo = coarse_level(F, geo, C);
    levels.push_back(std::move(C));
  }
  return levels;
}

/// L's transfer tables to C (the next coarser level) and inv_norm: 1 / the sum of the
/// prolongation weights from active coarse cells (and from the zero beyond a Dirichlet end).
template <class T>
void build_transfers(MultigridLevel<T>& L, const MultigridLevel<T>& C) {
  std::array<std::vector<double>, 3> p_norm;
  for (int d = 0; d < 3; ++d) {
    AxisTransfer t = axis_transfer(L, d, C.shape.n[d], C.scale[d]);
    L.r_count[d] = t.r_count;
    L.p_count[d] = t.p_count;
    L.r_idx[d] = std::move(t.r_idx);
    L.p_idx[d] = std::move(t.p_idx);
    L.r_w[d].assign(t.r_w.begin(), t.r_w.end());
    L.p_w[d].assign(t.p_w.begin(), t.p_w.end());
    p_norm[d] = std::move(t.p_norm);
  }
  L.inv_norm.assign(L.shape.size(), T(0));
  for (int i = 0; i < L.shape.n[0]; ++i)
    for (int j = 0; j < L.shape.n[1]; ++j)
      for (int k = 0; k < L.shape.n[2]; ++k) {
        const std::size_t q = L.shape.index(i, j, k);
        if (L.inv_diag[q] == T(0)) continue;
        double norm = 0;
        for (int e0 = 0; e0 < L.p_count[0]; ++e0)
          for (int e1 = 0; e1 < L.p_count[1]; ++e1)
            for (int e2 = 0; e2 < L.p_count[2]; ++e2) {
              const std::size_t e[3] = {std::size_t(i * L.p_count[0] + e0),
                                        std::size_t(j * L.p_count[1] + e1),
                                        std::size_t(k * L.p_count[2] + e2)};
              const double w = p_norm[0][e[0]] * p_norm[1][e[1]] * p_norm[2][e[2]];
              if (w == 0) continue;
              bool beyond = false;
              for (int d = 0; d < 3; ++d) beyond = beyond || L.p_w[d][e[d]] == T(0);
              const std::size_t Q =
                  C.shape.index(L.p_idx[0][e[0]], L.p_idx[1][e[1]], L.p_idx[2][e[2]]);
              if (beyond || C.inv_diag[Q] != T(0)) norm += w;
            }
        L.inv_norm[q] = norm > 0 ? T(1.0 / norm) : T(0);
      }
}

/// The coarsest level's matrix on its active cells (dense index: the order of cell_of), one
/// rank-one term added per pocket without a Dirichlet side (its null vector is the pocket's
/// constant: the term pins the pocket's mean).
template <class T>
std::vector<double> coarsest_matrix(const MultigridLevel<T>& L, const std::vector<int32_t>& cell_of,
                                    const std::vector<int32_t>& dense) {
  const Shape3& sh = L.shape;
  const std::size_t m = cell_of.size();
  std::vector<double> A(m * m, 0.0);
  std::vector<double> ghost(m, 0.0);  // each row's Dirichlet conductance
  for (std::size_t r = 0; r < m; ++r) {
    const std::size_t q = std::size_t(cell_of[r]);
    const int ijk[3] = {int(q / (std::size_t(sh.n[1]) * sh.n[2])), int((q / sh.n[2]) % sh.n[1]),
                        int(q % sh.n[2])};
    A[r * m + r] = double(L.diag[q]);
    double off = 0;
    for (int d = 0; d < 3; ++d) {
      for (int s = -1; s <= 1; s += 2) {
        int nb[3] = {ijk[0], ijk[1], ijk[2]};
        nb[d] = wrap(ijk[d] + s, sh.n[d], L.periodic[d]);
        if (nb[d] < 0) continue;
        const std::size_t Q = sh.index(nb[0], nb[1], nb[2]);
        const double cond = double(s > 0 ? L.c[d][q] : L.c[d][Q]);
        if (cond == 0 || dense[Q] < 0) continue;
        A[r * m + std::size_t(dense[Q])] -= cond;
        off += cond;
      }
    }
    ghost[r] = A[r * m + r] - off;
  }
  // Pockets: connected components of the coupling graph (breadth first, in index order).
  std::vector<int32_t> pocket(m, -1), queue, members;
  for (std::size_t s0 = 0; s0 < m; ++s0) {
    if (pocket[s0] >= 0) continue;
    queue.assign(1, int32_t(s0));
    members.clear();
    pocket[s0] = int32_t(s0);
    double dirichlet = 0, top = 0;
    while (!queue.empty()) {
      const std::size_t r = std::size_t(queue.back());
      queue.pop_back();
      members.push_back(int32_t(r));
      dirichlet += ghost[r];
      top = std::max(top, A[r * m + r]);
      for (std::size_t c = 0; c < m; ++c)
        if (c != r && A[r * m + c] != 0 && pocket[c] < 0) {
          pocket[c] = int32_t(s0);
          queue.push_back(int32_t(c));
        }
    }
    if (dirichlet > 0) continue;
    const double w = top / double(members.size());
    for (int32_t r : members)
      for (int32_t c : members) A[std::size_t(r) * m + std::size_t(c)] += w;
  }
  return A;
}

/// A (m x m, row-major) = L L^T: the lower factor in place, the upper triangle zeroed. False
/// (A spoiled) when A is not positive definite.
bool cholesky_in_place(std::vector<double>& A, std::size_t m) {
  for (std::size_t j = 0; j < m; ++j) {
    double d = A[j * m + j];
    for (std::size_t k = 0; k < j; ++k) d -= A[j * m + k] * A[j * m + k];
    if (!(d > 0)) return false;
    const double ljj = std::sqrt(d);
    A[j * m + j] = ljj;
    for (std::size_t i = j + 1; i < m; ++i) {
      double v = A[i * m + j];
      for (std::size_t k = 0; k < j; ++k) v -= A[i * m + k] * A[j * m + k];
      A[i * m + j] = v / ljj;
    }
  }
  for (std::size_t i = 0; i < m; ++i)
    for (std::size_t j = i + 1; j < m; ++j) A[i * m + j] = 0;
  return true;
}

}  // namespace

template <class T>
void PoissonMultigrid<T>::build(const Laplace7& op) {
  check_sides(op);
  levels_ = coarsen<MgScalar>(op);
  for (std::size_t l = 0; l + 1 < levels_.size(); ++l) build_transfers(levels_[l], levels_[l + 1]);
  allocate_scratch();
  build_product(op);
  factor_coarsest();
  split_layout();
}

template <class T>
void PoissonMultigrid<T>::allocate_scratch() {
  using F32 = MgScalar;
  std::size_t widest = 1;
  for (std::size_t l = 0; l < levels_.size(); ++l) {
    MultigridLevel<F32>& L = levels_[l];
    const std::size_t n = L.shape.size();
    widest = std::max(widest, std::size_t(L.shape.n[2]));
    L.passes = 1;
    for (int d = 0; d < 3; ++d)
      if (L.periodic[d] && L.shape.n[d] > 1 && L.shape.n[d] % 2 == 1) ++L.passes;
    L.x.assign(n, F32(0));
    L.b.assign(n, F32(0));
    if (l + 1 < levels_.size()) L.r.assign(n, F32(0));
  }
  zero_row_.assign(widest, F32(0));
  parity_.resize(widest + 1);
  for (std::size_t k = 0; k <= widest; ++k) parity_[k] = F32((k & 1) == 0 ? 1 : 0);
  zero_row_t_.assign(widest, T(0));
}

template <class T>
void PoissonMultigrid<T>::build_product(const Laplace7& op) {
  product_ = MultigridLevel<T>();
  product_.shape = levels_[0].shape;
  for (int d = 0; d < 3; ++d) product_.periodic[d] = levels_[0].periodic[d];
  product_.unit = true;
  product_.diag.assign(levels_[0].diag.begin(), levels_[0].diag.end());
  singular_ = op.singular();
  n_active_ = 0;
  for (MgScalar d : levels_[0].diag) n_active_ += d != MgScalar(0) ? 1 : 0;
  any_inactive_ = n_active_ < product_.shape.size();
  for (auto& p : part_) p.assign(std::size_t(product_.shape.n[0]), 0.0);
}

template <class T>
void PoissonMultigrid<T>::factor_coarsest() {
  const MultigridLevel<MgScalar>& L = levels_.back();
  cell_of_.clear();
  chol_.clear();
  rhs_.clear();
  std::vector<int32_t> dense(L.shape.size(), -1);
  for (std::size_t q = 0; q < L.shape.size(); ++q)
    if (L.inv_diag[q] != MgScalar(0)) {
      dense[q] = int32_t(cell_of_.size());
      cell_of_.push_back(int32_t(q));
    }
  const std::size_t m = cell_of_.size();
  if (m == 0 || m > kMaxDirectCells) {  // sweep instead
    cell_of_.clear();
    return;
  }
  std::vector<double> A = coarsest_matrix(L, cell_of_, dense);
  if (!cholesky_in_place(A, m)) {  // not positive definite after all: sweep instead
    cell_of_.clear();
    return;
  }
  chol_ = std::move(A);
  rhs_.assign(m, 0.0);
}

template <class T>
void PoissonMultigrid<T>::split_layout() {
  // Level 0 runs on unit conductances (x = 0 on its solid cells): its c arrays go.
  MultigridLevel<MgScalar>& L0 = levels_[0];
  L0.unit = true;
  for (int d = 0; d < 3; ++d) AlignedVector<MgScalar>().swap(L0.c[d]);
  // Every level's per-cell arrays, and CG's diagonal, to rows split by the parity of k (see the
  // cycle's kernels): CG runs on the split rows too.
  for (MultigridLevel<MgScalar>& L : levels_) {
    for (int d = 0; d < 3; ++d) split_rows(L.c[d], L.shape.n[2]);
    split_rows(L.diag, L.shape.n[2]);
    split_rows(L.inv_diag, L.shape.n[2]);
    split_rows(L.inv_norm, L.shape.n[2]);
  }
  split_rows(product_.diag, product_.shape.n[2]);
  MultigridLevel<MgScalar>& C = levels_.back();
  const int n2 = C.shape.n[2];
  for (int32_t& q : cell_of_) q = q - q % n2 + split_pos(q % n2, n2);
}

template <class T>
std::size_t PoissonMultigrid<T>::bytes() const {
  using F32 = MgScalar;
  std::size_t b = 0;
  for (const MultigridLevel<F32>& L : levels_) {
    for (int d = 0; d < 3; ++d)
      b += L.c[d].size() * sizeof(F32) + L.r_idx[d].size() * 4 + L.p_idx[d].size() * 4 +
           (L.r_w[d].size() + L.p_w[d].size()) * sizeof(F32);
    b += (L.diag.size() + L.inv_diag.size() + L.x.size() + L.b.size() + L.r.size() +
          L.inv_norm.size()) *
         sizeof(F32);
  }
  return b + product_.diag.size() * sizeof(T) + zero_row_.size() * sizeof(F32) +
         zero_row_t_.size() * sizeof(T) + cell_of_.size() * 4 +
         (chol_.size() + rhs_.size()) * sizeof(double);
}

// ---- the cycle
// -----------------------------------------------------------------------------------

/// What the row kernels read of one level, and the operation's inputs.
template <class T>
struct LevelArgs {
  using Scalar = T;
  const MultigridLevel<T>* L = nullptr;
  const T* zero = nullptr;  // a zero row: the neighbour beyond a bounded end (or of a 1-cell axis)
  const T* b = nullptr;
  T* x = nullptr;
  T* r = nullptr;  // residual (or product): out
  int colour = 0, pass = 0;
  const MultigridLevel<T>* coarse = nullptr;  // transfers: the next coarser level
  T* b_coarse = nullptr;                      // restriction: out
  // Level 0's entry and exit in the grid's precision (double or float): r in, z out.
  const void* in = nullptr;
  void* out = nullptr;
  bool io_double = false;
  bool io_split = false;          // in (entry) already split by the parity of k; exit: no z out
  bool first_half_sweep = false;  // entry: also the first half-sweep from x = 0
  // Residual and prolongation: colour 0's cells only (one wrap pass only). Right after a
  // half-sweep of colour 1 its residual is 0 (to round-off): the restriction reads it as 0; the
  // prolongation leaves colour 1 alone, as the half-sweep of colour 1 that follows it
  // overwrites those cells without reading them.
  bool colour0_only = false;
  const T* parity = nullptr;  // 1, 0, 1, 0, ... (a row and one more)
  // CG on level 0 (in the grid's precision), per-plane partial sums (fixed order in a plane):
  double* sums = nullptr;            // product: s . q; exit: r . z; update: sum r
  double* sums2 = nullptr;           // exit: sum z; update: max |r|
  const T* cg_r = nullptr;           // exit: r (its dot with z)
  const MgScalar* cg_z = nullptr;    // s update: z (level 0's x of the V-cycle)
  const MgScalar* diag_f = nullptr;  // CG's product: level 0's diag (exact small integers)
  T *cg_x = nullptr, *cg_s = nullptr, *cg_q = nullptr, *cg_rw = nullptr;
  double alpha = 0, beta = 0, mean = 0;
};

namespace {

// ---- the V-cycle's kernels, on rows split by the parity of k
// -------------------------------------- A level stores each row as its even k (positions [0, ne))
// then its odd k ([ne, n2)): one colour of a red-black half-sweep is then one contiguous half-row,
// whose k-neighbours are the other half at offsets 0 and -1 (even half) or +1 and 0 (odd half); the
// neighbouring rows' cells with the same k sit at the same positions. Halving k maps fine k = 2K,
// 2K + 1 to the even and odd halves at K, so the transfers are contiguous too.

inline int half_len(int n2, int h) { return h == 0 ? (n2 + 1) / 2 : n2 / 2; }

/// The four neighbouring rows of (i, j) (the zero row beyond a bounded end), the conductances to
/// them and along k, in the split layout.
template <class T>
struct SplitRow {
  const T *xim, *xip, *xjm, *xjp;
  const T *cim, *cip, *cjm, *cjp, *ck;
  std::size_t base;
  int n2, ne;
  bool wrap2;
};

template <class T>
FLAGSIM_INLINE SplitRow<T> split_row(const LevelArgs<T>& a, int i, int j) {
  const MultigridLevel<T>& L = *a.L;
  const Shape3& sh = L.shape;
  auto nb = [&](int m, int d) { return sh.n[d] > 1 ? wrap(m, sh.n[d], L.periodic[d]) : -1; };
  const int im = nb(i - 1, 0), ip = nb(i + 1, 0), jm = nb(j - 1, 1), jp = nb(j + 1, 1);
  SplitRow<T> w;
  w.base = sh.index(i, j, 0);
  const T* x = a.x;
  w.xim = im >= 0 ? x + sh.index(im, j, 0) : a.zero;
  w.xip = ip >= 0 ? x + sh.index(ip, j, 0) : a.zero;
  w.xjm = jm >= 0 ? x + sh.index(i, jm, 0) : a.zero;
  w.xjp = jp >= 0 ? x + sh.index(i, jp, 0) : a.zero;
  if (L.unit) {
    w.cim = w.cip = w.cjm = w.cjp = w.ck = nullptr;
  } else {
    w.cim = im >= 0 ? L.c[0].data() + sh.index(im, j, 0) : a.zero;
    w.cip = L.c[0].data() + w.base;
    w.cjm = jm >= 0 ? L.c[1].data() + sh.index(i, jm, 0) : a.zero;
    w.cjp = L.c[1].data() + w.base;
    w.ck = L.c[2].data() + w.base;
  }
  w.n2 = sh.n[2];
  w.ne = (w.n2 + 1) / 2;
  w.wrap2 = L.periodic[2] && w.n2 > 1;
  return w;
}

/// The cells of half h of a row outside split_interior's interior (at most two; all of them on a
/// row of at most 3 cells): their split positions and those of their k - 1 and k + 1 (-1: none,
/// beyond a bounded end), the same for every row of a level.
struct HalfEnds {
  int n = 0;
  int q[4], qm[4], qp[4];
  HalfEnds(int n2, bool wrap2, int h, bool skip_last) {
    const int ne = (n2 + 1) / 2, no = n2 / 2;
    const int lo = h == 0 ? 1 : 0, hi = h == 0 ? no : std::min(no, ne - 1);
    const int len = h == 0 ? ne : no;
    auto add = [&](int e) {
      const int k = 2 * e + h;
      if (skip_last && k == n2 - 1) return;
      const int km = k > 0 ? k - 1 : (wrap2 ? n2 - 1 : -1);
      const int kp = k + 1 < n2 ? k + 1 : (wrap2 ? 0 : -1);
      q[n] = split_pos(k, n2);
      qm[n] = km >= 0 ? split_pos(km, n2) : -1;
      qp[n] = kp >= 0 ? split_pos(kp, n2) : -1;
      ++n;
    };
    if (hi <= lo) {
      for (int e = 0; e < len; ++e) add(e);
    } else {
      for (int e = 0; e < lo; ++e) add(e);
      for (int e = hi; e < len; ++e) add(e);
    }
  }
};

/// The rows of plane i in order, their SplitRow advanced row by row: the plane's neighbouring
/// planes and the wraps along j are looked up once per plane, not per row (split_row's result,
/// the same pointers); with each half's end cells (the same for every row).
template <class T>
struct RowWalker {
  SplitRow<T> w;
  HalfEnds ends[2];
  const T *x, *zero, *c1;
  std::size_t plane;  // index of (i, 0, 0)
  int n1;
  bool wrap1;  // j wraps (periodic, more than one row)
  FLAGSIM_INLINE RowWalker(const LevelArgs<T>& a, int i)
      : w(split_row(a, i, 0)),
        ends{HalfEnds(w.n2, w.wrap2, 0, false), HalfEnds(w.n2, w.wrap2, 1, false)} {
    const MultigridLevel<T>& L = *a.L;
    x = a.x;
    zero = a.zero;
    c1 = L.unit ? nullptr : L.c[1].data();
    plane = w.base;
    n1 = L.shape.n[1];
    wrap1 = L.periodic[1] && n1 > 1;
  }
  /// Row j's pointers (j = 0, 1, ... in order; row 0 is set by the constructor).
  FLAGSIM_INLINE void to_row(int j) {
    if (j == 0) return;
    const std::size_t n2 = std::size_t(w.n2);
    w.base += n2;
    if (w.xim != zero) w.xim += n2;
    if (w.xip != zero) w.xip += n2;
    w.xjm = x + w.base - n2;
    w.xjp = j + 1 < n1 ? x + w.base + n2 : (wrap1 ? x + plane : zero);
    if (c1) {
      if (w.cim != zero) w.cim += n2;
      w.cip += n2;
      w.cjm = c1 + w.base - n2;
      w.cjp += n2;
      w.ck += n2;
    }
  }
};

/// sum over the six neighbours of conductance * x at split position q (xr: x of the row), the
/// k-neighbours at positions qm (k - 1, also where c along k couples it) and qp (k + 1), S one
/// lane type. One expression for every lane width: the same bits.
template <bool Unit, class S, class T>
FLAGSIM_INLINE S split_sum(const SplitRow<T>& w, const T* xr, int q, const S& xkm, const S& xkp,
                           const S& ckm) {
  const S xim = load_lanes<S>(w.xim + q), xip = load_lanes<S>(w.xip + q);
  const S xjm = load_lanes<S>(w.xjm + q), xjp = load_lanes<S>(w.xjp + q);
  (void)xr;
  if constexpr (Unit) {
    (void)ckm;
    return ((((xim + xip) + xjm) + xjp) + xkm) + xkp;
  } else {
    return ((((load_lanes<S>(w.cim + q) * xim + load_lanes<S>(w.cip + q) * xip) +
              load_lanes<S>(w.cjm + q) * xjm) +
             load_lanes<S>(w.cjp + q) * xjp) +
            ckm * xkm) +
           load_lanes<S>(w.ck + q) * xkp;
  }
}

/// The sum at natural index k (any k: the row's ends wrap or see zero).
template <bool Unit, class T>
FLAGSIM_INLINE T split_cell_sum(const SplitRow<T>& w, const T* xr, int k) {
  const int n2 = w.n2;
  T xkm = T(0), xkp = T(0), ckm = T(0);
  const int km = k > 0 ? k - 1 : (w.wrap2 ? n2 - 1 : -1);
  const int kp = k + 1 < n2 ? k + 1 : (w.wrap2 ? 0 : -1);
  if (km >= 0) {
    xkm = xr[split_pos(km, n2)];
    if (!Unit) ckm = w.ck[split_pos(km, n2)];
  }
  if (kp >= 0) xkp = xr[split_pos(kp, n2)];
  return split_sum<Unit, T>(w, xr, split_pos(k, n2), xkm, xkp, ckm);
}

/// body(q, sum) over the interior of half h of a row (positions whose k-neighbours are both
/// inside the row), by vectors of L::W lanes and then one by one; returns the interior's
/// [first, last) in half-row indices through lo and hi. body must give the same result when
/// called twice for a position (the last vector may overlap the one before).
template <bool Unit, class L, class T, class Body>
FLAGSIM_INLINE void split_interior(const SplitRow<T>& w, const T* xr, int h, int& lo, int& hi,
                                   const Body& body) {
  const int ne = w.ne, no = w.n2 / 2;
  // even half e: k - 1 = odd e - 1, k + 1 = odd e; odd half o: k - 1 = even o, k + 1 = even o + 1
  lo = h == 0 ? 1 : 0;
  hi = h == 0 ? no : std::min(no, ne - 1);
  const int off = h == 0 ? 0 : ne;
  const int km = h == 0 ? ne - 1 : 0;  // position of k - 1 for half index 0
  const int kp = h == 0 ? ne : 1;      // position of k + 1 for half index 0
  int e = lo;
#ifdef FLAGSIM_HAVE_VECTORS
  if constexpr (!std::is_void<L>::value) {
    auto chunk = [&](auto lanes, int c) FLAGSIM_INLINE_LAMBDA {
      using S = decltype(lanes);
      S ckm{};
      if constexpr (!Unit) ckm = load_lanes<S>(w.ck + km + c);
      body(off + c, split_sum<Unit, S>(w, xr, off + c, load_lanes<S>(xr + km + c),
                                       load_lanes<S>(xr + kp + c), ckm));
    };
    using S = typename L::V;
    for (; e + L::W <= hi; e += L::W) chunk(S{}, e);
    // The rest as one more vector ending at hi, overlapping the last: a cell's value depends
    // only on the other half and the other rows, so computing it twice gives it twice.
    if (e < hi && hi - lo >= L::W) {
      chunk(S{}, hi - L::W);
      e = hi;
    }
    // A half shorter than a wide vector (the coarse levels' rows): the same with 16-byte
    // vectors, the same bits per lane.
    if constexpr (sizeof(S) > 16) {
      using N = Lanes16<T>;
      if (e < hi && hi - lo >= N::W) {
        for (; e + N::W <= hi; e += N::W) chunk(typename N::V{}, e);
        if (e < hi) {
          chunk(typename N::V{}, hi - N::W);
          e = hi;
        }
      }
    }
  }
#endif
  for (; e < hi; ++e) {
    T ckm = T(0);
    if constexpr (!Unit) ckm = w.ck[km + e];
    body(off + e, split_sum<Unit, T>(w, xr, off + e, xr[km + e], xr[kp + e], ckm));
  }
}

/// f(e) for the half-row indices in [0, n) outside the interior [lo, hi).
template <class F>
FLAGSIM_INLINE void for_each_end(int n, int lo, int hi, const F& f) {
  if (hi <= lo) {
    for (int e = 0; e < n; ++e) f(e);
    return;
  }
  for (int e = 0; e < lo; ++e) f(e);
  for (int e = hi; e < n; ++e) f(e);
}

/// Gauss-Seidel on the cells of one colour (parity of i + j + k: one half of each row) and one
/// wrap pass, plane i: x <- (b + neighbour_sum) / diag.
struct SmoothPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const MultigridLevel<T>& Lv = *a.L;
    const Shape3& sh = Lv.shape;
    const int n0 = sh.n[0], n1 = sh.n[1], n2 = sh.n[2];
    if (Lv.passes == 1) {  // no wrap pass: every row whole, its ends from a table
      RowWalker<T> rw(a, i);
      for (int j = 0; j < n1; ++j) {
        rw.to_row(j);
        const SplitRow<T>& w = rw.w;
        T* xr = a.x + w.base;
        const T* br = a.b + w.base;
        const T* dr = Lv.inv_diag.data() + w.base;
        const int h = (a.colour + i + j) & 1;  // the half (parity of k) of this colour
        int lo, hi;
        split_interior<Unit, L>(
            w, xr, h, lo, hi, [&](int q, const auto& sum) FLAGSIM_INLINE_LAMBDA {
              using S = std::decay_t<decltype(sum)>;
              store_lanes(xr + q, load_lanes<S>(dr + q) * (load_lanes<S>(br + q) + sum));
            });
        const HalfEnds& E = rw.ends[h];
        for (int t = 0; t < E.n; ++t) {
          const int q = E.q[t], qm = E.qm[t], qp = E.qp[t];
          const T xkm = qm >= 0 ? xr[qm] : T(0), xkp = qp >= 0 ? xr[qp] : T(0);
          T ckm = T(0);
          if constexpr (!Unit) ckm = qm >= 0 ? w.ck[qm] : T(0);
          xr[q] = dr[q] * (br[q] + split_sum<Unit, T>(w, xr, q, xkm, xkp, ckm));
        }
      }
      return;
    }
    const bool odd0 = Lv.periodic[0] && n0 > 1 && n0 % 2 == 1;
    const bool odd1 = Lv.periodic[1] && n1 > 1 && n1 % 2 == 1;
    const bool odd2 = Lv.periodic[2] && n2 > 1 && n2 % 2 == 1;
    for (int j = 0; j < n1; ++j) {
      const int row_pass = (odd0 && i == n0 - 1 ? 1 : 0) + (odd1 && j == n1 - 1 ? 1 : 0);
      if (row_pass > a.pass) continue;
      const SplitRow<T> w = split_row(a, i, j);
      T* xr = a.x + w.base;
      const T* br = a.b + w.base;
      const T* dr = Lv.inv_diag.data() + w.base;
      const int h = (a.colour + i + j) & 1;  // the half (parity of k) of this colour
      auto update = [&](int k) FLAGSIM_INLINE_LAMBDA {
        const int q = split_pos(k, n2);
        xr[q] = dr[q] * (br[q] + split_cell_sum<Unit>(w, xr, k));
      };
      if (row_pass == a.pass) {
        int lo, hi;
        split_interior<Unit, L>(
            w, xr, h, lo, hi, [&](int q, const auto& sum) FLAGSIM_INLINE_LAMBDA {
              using S = std::decay_t<decltype(sum)>;
              store_lanes(xr + q, load_lanes<S>(dr + q) * (load_lanes<S>(br + q) + sum));
            });
        // the half's ends, by natural k (an odd periodic axis: its last cell in the next pass)
        for_each_end(half_len(n2, h), lo, hi, [&](int e) FLAGSIM_INLINE_LAMBDA {
          const int k = 2 * e + h;
          if (!(odd2 && k == n2 - 1)) update(k);
        });
      } else if (odd2 && row_pass + 1 == a.pass && ((n2 - 1) & 1) == h) {
        update(n2 - 1);
      }
    }
  }
};

/// f(q, sum) for every position q of row w (x of the row: xr), sum the neighbour sum there: by
/// vectors of L::W lanes inside each half, one by one at its ends (ends: the row's HalfEnds of
/// half 0 and 1, no cell skipped). f takes a lane type or T and must give the same result when
/// called twice for a position (see split_interior). only >= 0: that half alone.
template <bool Unit, class L, class T, class F>
FLAGSIM_INLINE void each_cell_sum(const SplitRow<T>& w, const T* xr, const HalfEnds* ends,
                                  const F& f, int only = -1) {
  for (int h = 0; h < 2; ++h) {
    if (only >= 0 && h != only) continue;
    int lo, hi;
    split_interior<Unit, L>(w, xr, h, lo, hi, f);
    const HalfEnds& E = ends[h];
    for (int t = 0; t < E.n; ++t) {
      const int q = E.q[t], qm = E.qm[t], qp = E.qp[t];
      const T xkm = qm >= 0 ? xr[qm] : T(0), xkp = qp >= 0 ? xr[qp] : T(0);
      T ckm = T(0);
      if constexpr (!Unit) ckm = qm >= 0 ? w.ck[qm] : T(0);
      f(q, split_sum<Unit, T>(w, xr, q, xkm, xkp, ckm));
    }
  }
}

/// r = (b - A x) * inv_norm on plane i: the residual, weighted for the restriction.
struct ResidualPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const MultigridLevel<T>& Lv = *a.L;
    RowWalker<T> rw(a, i);
    for (int j = 0; j < Lv.shape.n[1]; ++j) {
      rw.to_row(j);
      const SplitRow<T>& w = rw.w;
      const T* xr = a.x + w.base;
      const T* br = a.b + w.base;
      const T* dg = Lv.diag.data() + w.base;
      const T* nr = Lv.inv_norm.data() + w.base;
      T* rr = a.r + w.base;
      // colour 0's half only: colour 1's residual is 0, which the restriction takes as read
      const int only = a.colour0_only ? (i + j) & 1 : -1;
      each_cell_sum<Unit, L>(
          w, xr, rw.ends,
          [&](int q, const auto& sum) FLAGSIM_INLINE_LAMBDA {
            using S = std::decay_t<decltype(sum)>;
            const S ax = load_lanes<S>(dg + q) * load_lanes<S>(xr + q) - sum;
            store_lanes(rr + q, load_lanes<S>(nr + q) * (load_lanes<S>(br + q) - ax));
          },
          only);
    }
  }
};

/// The first half-sweep from x = 0 on a coarse level (one wrap pass only): colour 0 (one half of
/// each row) sees no neighbour yet, x = b / diag there; colour 1 stays 0.
struct FirstHalfSweepPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const MultigridLevel<T>& Lv = *a.L;
    const int n1 = Lv.shape.n[1], n2 = Lv.shape.n[2], ne = (n2 + 1) / 2;
    for (int j = 0; j < n1; ++j) {
      const std::size_t base = Lv.shape.index(i, j, 0);
      const T* br = a.b + base;
      const T* dr = Lv.inv_diag.data() + base;
      T* xr = a.x + base;
      const int h = (i + j) & 1;
      const int lo = h == 0 ? 0 : ne, hi = h == 0 ? ne : n2;
      for (int q = 0; q < lo; ++q) xr[q] = T(0);
      for (int q = lo; q < hi; ++q) xr[q] = dr[q] * br[q];
      for (int q = hi; q < n2; ++q) xr[q] = T(0);
    }
  }
};

/// Partial sums in a fixed order that does not depend on the vector width: 8 interleaved lanes
/// (the compiler vectorises them), added pairwise when read.
struct Lanes8 {
  double v[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  double tail = 0;
  template <class F>
  FLAGSIM_INLINE void add(int n, const F& f) {
    int k = 0;
    for (; k + 8 <= n; k += 8)
      for (int l = 0; l < 8; ++l) v[l] += f(k + l);
    for (; k < n; ++k) tail += f(k);
  }
  double sum() const {
    return (((v[0] + v[1]) + (v[2] + v[3])) + ((v[4] + v[5]) + (v[6] + v[7]))) + tail;
  }
};

/// CG's update on plane i: x += alpha s, r -= alpha q; sums: sum r, sums2: max |r|.
struct UpdatePlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const Shape3& sh = a.L->shape;
    const std::size_t base = sh.index(i, 0, 0);
    const int n = sh.n[1] * sh.n[2];
    T* x = a.cg_x + base;
    T* r = a.cg_rw + base;
    const T* s = a.cg_s + base;
    const T* q = a.cg_q + base;
    const T al = T(a.alpha);
    int k = 0;
#ifdef FLAGSIM_HAVE_VECTORS
    if constexpr (!std::is_void<L>::value) {
      using S = typename L::V;
      for (; k + L::W <= n; k += L::W) {
        store_lanes(x + k, load_lanes<S>(x + k) + al * load_lanes<S>(s + k));
        store_lanes(r + k, load_lanes<S>(r + k) - al * load_lanes<S>(q + k));
      }
    }
#endif
    for (; k < n; ++k) {
      x[k] = x[k] + al * s[k];
      r[k] = r[k] - al * q[k];
    }
    Lanes8 sums;
    sums.add(n, [&](int c) { return double(r[c]); });
    double m8[8] = {0, 0, 0, 0, 0, 0, 0, 0}, top = 0;  // max |r|: any order gives the same
    int c = 0;
    for (; c + 8 <= n; c += 8)
      for (int l = 0; l < 8; ++l) {
        const double v = std::fabs(double(r[c + l]));
        m8[l] = v > m8[l] ? v : m8[l];
      }
    for (; c < n; ++c) top = std::max(top, double(std::fabs(r[c])));
    for (double v : m8) top = std::max(top, v);
    const double sum = sums.sum();
    a.sums[i] = sum;
    a.sums2[i] = top;
  }
};

#ifdef FLAGSIM_HAVE_VECTORS
/// A vector of floats, Bytes long: a lane type's lanes as the V-cycle's scalar.
template <int Bytes>
struct FloatLanes;
template <>
struct FloatLanes<8> {
  typedef float V __attribute__((vector_size(8)));
};
template <>
struct FloatLanes<16> {
  typedef float V __attribute__((vector_size(16)));
};
template <>
struct FloatLanes<32> {
  typedef float V __attribute__((vector_size(32)));
};
static_assert(std::is_same<MgScalar, float>::value, "FloatLanes: the V-cycle runs in float");
#endif

/// CG's new direction on plane i: s = (z - mean) + beta s, z = the V-cycle's level-0 x (float,
/// split as s), the mean only on unknowns (diag != 0).
struct DirectionPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const Shape3& sh = a.L->shape;
    const std::size_t base = sh.index(i, 0, 0);
    const int n = sh.n[1] * sh.n[2];
    T* s = a.cg_s + base;
    const MgScalar* z = a.cg_z + base;
    const T* dg = a.L->diag.data() + base;
    const T be = T(a.beta), m = T(a.mean);
    int k = 0;
#ifdef FLAGSIM_HAVE_VECTORS
    if constexpr (!std::is_void<L>::value) {
      using S = typename L::V;
      using Z = typename FloatLanes<int(sizeof(MgScalar)) * L::W>::V;
      const S zero{};
      if (m == T(0)) {  // z - 0 = z: the diagonal is not read
        for (; k + L::W <= n; k += L::W)
          store_lanes(s + k,
                      __builtin_convertvector(load_lanes<Z>(z + k), S) + be * load_lanes<S>(s + k));
      } else {
        for (; k + L::W <= n; k += L::W) {
          const S zk = __builtin_convertvector(load_lanes<Z>(z + k), S);
          const S mk = load_lanes<S>(dg + k) == zero ? zero : zero + m;
          store_lanes(s + k, (zk - mk) + be * load_lanes<S>(s + k));
        }
      }
    }
#endif
    if (m == T(0))
      for (; k < n; ++k) s[k] = T(z[k]) + be * s[k];
    else
      for (; k < n; ++k) s[k] = (T(z[k]) - (dg[k] == T(0) ? T(0) : m)) + be * s[k];
  }
};

/// y = A x on plane i (0 on inactive cells, where diag is 0), x = 0 on solid cells: level 0's
/// product for CG, on rows split by the parity of k as the cycle's; with sums, x . y per plane in
/// storage order.
struct ProductPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const MultigridLevel<T>& Lv = *a.L;
    const int n1 = Lv.shape.n[1], n2 = Lv.shape.n[2];
    RowWalker<T> rw(a, i);
    for (int j = 0; j < n1; ++j) {
      rw.to_row(j);
      const SplitRow<T>& w = rw.w;
      const T* xr = a.x + w.base;
      const MgScalar* dg = a.diag_f + w.base;
      T* yr = a.r + w.base;
      each_cell_sum<Unit, L>(w, xr, rw.ends, [&](int q, const auto& sum) FLAGSIM_INLINE_LAMBDA {
        using S = std::decay_t<decltype(sum)>;
        const S zero{};
        S d;
        if constexpr (std::is_same<S, T>::value) {
          d = T(dg[q]);
        } else {
#ifdef FLAGSIM_HAVE_VECTORS
          using Z = typename FloatLanes<int(sizeof(MgScalar) * sizeof(S) / sizeof(T))>::V;
          d = __builtin_convertvector(load_lanes<Z>(dg + q), S);
#endif
        }
        store_lanes(yr + q, d == zero ? zero : d * load_lanes<S>(xr + q) - sum);
      });
    }
    if (!a.sums) return;
    const std::size_t base = Lv.shape.index(i, 0, 0);
    const T* x = a.x + base;
    const T* y = a.r + base;
    Lanes8 dots;
    dots.add(n1 * n2, [&](int q) { return double(x[q]) * double(y[q]); });
    a.sums[i] = dots.sum();
  }
};

/// MGPCG's start on plane i, before the product: x (natural: cg_x) and b (natural: in) to rows
/// split by the parity of k, x into cg_s (0 on the cells that are no unknowns, where diag is 0)
/// and b into cg_rw; sums: max |b| over the unknowns.
struct StartPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const Shape3& sh = a.L->shape;
    const int n1 = sh.n[1], n2 = sh.n[2], ne = (n2 + 1) / 2, no = n2 / 2;
    double top = 0;
    for (int j = 0; j < n1; ++j) {
      const std::size_t base = sh.index(i, j, 0);
      const T* xn = a.cg_x + base;
      const T* bn = static_cast<const T*>(a.in) + base;
      const T* dg = a.L->diag.data() + base;
      T* xs = a.cg_s + base;
      T* rs = a.cg_rw + base;
      for (int e = 0; e < ne; ++e) {
        xs[e] = xn[2 * e];
        rs[e] = bn[2 * e];
      }
      for (int o = 0; o < no; ++o) {
        xs[ne + o] = xn[2 * o + 1];
        rs[ne + o] = bn[2 * o + 1];
      }
      for (int q = 0; q < n2; ++q) {
        if (dg[q] == T(0))
          xs[q] = T(0);
        else
          top = std::max(top, std::fabs(double(rs[q])));
      }
    }
    a.sums[i] = top;
  }
};

/// MGPCG's start on plane i, after the product (cg_q = K x): r (cg_rw, holding b) = b - K x on
/// the unknowns, 0 elsewhere; sums2: max |r|.
struct StartResidualPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const Shape3& sh = a.L->shape;
    const std::size_t base = sh.index(i, 0, 0);
    const int n = sh.n[1] * sh.n[2];
    const T* dg = a.L->diag.data() + base;
    const T* q = a.cg_q + base;
    T* r = a.cg_rw + base;
    double top = 0;
    for (int c = 0; c < n; ++c) {
      r[c] = dg[c] == T(0) ? T(0) : T(double(r[c]) - double(q[c]));
      top = std::max(top, std::fabs(double(r[c])));
    }
    a.sums2[i] = top;
  }
};

/// v's plane i between the natural order (natural[k]) and rows split by the parity of k
/// (split[split_pos(k)]): to_split copies natural into split, else split into natural.
struct SplitCopyPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const Shape3& sh = a.L->shape;
    const int n1 = sh.n[1], n2 = sh.n[2], ne = (n2 + 1) / 2, no = n2 / 2;
    for (int j = 0; j < n1; ++j) {
      const std::size_t base = sh.index(i, j, 0);
      T* sp = a.cg_s + base;
      T* nat = a.cg_x + base;
      if (a.colour == 1) {
        for (int e = 0; e < ne; ++e) sp[e] = nat[2 * e];
        for (int o = 0; o < no; ++o) sp[ne + o] = nat[2 * o + 1];
      } else {
        for (int e = 0; e < ne; ++e) nat[2 * e] = sp[e];
        for (int o = 0; o < no; ++o) nat[2 * o + 1] = sp[ne + o];
      }
    }
  }
};

/// Level 0's entry: b = r, to the V-cycle's precision and split by the parity of k, and x = 0,
/// or with first_half_sweep (one wrap pass only) the first half-sweep from x = 0 too: colour 0
/// sees no neighbour yet, x = b / diag there, colour 1 stays 0 (a fill and a stencil pass saved).
struct EntryPlane {
  template <class In, class T>
  FLAGSIM_INLINE static void body(const LevelArgs<T>& a, int i) {
    const MultigridLevel<T>& Lv = *a.L;
    const int n1 = Lv.shape.n[1], n2 = Lv.shape.n[2], ne = (n2 + 1) / 2, no = n2 / 2;
    for (int j = 0; j < n1; ++j) {
      const std::size_t base = Lv.shape.index(i, j, 0);
      const In* in = static_cast<const In*>(a.in) + base;
      T* br = const_cast<T*>(a.b) + base;
      T* xr = a.x + base;
      const T* dr = Lv.inv_diag.data() + base;
      if (a.io_split) {
        for (int q = 0; q < n2; ++q) br[q] = T(in[q]);
      } else {
        for (int e = 0; e < ne; ++e) br[e] = T(in[2 * e]);
        for (int o = 0; o < no; ++o) br[ne + o] = T(in[2 * o + 1]);
      }
      if (a.first_half_sweep) {
        const int h = (i + j) & 1;  // colour 0's half
        const int lo = h == 0 ? 0 : ne, hi = h == 0 ? ne : n2;
        for (int q = 0; q < lo; ++q) xr[q] = T(0);
        for (int q = lo; q < hi; ++q) xr[q] = dr[q] * br[q];
        for (int q = hi; q < n2; ++q) xr[q] = T(0);
      } else {
        for (int q = 0; q < n2; ++q) xr[q] = T(0);
      }
    }
  }
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    if (a.io_double)
      body<double>(a, i);
    else
      body<float>(a, i);
  }
};

/// Level 0's exit: z = x in the grid's precision and natural order; with sums, per plane r . z
/// (sums) and sum z (sums2), r = a.in. With io_split (the solve's): no z (CG reads x), r split
/// as x, the sums over the plane in storage order.
struct ExitPlane {
  template <class Out, class T>
  FLAGSIM_INLINE static void body(const LevelArgs<T>& a, int i) {
    const Shape3& sh = a.L->shape;
    const int n1 = sh.n[1], n2 = sh.n[2], ne = (n2 + 1) / 2, no = n2 / 2;
    Lanes8 rz, zs;
    if (a.io_split) {
      const std::size_t base = sh.index(i, 0, 0);
      const T* x = a.x + base;
      const Out* r = static_cast<const Out*>(a.in) + base;
      rz.add(n1 * n2, [&](int q) { return double(r[q]) * double(x[q]); });
      zs.add(n1 * n2, [&](int q) { return double(x[q]); });
      a.sums[i] = rz.sum();
      a.sums2[i] = zs.sum();
      return;
    }
    for (int j = 0; j < n1; ++j) {
      const std::size_t base = sh.index(i, j, 0);
      const T* x = a.x + base;
      Out* z = static_cast<Out*>(a.out) + base;
      for (int e = 0; e < ne; ++e) z[2 * e] = Out(x[e]);
      for (int o = 0; o < no; ++o) z[2 * o + 1] = Out(x[ne + o]);
      if (!a.sums) continue;
      const Out* r = static_cast<const Out*>(a.in) + base;
      rz.add(n2, [&](int k) { return double(r[k]) * double(z[k]); });
      zs.add(n2, [&](int k) { return double(z[k]); });
    }
    if (!a.sums) return;
    a.sums[i] = rz.sum();
    a.sums2[i] = zs.sum();
  }
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    if (a.io_double)
      body<double>(a, i);
    else
      body<float>(a, i);
  }
};

/// tmp = sum over the transfer entries (e0, e1) of row (I, J) (count[0] x count[1] of them) of
/// w[0][e0] w[1][e1] times row (idx[0][e0], idx[1][e1]) of src (shape sh, rows of sh.n[2]): the
/// rows a restriction or prolongation combines, summed in a fixed order.
/// With colour0_only, each source row (i, j) is read on its colour-0 half only (the half of
/// parity (i + j) & 1 of k), the other half taken as 0.
template <class T>
FLAGSIM_INLINE void weighted_rows(const T* src, const Shape3& sh, int I, int J, const int count[3],
                                  const std::array<AlignedVector<T>, 3>& w,
                                  const std::array<std::vector<int32_t>, 3>& idx, T* tmp,
                                  bool colour0_only = false) {
  const int n = sh.n[2], ne = (n + 1) / 2;
  std::fill(tmp, tmp + n, T(0));
  for (int e0 = 0; e0 < count[0]; ++e0) {
    const std::size_t ea = std::size_t(I * count[0] + e0);
    if (w[0][ea] == T(0)) continue;
    for (int e1 = 0; e1 < count[1]; ++e1) {
      const std::size_t eb = std::size_t(J * count[1] + e1);
      if (w[1][eb] == T(0)) continue;
      const T wab = w[0][ea] * w[1][eb];
      const T* row = src + sh.index(idx[0][ea], idx[1][eb], 0);
      int lo = 0, hi = n;
      if (colour0_only) {
        const bool odd = ((idx[0][ea] + idx[1][eb]) & 1) != 0;
        lo = odd ? ne : 0;
        hi = odd ? n : ne;
      }
      for (int k = lo; k < hi; ++k) tmp[k] += wab * row[k];
    }
  }
}

/// C.b = P^T F.r on coarse plane I (F.r holds (b - A x) * inv_norm), 0 on inactive coarse cells:
/// per coarse row the weighted fine rows summed into one (tmp), then along k (on a halved k the
/// coarse K takes fine 2K - 1, 2K, 2K + 1, 2K + 2: odd K - 1, even K, odd K, even K + 1).
struct RestrictPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int I) {
    const MultigridLevel<T>& F = *a.L;
    const MultigridLevel<T>& C = *a.coarse;
    const Shape3 &fs = F.shape, &cs = C.shape;
    const int nf2 = fs.n[2], nc2 = cs.n[2], nef = (nf2 + 1) / 2;
    T tmp[4096], nat[2048 + 1];
    for (int J = 0; J < cs.n[1]; ++J) {
      weighted_rows(F.r.data(), fs, I, J, F.r_count, F.r_w, F.r_idx, tmp, a.colour0_only);
      const std::size_t cbase = cs.index(I, J, 0);
      T* out = a.b_coarse + cbase;
      const T* active = C.inv_diag.data() + cbase;
      if (F.r_count[2] == 1) {  // k not halved: the same split positions
        for (int q = 0; q < nc2; ++q) out[q] = active[q] != T(0) ? tmp[q] : T(0);
        continue;
      }
      const T* ev = tmp;
      const T* od = tmp + nef;
      const int no = nf2 / 2;
      // interior K: 1 <= K and K + 1 < nef, K < no
      const int hi = std::min(nef - 1, no);
      for (int K = 1; K < hi; ++K)
        nat[K] = (T(0.25) * od[K - 1] + T(0.75) * ev[K]) + (T(0.75) * od[K] + T(0.25) * ev[K + 1]);
      for (int K = 0; K < nc2; ++K) {
        if (K >= 1 && K < hi) {
          K = hi - 1;
          continue;
        }
        const std::size_t c = std::size_t(4 * K);
        const T* w = F.r_w[2].data() + c;
        const int32_t* f = F.r_idx[2].data() + c;
        nat[K] = (w[0] * tmp[split_pos(f[0], nf2)] + w[1] * tmp[split_pos(f[1], nf2)]) +
                 (w[2] * tmp[split_pos(f[2], nf2)] + w[3] * tmp[split_pos(f[3], nf2)]);
      }
      // to the coarse split row: even K to its first half, odd K to its second
      const int nec = (nc2 + 1) / 2, noc = nc2 / 2;
      for (int e = 0; e < nec; ++e) out[e] = active[e] != T(0) ? nat[2 * e] : T(0);
      for (int o = 0; o < noc; ++o) out[nec + o] = active[nec + o] != T(0) ? nat[2 * o + 1] : T(0);
    }
  }
};

/// x += P C.x on fine plane i: per fine row the weighted coarse rows summed into one (tmp, then
/// in natural order), then interpolated along k (fine 2K and 2K + 1 from coarse K and K -+ 1:
/// the even and odd halves), times inv_norm.
struct ProlongPlane {
  template <class L, bool Unit, class T>
  FLAGSIM_INLINE static void run(const LevelArgs<T>& a, int i) {
    const MultigridLevel<T>& F = *a.L;
    const MultigridLevel<T>& C = *a.coarse;
    const Shape3 &fs = F.shape, &cs = C.shape;
    const int nf2 = fs.n[2], nc2 = cs.n[2], nef = (nf2 + 1) / 2, nof = nf2 / 2;
    T tmp[4096], nat[2048 + 1];
    for (int j = 0; j < fs.n[1]; ++j) {
      weighted_rows(C.x.data(), cs, i, j, F.p_count, F.p_w, F.p_idx, tmp);
      const std::size_t base = fs.index(i, j, 0);
      T* xr = a.x + base;
      const T* nr = F.inv_norm.data() + base;
      // colour 0's half only, or both
      const int h0 = (i + j) & 1;
      const bool even = !a.colour0_only || h0 == 0, odd = !a.colour0_only || h0 == 1;
      if (F.p_count[2] == 1) {  // k not halved: the same split positions
        for (int q = even ? 0 : nef; q < (odd ? nf2 : nef); ++q) xr[q] += nr[q] * tmp[q];
        continue;
      }
      // the coarse split row to natural order: its two halves interleaved
      const int nec = (nc2 + 1) / 2, noc = nc2 / 2;
      for (int o = 0; o < noc; ++o) {
        nat[2 * o] = tmp[o];
        nat[2 * o + 1] = tmp[nec + o];
      }
      if (nec > noc) nat[nc2 - 1] = tmp[nec - 1];
      const T* w = F.p_w[2].data();
      const int32_t* c = F.p_idx[2].data();
      auto edge = [&](int k) {
        const int q = split_pos(k, nf2);
        xr[q] += nr[q] * (w[2 * k] * nat[c[2 * k]] + w[2 * k + 1] * nat[c[2 * k + 1]]);
      };
      // even half e (k = 2e): parent e, other e - 1; odd half o (k = 2o + 1): parent o, other o + 1
      if (even) {
        for (int e = 1; e < nef; ++e) xr[e] += nr[e] * (T(0.75) * nat[e] + T(0.25) * nat[e - 1]);
        edge(0);
      }
      if (odd) {
        const int ohi = std::min(nof, nc2 - 1);
        for (int o = 0; o < ohi; ++o)
          xr[nef + o] += nr[nef + o] * (T(0.75) * nat[o] + T(0.25) * nat[o + 1]);
        for (int o = ohi; o < nof; ++o) edge(2 * o + 1);
      }
    }
  }
};

template <class T>
using PlaneFn = LaneKernel<void(const LevelArgs<T>&, int)>;

/// Kernel's plane function on the widest vectors this CPU has (the same bits at every width).
template <class Kernel, class T>
PlaneFn<T> plane_fn() {
  static constexpr auto plane = [](auto c, const LevelArgs<T>& a, int i) FLAGSIM_INLINE_LAMBDA {
    if (a.L->unit)
      Kernel::template run<typename decltype(c)::L, true>(a, i);
    else
      Kernel::template run<typename decltype(c)::L, false>(a, i);
  };
  return on_widest_lanes<T, void(const LevelArgs<T>&, int)>(plane);
}

/// Kernel on every plane of a level, planes split over the threads (each plane's result is
/// independent of the split).
template <class Kernel, class T>
void for_each_plane(const LevelArgs<T>& a, int planes = -1) {
  const PlaneFn<T> fn = plane_fn<Kernel, T>();
  const MultigridLevel<T>& L = *a.L;
  parallel_for_if(Index(L.shape.size()) > kGridParallelGrain, planes < 0 ? L.shape.n[0] : planes,
                  [&](Index i) { fn(a, int(i)); });
}

/// One stage of a fused pass over a level: a plane kernel and its arguments.
template <class T>
struct PlaneStage {
  PlaneFn<T> fn;
  LevelArgs<T> a;
};

template <class T>
struct StageList;
template <class T>
void run_stages(const StageList<T>& list);

/// The stages of a fused pass over one level, in order; a full list runs (run_stages) and starts
/// again, which gives the same result: no allocation.
template <class T>
struct StageList {
  static constexpr int kMaxStages = 24;
  PlaneStage<T> st[kMaxStages];
  int n = 0;
  template <class Kernel>
  void add(const LevelArgs<T>& a) {
    if (n == kMaxStages) flush();
    st[n].fn = plane_fn<Kernel, T>();
    st[n].a = a;
    ++n;
  }
  void flush() {
    run_stages(*this);
    n = 0;
  }
};

/// Stage s of list on planes [first, last) of an n0-plane level (indices wrap on a ring).
template <class T>
void run_planes(const StageList<T>& list, int s, int first, int last, int n0) {
  const PlaneStage<T>& st = list.st[s];
  for (int p = first; p < last; ++p) st.fn(st.a, (p % n0 + n0) % n0);
}

/// The stages of list over every plane of their level, with the result of running each stage
/// over all planes before the next begins (the same bits), provided stage s on plane p writes
/// plane p only, and reads of the other planes only planes p - 1 and p + 1, and there only what
/// stage s does not write (as every stage of the cycle: a colour's half-sweep reads the other
/// colour there; the entry, the prolongation and the exit read no other plane; the residual
/// writes r, which no stage reads). The schedule below runs stage s on plane p after stage s - 1
/// on planes p - 1 .. p + 1 and before stage s + 1 on them. Temporal
/// blocking, so a level's planes stream through the cache once per pass instead of once per
/// stage: the planes are cut into slabs (one per thread); phase 1 runs each slab as a wavefront
/// (stage s one plane behind stage s - 1) over a trapezoid that shrinks by a plane per stage at
/// each end shared with another slab (or with itself across a periodic wrap), phase 2 fills the
/// triangle at each shared end (stage s on the 2 s planes around it, stage by stage). A level
/// with wrap passes (an odd periodic axis) or too few planes runs stage by stage.
template <class T>
void run_stages(const StageList<T>& list) {
  const int S = list.n;
  if (S == 0) return;
  const MultigridLevel<T>& L = *list.st[0].a.L;
  const int n0 = L.shape.n[0];
  const bool ring = L.periodic[0] && n0 > 1;
  const bool team = use_team(Index(L.shape.size()) > kGridParallelGrain);
  int slabs = team ? std::min(num_threads(), n0 / (2 * S)) : 1;
  if (!ring)
    slabs = std::max(slabs, 1);  // no shared end: one slab of any length
  else if (n0 < 2 * S)
    slabs = 0;  // too short to shrink from both ends
  if (L.passes != 1 || slabs < 1) {
    for (int s = 0; s < S; ++s) {
      const PlaneStage<T>& st = list.st[s];
      parallel_for_if(team, n0, [&](Index i) { st.fn(st.a, int(i)); });
    }
    return;
  }
  auto bound = [&](int k) { return int(std::int64_t(k) * n0 / slabs); };
  // Phase 1: slab k = [lo, hi), a wavefront over the planes its stages can reach on their own.
  parallel_for_if(slabs > 1, slabs, [&](Index k) {
    const int lo = bound(int(k)), hi = bound(int(k) + 1);
    const int shrink_lo = (k > 0 || ring) ? 1 : 0, shrink_hi = (k + 1 < slabs || ring) ? 1 : 0;
    for (int t = 0; t < hi - lo + S - 1; ++t)
      for (int s = 0; s < S; ++s) {
        const int p = lo + t - s;
        if (p >= lo + shrink_lo * s && p < hi - shrink_hi * s) list.st[s].fn(list.st[s].a, p);
      }
  });
  // Phase 2: the triangle around each shared end b (on a ring slab 0's start too).
  const int ends = ring ? slabs : slabs - 1;
  parallel_for_if(ends > 1, ends, [&](Index e) {
    const int b = bound(ring ? int(e) : int(e) + 1);
    for (int s = 1; s < S; ++s) run_planes(list, s, b - s, b + s, n0);
  });
}

}  // namespace

template <class T>
LevelArgs<MgScalar> PoissonMultigrid<T>::args(int l) {
  LevelArgs<MgScalar> a;
  MultigridLevel<MgScalar>& L = levels_[std::size_t(l)];
  a.L = &L;
  a.zero = zero_row_.data();
  a.b = L.b.data();
  a.x = L.x.data();
  a.r = L.r.data();
  if (l + 1 < int(levels_.size())) {
    a.coarse = &levels_[std::size_t(l + 1)];
    a.b_coarse = levels_[std::size_t(l + 1)].b.data();
  }
  a.io_double = std::is_same<T, double>::value;
  a.parity = parity_.data();
  return a;
}

template <class T>
void PoissonMultigrid<T>::apply_operator(const T* x, T* y) {
  const std::size_t n = product_.shape.size();
  AlignedVector<T> xs(n), ys(n);
  LevelArgs<T> a = cg_args();
  a.sums = nullptr;
  split_copy(a, const_cast<T*>(x), xs.data(), true);  // x is only read
  a.x = xs.data();
  a.r = ys.data();
  for_each_plane<ProductPlane>(a);
  split_copy(a, y, ys.data(), false);
}

template <class T>
void PoissonMultigrid<T>::split_copy(const LevelArgs<T>& a, T* natural, T* split, bool to_split) {
  LevelArgs<T> c = a;
  c.cg_x = natural;
  c.cg_s = split;
  c.colour = to_split ? 1 : 0;
  for_each_plane<SplitCopyPlane>(c);
}

template <class T>
void PoissonMultigrid<T>::apply(const T* r, T* z) {
  vcycle(r, z);
}

template <class T>
void PoissonMultigrid<T>::vcycle(const T* r_in, T* z) {
  using F32 = MgScalar;
  const int nl = int(levels_.size());
  const bool split = z == nullptr;  // the solve's: r split as the levels, z = level 0's x
  StageList<F32> list;
  // Red then black (forward) or black then red (backward), the wrap passes likewise; `skip`
  // half-sweeps of the first sweep already done.
  auto sweep = [&](LevelArgs<F32> a, bool forward, int sweeps, int skip) {
    for (int s = 0; s < sweeps; ++s)
      for (int h = s == 0 ? skip : 0; h < 2; ++h) {
        a.colour = forward ? h : 1 - h;
        for (int p = 0; p < a.L->passes; ++p) {
          a.pass = forward ? p : a.L->passes - 1 - p;
          list.add<SmoothPlane>(a);
        }
      }
  };
  // Smoothing from x = 0: the first half-sweep reads no neighbour (one wrap pass only). Level 0
  // reads its b from r on the way.
  auto presmooth = [&](LevelArgs<F32> a, int l, int sweeps) {
    const bool first = a.L->passes == 1;
    if (l == 0) {
      a.in = r_in;
      a.io_split = split;
      a.first_half_sweep = first;
      list.add<EntryPlane>(a);
    } else if (first) {
      list.add<FirstHalfSweepPlane>(a);
    } else {
      std::fill(a.x, a.x + a.L->shape.size(), F32(0));
    }
    sweep(a, true, sweeps, first ? 1 : 0);
  };
  // Down: smooth from x = 0 and take the residual (one fused pass), restrict it.
  for (int l = 0; l + 1 < nl; ++l) {
    const LevelArgs<F32> a = args(l);
    presmooth(a, l, smooth_sweeps(l));
    LevelArgs<F32> res = a;
    res.colour0_only = a.L->passes == 1;  // the last half-sweep was colour 1's
    list.add<ResidualPlane>(res);
    list.flush();
    for_each_plane<RestrictPlane>(res, a.coarse->shape.n[0]);
  }
  // Coarsest: the dense factor, or symmetric sweeps.
  {
    const LevelArgs<F32> a = args(nl - 1);
    if (!chol_.empty()) {
      if (nl == 1) {  // level 0 is the coarsest: b from r
        LevelArgs<F32> e = a;
        e.in = r_in;
        e.io_split = split;
        for_each_plane<EntryPlane>(e);
      }
      std::fill(a.x, a.x + a.L->shape.size(), F32(0));
      const std::size_t m = cell_of_.size();
      for (std::size_t i = 0; i < m; ++i) {  // L y = b
        double v = double(a.b[cell_of_[i]]);
        const double* li = chol_.data() + i * m;
        for (std::size_t k = 0; k < i; ++k) v -= li[k] * rhs_[k];
        rhs_[i] = v / li[i];
      }
      for (std::size_t i = m; i-- > 0;) {  // L^T x = y
        double v = rhs_[i];
        for (std::size_t k = i + 1; k < m; ++k) v -= chol_[k * m + i] * rhs_[k];
        rhs_[i] = v / chol_[i * m + i];
      }
      for (std::size_t i = 0; i < m; ++i) a.x[cell_of_[i]] = F32(rhs_[i]);
    } else {
      presmooth(a, nl - 1, kCoarsestSweeps);
      sweep(a, false, kCoarsestSweeps, 0);
      list.flush();
    }
  }
  // Up: add the coarse correction and smooth in the reverse order (one fused pass; on level 0
  // the exit too).
  for (int l = nl - 2; l >= 0; --l) {
    const LevelArgs<F32> a = args(l);
    LevelArgs<F32> pro = a;
    pro.colour0_only = a.L->passes == 1;  // colour 1's half-sweep comes next
    list.add<ProlongPlane>(pro);
    sweep(a, false, smooth_sweeps(l), 0);
    if (l > 0) list.flush();
  }
  LevelArgs<F32> a = args(0);
  a.out = z;
  a.io_split = split;
  if (split) {
    a.in = r_in;
    a.sums = part_[0].data();
    a.sums2 = part_[1].data();
  }
  list.add<ExitPlane>(a);
  list.flush();
}

template <class T>
LevelArgs<T> PoissonMultigrid<T>::cg_args() {
  LevelArgs<T> a;
  a.L = &product_;
  a.zero = zero_row_t_.data();
  a.diag_f = levels_[0].diag.data();
  a.sums = part_[0].data();
  a.sums2 = part_[1].data();
  return a;
}

template <class T>
CgResult PoissonMultigrid<T>::solve(const T* b, T* x, double tol, int max_iter, CgScratch<T>& w) {
  // CG runs on rows split by the parity of k, as the levels: x in w.z, r, s, q in w's own.
  const std::size_t n = product_.shape.size();
  const int planes = product_.shape.n[0];
  T* r = w.r.data();
  T* xs = w.z.data();
  T* s = w.s.data();
  T* q = w.q.data();
  const MgScalar* z = levels_[0].x.data();  // M r: the cycle's level-0 x
  const T* active = product_.diag.data();   // 0: not an unknown (solid, or no open face)
  auto in_order = [&](int k) {              // the planes' partial sums, added in plane order
    double t = 0;
    for (int i = 0; i < planes; ++i) t += part_[std::size_t(k)][std::size_t(i)];
    return t;
  };
  auto largest = [&](int k) {  // the planes' maxima
    double t = 0;
    for (int i = 0; i < planes; ++i) t = std::max(t, part_[std::size_t(k)][std::size_t(i)]);
    return t;
  };
  auto mean = [&](const T* v) {  // over the unknowns
    return deterministic_sum(
               n, [&](std::size_t i) { return active[i] == T(0) ? 0.0 : double(v[i]); }) /
           double(n_active_);
  };
  CgResult res;
  LevelArgs<T> a = cg_args();
  a.sums = nullptr;
  double b_max = 0, r_max = 0, sum_r = 0;
  if (!singular_) {
    // One blocked pass: x and b split (x = 0 off the unknowns) with max |b| over the unknowns;
    // q = K x; r = b - q on the unknowns (0 elsewhere) with max |r|.
    StageList<T> list;
    LevelArgs<T> start = cg_args();
    start.cg_x = x;
    start.cg_s = xs;
    start.cg_rw = r;
    start.in = b;
    list.template add<StartPlane>(start);
    LevelArgs<T> product = a;
    product.x = xs;
    product.r = q;
    list.template add<ProductPlane>(product);
    LevelArgs<T> rest = cg_args();
    rest.cg_rw = r;
    rest.cg_q = q;
    list.template add<StartResidualPlane>(rest);
    list.flush();
    b_max = largest(0);
    r_max = largest(1);
  } else {
    split_copy(a, x, xs, true);
    split_copy(a, const_cast<T*>(b), r, true);  // b is only read
    if (any_inactive_)
      parallel_for_cells(long(n), [&](Index i) {
        if (active[i] == T(0)) xs[i] = T(0);
      });
    // max|b| over the unknowns of b - mean(b): constants over the unknowns are K's null space,
    // the solve is for the zero-mean part.
    const double mb = mean(r);
    b_max = parallel_max(
        n, [&](std::size_t i) { return active[i] == T(0) ? 0.0 : std::fabs(double(r[i]) - mb); });
    // r = b - K x on the unknowns, 0 elsewhere, its mean over the unknowns taken out.
    a.x = xs;
    a.r = q;
    for_each_plane<ProductPlane>(a);
    parallel_for_cells(long(n), [&](Index i) {
      r[i] = active[i] == T(0) ? T(0) : T(double(r[i]) - double(q[i]));
    });
    const double mr = mean(r);
    parallel_for_cells(long(n), [&](Index i) {
      if (active[i] != T(0)) r[i] = T(r[i] - mr);
    });
    sum_r = deterministic_sum(n, [&](std::size_t i) { return double(r[i]); });
    r_max = parallel_max(n, [&](std::size_t i) { return std::fabs(double(r[i])); });
  }
  if (b_max == 0 || r_max <= tol * b_max) {
    res.residual = b_max == 0 ? 0.0 : r_max / b_max;
    split_copy(a, x, xs, false);
    return res;
  }
  // z = M r; for a singular K, z's mean over the unknowns m is taken out of the direction
  // (s = z - m + beta s) and of r . z (r . (z - m) = r . z - m sum r).
  double m = 0;
  auto precondition = [&]() {
    vcycle(r, nullptr);
    const double rz = in_order(0);
    m = singular_ ? in_order(1) / double(n_active_) : 0.0;
    return rz - m * sum_r;
  };
  // s = (z - m) + beta s, then q = K s with s . q: one fused pass (the product of plane p reads
  // s on planes p - 1 .. p + 1).
  auto direction_and_product = [&](double beta) {
    StageList<T> list;
    LevelArgs<T> d = cg_args();
    d.sums = nullptr;
    d.cg_s = s;
    d.cg_z = z;
    d.beta = beta;
    d.mean = m;
    list.template add<DirectionPlane>(d);
    LevelArgs<T> p = cg_args();
    p.x = s;
    p.r = q;
    list.template add<ProductPlane>(p);
    list.flush();
  };
  double rz = precondition(), beta = 0.0;
  for (int it = 1; it <= max_iter; ++it) {
    direction_and_product(beta);
    const double sq = in_order(0);
    res.iterations = it;
    if (!(sq > 0)) break;  // breakdown (converged to round-off, or not SPD): stop here
    LevelArgs<T> u = cg_args();
    u.cg_x = xs;
    u.cg_rw = r;
    u.cg_s = s;
    u.cg_q = q;
    u.alpha = rz / sq;
    for_each_plane<UpdatePlane>(u);
    sum_r = in_order(0);
    r_max = largest(1);
    if (r_max <= tol * b_max) break;
    const double rz_new = precondition();
    beta = rz_new / rz;
    rz = rz_new;
  }
  split_copy(a, x, xs, false);
  res.residual = r_max / b_max;
  res.converged = r_max <= tol * b_max;
  return res;
}

template class PoissonMultigrid<float>;
template class PoissonMultigrid<double>;

}  // namespace flagsim
