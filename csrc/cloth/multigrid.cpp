#include "cloth/multigrid.h"

#include <cmath>

#include "common/parallel.h"

namespace flagsim {

namespace {

// Coarsening stops at this many vertices or fewer: a dense Cholesky of 3 x 16 unknowns per step
// costs less than one more level.
constexpr Index kCoarsestVertices = 16;

// Cycles per coarse correction below level 0: 2 (a W-cycle) makes up for the piecewise-constant
// prolongation's too-stiff coarse operators (128 x 128 flag: 22 -> 14 CG iterations per step).
constexpr int kGamma = 2;
constexpr int kCenter = 4;  // stencil slot of (dr, dc) = (0, 0)
inline int slot(int dr, int dc) { return 3 * (dr + 1) + (dc + 1); }

inline bool free_vertex(const ClothTopology& topo, Index i) { return topo.inv_mass[i] != 0.0; }

using Vec4f = Eigen::Vector4f;
using Vec4fMap = Eigen::Map<Vec4f, Eigen::Aligned16>;
using Vec4fCMap = Eigen::Map<const Vec4f, Eigen::Aligned16>;

// Position of vertex (r, c) in the fine level's bordered array, and of the stencil's offsets.
inline Index fine_index(const MultigridFine& F, int r, int c) {
  return Index(r + kFinePad) * F.stride + c + kFinePad;
}
inline void fine_offsets(const MultigridFine& F, Index (&off)[kFineStencil]) {
  for (int k = 0; k < kFineStencil; ++k) off[k] = Index(kFineOffset[k][0]) * F.stride + kFineOffset[k][1];
}

// Slot k of the stencil with j = i + o_k (i, j grid vertices, i before j), or -1.
int stencil_slot(int cols, Index i, Index j) {
  const int dr = int(j / cols - i / cols), dc = int(j % cols - i % cols);
  for (int k = 0; k < kFineStencil; ++k)
    if (kFineOffset[k][0] == dr && kFineOffset[k][1] == dc) return k;
  return -1;
}

// Index into F.M of the coupling of grid vertices i and j (either order), -1 outside the stencil.
Index coupling_index(const ClothTopology& topo, const MultigridFine& F, Index i, Index j) {
  if (i > j) std::swap(i, j);
  const int k = stencil_slot(topo.cols, i, j);
  if (k < 0) return -1;
  return kFineStencil * fine_index(F, int(i / topo.cols), int(i % topo.cols)) + k;
}

// sum_{j != p} -A_pj x_j over the later (kUpper), earlier (kLower) or all neighbours j of p:
// -A_{p, p + o_k} = M[6 p + k], -A_{p, p - o_k} = M[6 (p - o_k) + k]^T.
enum class Side { kAll, kLower, kUpper };
template <Side side>
inline Vec4f fine_neighbours(const MultigridFine& F, const Index (&off)[kFineStencil], Index p) {
  Vec4f acc = Vec4f::Zero();
  const float* x = F.x.data();
  if (side != Side::kLower) {
    const Mat43f* m = &F.M[kFineStencil * p];
    for (int k = 0; k < kFineStencil; ++k)
      acc.noalias() += m[k] * Vec4fCMap(x + 4 * (p + off[k])).head<3>();
  }
  if (side != Side::kUpper)
    for (int k = 0; k < kFineStencil; ++k) {
      const Index q = p - off[k];
      acc.noalias() += F.M[kFineStencil * q + k] * Vec4fCMap(x + 4 * q).head<3>();
    }
  return acc;
}

// Fine-level block Gauss-Seidel: x_p <- D_p^-1 (b_p - sum_{j != p} A_pj x_j) over the grid in
// increasing (forward) or decreasing order; pinned vertices have D_p^-1 = 0 and stay 0.
// from_zero: the forward sweep that starts from x = 0 reads only the earlier neighbours.
void gauss_seidel_fine(const ClothTopology& topo, MultigridFine& F, bool forward, bool from_zero) {
  Index off[kFineStencil];
  fine_offsets(F, off);
  const int R = topo.rows, C = topo.cols;
  for (int n = 0; n < R; ++n) {
    const int r = forward ? n : R - 1 - n;
    for (int m = 0; m < C; ++m) {
      const Index p = fine_index(F, r, forward ? m : C - 1 - m);
      const Vec4f acc = Vec4fCMap(F.b.data() + 4 * p) +
                        (from_zero ? fine_neighbours<Side::kLower>(F, off, p) : fine_neighbours<Side::kAll>(F, off, p));
      Vec4fMap(F.x.data() + 4 * p).noalias() = F.Dinv[p] * acc.head<3>();
    }
  }
}

// Coarse-level block Gauss-Seidel sweep with the 9-point block stencil.
void gauss_seidel_level(MultigridLevel& L, bool forward) {
  const int R = L.rows, C = L.cols;
  const Index n = Index(R) * C;
  for (Index m = 0; m < n; ++m) {
    const Index v = forward ? m : n - 1 - m;
    if (!L.active[v]) continue;
    const int r = int(v / C), c = int(v % C);
    Vec3 acc = L.b.row(v);
    const Mat3* a = &L.A[9 * v];
    for (int dr = -1; dr <= 1; ++dr) {
      if (r + dr < 0 || r + dr >= R) continue;
      for (int dc = -1; dc <= 1; ++dc) {
        if (c + dc < 0 || c + dc >= C || (dr == 0 && dc == 0)) continue;
        acc.noalias() -= a[slot(dr, dc)] * Vec3(L.x.row(v + dr * C + dc));
      }
    }
    L.x.row(v) = (L.Dinv[v] * acc).transpose();
  }
}

// L.r = L.b - A L.x
void residual_level(MultigridLevel& L) {
  const int R = L.rows, C = L.cols;
  for (int r = 0; r < R; ++r)
    for (int c = 0; c < C; ++c) {
      const Index v = Index(r) * C + c;
      Vec3 acc = L.b.row(v);
      const Mat3* a = &L.A[9 * v];
      for (int dr = -1; dr <= 1; ++dr) {
        if (r + dr < 0 || r + dr >= R) continue;
        for (int dc = -1; dc <= 1; ++dc) {
          if (c + dc < 0 || c + dc >= C) continue;
          acc.noalias() -= a[slot(dr, dc)] * Vec3(L.x.row(v + dr * C + dc));
        }
      }
      L.r.row(v) = acc.transpose();
    }
}

// out.b = P^T r: each coarse vertex sums the residuals of its 2 x 2 fine vertices.
void restrict_to(int rows, int cols, const MatX3& r, MultigridLevel& out) {
  out.b.setZero();
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j) out.b.row(Index(i / 2) * out.cols + j / 2) += r.row(Index(i) * cols + j);
}

// Coarsest level: x = A^-1 b by the dense Cholesky factor (forward, then backward substitution).
void coarsest_solve(Multigrid& mg) {
  MultigridLevel& L = mg.levels.back();
  const Index n = 3 * Index(L.rows) * L.cols;
  VecX& y = mg.coarse_y;
  for (Index v = 0; v < n / 3; ++v) y.segment<3>(3 * v) = L.b.row(v).transpose();
  const Eigen::MatrixXd& F = mg.coarse_L;
  for (Index i = 0; i < n; ++i) {
    double s = y[i];
    for (Index k = 0; k < i; ++k) s -= F(i, k) * y[k];
    y[i] = s / F(i, i);
  }
  for (Index i = n - 1; i >= 0; --i) {
    double s = y[i];
    for (Index k = i + 1; k < n; ++k) s -= F(k, i) * y[k];
    y[i] = s / F(i, i);
  }
  for (Index v = 0; v < n / 3; ++v) L.x.row(v) = y.segment<3>(3 * v).transpose();
}

void cycle_level(Multigrid& mg, size_t l);

// Coarse correction of level l: Lc.x ~= A_{l+1}^-1 Lc.b by kGamma cycles from zero (2: W-cycle).
void coarse_correction(Multigrid& mg, size_t l) {
  MultigridLevel& Lc = mg.levels[l + 1];
  cycle_level(mg, l + 1);
  if (l + 2 == mg.levels.size() || kGamma < 2) return;
  Lc.x_sum = Lc.x;
  Lc.b_in = Lc.b;
  residual_level(Lc);  // second pass solves for the first one's error
  Lc.b = Lc.r;
  cycle_level(mg, l + 1);
  Lc.x += Lc.x_sum;
  Lc.b = Lc.b_in;
}

// Symmetric cycle on coarse level l: L.x ~= A_l^-1 L.b.
void cycle_level(Multigrid& mg, size_t l) {
  if (l + 1 == mg.levels.size()) {
    coarsest_solve(mg);
    return;
  }
  MultigridLevel& L = mg.levels[l];
  MultigridLevel& Lc = mg.levels[l + 1];
  L.x.setZero();
  gauss_seidel_level(L, true);
  residual_level(L);
  restrict_to(L.rows, L.cols, L.r, Lc);
  coarse_correction(mg, l);
  for (int r = 0; r < L.rows; ++r)
    for (int c = 0; c < L.cols; ++c)
      if (L.active[Index(r) * L.cols + c]) L.x.row(Index(r) * L.cols + c) += Lc.x.row(Index(r / 2) * Lc.cols + c / 2);
  gauss_seidel_level(L, false);
}

// The 2 x 2 aggregate of level below's vertex (r, c) relative to that of (r + dr, c + dc).
inline Mat3& coarse_block(MultigridLevel& Lc, int r, int c, int r2, int c2) {
  const int R = r / 2, C = c / 2;
  return Lc.A[9 * (Index(R) * Lc.cols + C) + slot(r2 / 2 - R, c2 / 2 - C)];
}

// Inverse diagonal blocks; an inactive vertex gets identity (its equation reads x = b = 0).
void finish_level(MultigridLevel& L) {
  const Index n = Index(L.rows) * L.cols;
  for (Index v = 0; v < n; ++v) {
    if (!L.active[v]) {
      L.A[9 * v + kCenter].setIdentity();
      L.Dinv[v].setIdentity();
    } else {
      L.Dinv[v] = L.A[9 * v + kCenter].inverse();
    }
  }
}

}  // namespace

void apply_system(const ClothTopology& topo, const ClothSystem& A, const MatX3& p, MatX3& out) {
  const bool tri = !A.J.empty();
  parallel_for(topo.num_vertices(), [&](Index i) {
    if (!free_vertex(topo, i)) {
      out.row(i).setZero();
      return;
    }
    const Vec3 pi = p.row(i);
    Vec3 acc = A.D[i] * pi;
    for (int32_t k = topo.adj_offset[i]; k < topo.adj_offset[i + 1]; ++k)
      acc += A.B[topo.adj_spring[k]].apply(pi - Vec3(p.row(topo.adj_other[k])));
    if (tri)
      for (int32_t k = topo.tri_adj_offset[i]; k < topo.tri_adj_offset[i + 1]; ++k) {
        const int32_t t = topo.tri_adj[k];
        acc.noalias() += A.J[t] * Vec3(p.row(topo.triangles(t, 0)) + p.row(topo.triangles(t, 1)) +
                                       p.row(topo.triangles(t, 2)));
      }
    out.row(i) = acc.transpose();
  });
}

bool multigrid_applies(const ClothTopology& topo) {
  if (!(topo.rows >= 1 && topo.cols >= 1 && Index(topo.rows) * topo.cols == topo.num_vertices() &&
        topo.num_vertices() > kCoarsestVertices))
    return false;
  MultigridFine F;
  F.stride = topo.cols + 2 * kFinePad;
  for (Index s = 0; s < topo.num_springs(); ++s)
    if (coupling_index(topo, F, topo.springs(s, 0), topo.springs(s, 1)) < 0) return false;
  for (Index t = 0; t < topo.triangles.rows(); ++t)
    for (int p = 0; p < 3; ++p)
      for (int q = p + 1; q < 3; ++q)
        if (coupling_index(topo, F, topo.triangles(t, p), topo.triangles(t, q)) < 0) return false;
  return true;
}

void multigrid_build(const ClothTopology& topo, Multigrid& mg) {
  mg.levels.clear();
  MultigridFine& F = mg.fine;
  F.stride = topo.cols + 2 * kFinePad;
  const Index np = Index(topo.rows + 2 * kFinePad) * F.stride;
  F.M.assign(kFineStencil * np, Mat43f::Zero());
  F.Dinv.assign(np, Mat43f::Zero());
  for (MatX4f* m : {&F.b, &F.x}) m->setZero(np, 4);
  auto pair_index = [&](Index i, Index j) -> int32_t {
    return free_vertex(topo, i) && free_vertex(topo, j) ? int32_t(coupling_index(topo, F, i, j)) : -1;
  };
  F.spring_slot.resize(topo.num_springs());
  for (Index s = 0; s < topo.num_springs(); ++s) F.spring_slot[s] = pair_index(topo.springs(s, 0), topo.springs(s, 1));
  F.tri_slot.resize(3 * topo.triangles.rows());
  for (Index t = 0; t < topo.triangles.rows(); ++t) {
    F.tri_slot[3 * t + 0] = pair_index(topo.triangles(t, 0), topo.triangles(t, 1));
    F.tri_slot[3 * t + 1] = pair_index(topo.triangles(t, 0), topo.triangles(t, 2));
    F.tri_slot[3 * t + 2] = pair_index(topo.triangles(t, 1), topo.triangles(t, 2));
  }
  int R = topo.rows, C = topo.cols;
  std::vector<uint8_t> active(topo.num_vertices());
  for (Index i = 0; i < topo.num_vertices(); ++i) active[i] = free_vertex(topo, i);
  while (Index(R) * C > kCoarsestVertices) {
    MultigridLevel L;
    L.rows = (R + 1) / 2;
    L.cols = (C + 1) / 2;
    const Index n = Index(L.rows) * L.cols;
    L.A.assign(9 * n, Mat3::Zero());
    L.Dinv.assign(n, Mat3::Identity());
    L.active.assign(n, 0);
    for (int r = 0; r < R; ++r)
      for (int c = 0; c < C; ++c)
        if (active[Index(r) * C + c]) L.active[Index(r / 2) * L.cols + c / 2] = 1;
    for (MatX3* m : {&L.x, &L.b, &L.r, &L.x_sum, &L.b_in}) m->setZero(n, 3);
    active = L.active;
    R = L.rows;
    C = L.cols;
    mg.levels.push_back(std::move(L));
  }
  const Index n = 3 * Index(R) * C;
  mg.coarse_L.setZero(n, n);
  mg.coarse_y.setZero(n);
}

void multigrid_setup(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg) {
  // Fine level in float: springs give -A_ij = B_s, triangles -A_ij = -J_t (J_t is symmetric).
  MultigridFine& F = mg.fine;
  for (int32_t k : F.spring_slot)
    if (k >= 0) F.M[k].setZero();
  for (int32_t k : F.tri_slot)
    if (k >= 0) F.M[k].setZero();
  for (Index s = 0; s < topo.num_springs(); ++s)
    if (F.spring_slot[s] >= 0) F.M[F.spring_slot[s]].topRows<3>() += A.B[s].matrix().cast<float>();
  for (Index t = 0; t < Index(A.J.size()); ++t)
    for (int q = 0; q < 3; ++q)
      if (F.tri_slot[3 * t + q] >= 0) F.M[F.tri_slot[3 * t + q]].topRows<3>() -= A.J[t].cast<float>();
  for (int r = 0; r < topo.rows; ++r)
    for (int c = 0; c < topo.cols; ++c) {
      const Index i = Index(r) * topo.cols + c;
      if (free_vertex(topo, i)) F.Dinv[fine_index(F, r, c)].topRows<3>() = A.Pinv[i].cast<float>();
    }
  // Level 0 = P^T A P from the terms of A: with P piecewise constant, a term X (x) w w^T becomes
  // X (x) (P^T w)(P^T w)^T; a spring inside one aggregate cancels, one across two aggregates
  // adds B to both diagonals and -B to both couplings (pinned ends dropped).
  MultigridLevel& L0 = mg.levels.front();
  for (auto& a : L0.A) a.setZero();
  const int C = topo.cols;
  auto rc = [C](Index i, int& r, int& c) {
    r = int(i / C);
    c = int(i % C);
  };
  for (Index i = 0; i < topo.num_vertices(); ++i) {
    if (!free_vertex(topo, i)) continue;
    int r, c;
    rc(i, r, c);
    coarse_block(L0, r, c, r, c) += A.D[i];
  }
  for (Index s = 0; s < topo.num_springs(); ++s) {
    const Index i = topo.springs(s, 0), j = topo.springs(s, 1);
    const bool fi = free_vertex(topo, i), fj = free_vertex(topo, j);
    int ri, ci, rj, cj;
    rc(i, ri, ci);
    rc(j, rj, cj);
    if (fi && fj && ri / 2 == rj / 2 && ci / 2 == cj / 2) continue;
    const Mat3 B = A.B[s].matrix();
    if (fi) coarse_block(L0, ri, ci, ri, ci) += B;
    if (fj) coarse_block(L0, rj, cj, rj, cj) += B;
    if (fi && fj) {
      coarse_block(L0, ri, ci, rj, cj) -= B;
      coarse_block(L0, rj, cj, ri, ci) -= B;
    }
  }
  for (Index t = 0; t < Index(A.J.size()); ++t)
    for (int p = 0; p < 3; ++p) {
      const Index i = topo.triangles(t, p);
      if (!free_vertex(topo, i)) continue;
      int ri, ci;
      rc(i, ri, ci);
      for (int q = 0; q < 3; ++q) {
        const Index j = topo.triangles(t, q);
        if (!free_vertex(topo, j)) continue;
        int rj, cj;
        rc(j, rj, cj);
        coarse_block(L0, ri, ci, rj, cj) += A.J[t];
      }
    }
  finish_level(L0);
  // Level l + 1 = P^T A_l P: sum the 9-point stencils of each 2 x 2 aggregate.
  for (size_t l = 0; l + 1 < mg.levels.size(); ++l) {
    const MultigridLevel& L = mg.levels[l];
    MultigridLevel& Lc = mg.levels[l + 1];
    for (auto& a : Lc.A) a.setZero();
    for (int r = 0; r < L.rows; ++r)
      for (int c = 0; c < L.cols; ++c) {
        const Index v = Index(r) * L.cols + c;
        if (!L.active[v]) continue;
        for (int dr = -1; dr <= 1; ++dr)
          for (int dc = -1; dc <= 1; ++dc) {
            const int r2 = r + dr, c2 = c + dc;
            if (r2 < 0 || r2 >= L.rows || c2 < 0 || c2 >= L.cols) continue;
            if (!L.active[Index(r2) * L.cols + c2]) continue;
            coarse_block(Lc, r, c, r2, c2) += L.A[9 * v + slot(dr, dc)];
          }
      }
    finish_level(Lc);
  }
  // Coarsest level: dense matrix, then its Cholesky factor in the lower triangle.
  const MultigridLevel& Lc = mg.levels.back();
  Eigen::MatrixXd& G = mg.coarse_L;
  G.setZero();
  for (int r = 0; r < Lc.rows; ++r)
    for (int c = 0; c < Lc.cols; ++c) {
      const Index v = Index(r) * Lc.cols + c;
      for (int dr = -1; dr <= 1; ++dr)
        for (int dc = -1; dc <= 1; ++dc) {
          const int r2 = r + dr, c2 = c + dc;
          if (r2 < 0 || r2 >= Lc.rows || c2 < 0 || c2 >= Lc.cols) continue;
          G.block<3, 3>(3 * v, 3 * (Index(r2) * Lc.cols + c2)) = Lc.A[9 * v + slot(dr, dc)];
        }
    }
  const Index n = G.rows();
  for (Index j = 0; j < n; ++j) {
    double d = G(j, j);
    for (Index k = 0; k < j; ++k) d -= G(j, k) * G(j, k);
    d = std::sqrt(d);  // A_c is SPD: P has full column rank on the active vertices
    G(j, j) = d;
    for (Index i = j + 1; i < n; ++i) {
      double s = G(i, j);
      for (Index k = 0; k < j; ++k) s -= G(i, k) * G(j, k);
      G(i, j) = s / d;
    }
  }
}

double multigrid_vcycle(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg,
                        const MatX3& r, MatX3& z) {
  (void)A;
  MultigridFine& F = mg.fine;
  const int R = topo.rows, C = topo.cols;
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) F.b.row(fine_index(F, i, j)).head<3>() = r.row(Index(i) * C + j).cast<float>();
  gauss_seidel_fine(topo, F, true, true);
  // After a forward sweep x_p solves row p against the x_j, j < p, it had: the residual of row p
  // is what the j > p contribute, r_p - (A x)_p = -sum_{j > p} A_pj x_j (half a product).
  // Restricted on the fly: level 0's b = P^T r.
  MultigridLevel& L0 = mg.levels.front();
  L0.b.setZero();
  Index off[kFineStencil];
  fine_offsets(F, off);
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) {
      const Vec4f rp = fine_neighbours<Side::kUpper>(F, off, fine_index(F, i, j));
      L0.b.row(Index(i / 2) * L0.cols + j / 2) += rp.head<3>().cast<double>().transpose();
    }
  cycle_level(mg, 0);
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j)
      if (free_vertex(topo, Index(i) * C + j))
        F.x.row(fine_index(F, i, j)).head<3>() += L0.x.row(Index(i / 2) * L0.cols + j / 2).cast<float>();
  gauss_seidel_fine(topo, F, false, false);
  double rz = 0;
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) {
      const Index v = Index(i) * C + j;
      z.row(v) = F.x.row(fine_index(F, i, j)).head<3>().cast<double>();
      rz += r.row(v).dot(z.row(v));
    }
  return rz;
}

}  // namespace flagsim
