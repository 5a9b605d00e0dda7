#include "cloth/multigrid.h"

#include "cloth/stencil9.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <type_traits>

#include "common/parallel.h"
#include "common/simd.h"

namespace flagsim {

namespace {

// Coarsening stops at this many vertices or fewer: a dense Cholesky of 3 x 16 unknowns per step
// costs less than one more level.
constexpr Index kCoarsestVertices = 16;

inline bool free_vertex(const ClothTopology& topo, Index i) { return topo.inv_mass[i] != 0.0; }

// Adds B x_{nb} of the slots k.. (one per lane of S: double, or a 16- or 32-byte vector) to
// (sx, sy, sz).
template <class S>
FLAGSIM_INLINE void add_spring_blocks(const NeighbourBlocks& n, const double* x, size_t k, S& sx,
                                      S& sy, S& sz) {
  const double* p = x + 3 * std::size_t(n.nb[k]);
  S X, Y, Z;
  if constexpr (std::is_same<S, double>::value) {
    X = p[0];
    Y = p[1];
    Z = p[2];
  } else if constexpr (sizeof(S) == 16) {
    const double* q = x + 3 * std::size_t(n.nb[k + 1]);
    X = S{p[0], q[0]};
    Y = S{p[1], q[1]};
    Z = S{p[2], q[2]};
  } else {
    const double* q = x + 3 * std::size_t(n.nb[k + 1]);
    const double* r = x + 3 * std::size_t(n.nb[k + 2]);
    const double* t = x + 3 * std::size_t(n.nb[k + 3]);
    X = S{p[0], q[0], r[0], t[0]};
    Y = S{p[1], q[1], r[1], t[1]};
    Z = S{p[2], q[2], r[2], t[2]};
  }
  const S a = load_lanes<S>(&n.a[k]), ex = load_lanes<S>(&n.ex[k]);
  const S ey = load_lanes<S>(&n.ey[k]), ez = load_lanes<S>(&n.ez[k]);
  const S d = (ex * X + ey * Y) + ez * Z;
  sx += a * X + ex * d;
  sy += a * Y + ey * d;
  sz += a * Z + ez * d;
}

// sum of B_k x_{nb_k} over the slots [k, end) of NeighbourBlocks. Four slots per step in four
// running sums (lanes), one 32-byte vector (L = Lanes32, AVX), two 16-byte ones (Lanes16) or four
// scalars (void); the sums are added as (0 + 1) + (2 + 3), then the last < 4 slots in scalars. The
// same operations on every lane type, so every width gives the same bits. One kernel for the CG
// product and the smoother.
template <class L>
FLAGSIM_INLINE Vec3 spring_blocks_times(const NeighbourBlocks& n, const double* x, int32_t k,
                                        int32_t end) {
  double sx = 0, sy = 0, sz = 0;
  if (k + 4 <= end) {
    if constexpr (std::is_void<L>::value) {
      double ax[4] = {}, ay[4] = {}, az[4] = {};
      for (; k + 4 <= end; k += 4)
        for (int lane = 0; lane < 4; ++lane)
          add_spring_blocks(n, x, size_t(k + lane), ax[lane], ay[lane], az[lane]);
      sx = (ax[0] + ax[1]) + (ax[2] + ax[3]);
      sy = (ay[0] + ay[1]) + (ay[2] + ay[3]);
      sz = (az[0] + az[1]) + (az[2] + az[3]);
    } else if constexpr (L::W == 2) {
      typename L::V ax{}, ay{}, az{}, bx{}, by{}, bz{};
      for (; k + 4 <= end; k += 4) {
        add_spring_blocks(n, x, size_t(k), ax, ay, az);
        add_spring_blocks(n, x, size_t(k + 2), bx, by, bz);
      }
      sx = (ax[0] + ax[1]) + (bx[0] + bx[1]);
      sy = (ay[0] + ay[1]) + (by[0] + by[1]);
      sz = (az[0] + az[1]) + (bz[0] + bz[1]);
    } else {
      static_assert(L::W == 4, "four lanes of double");
      typename L::V ax{}, ay{}, az{};
      for (; k + 4 <= end; k += 4) add_spring_blocks(n, x, size_t(k), ax, ay, az);
      sx = (ax[0] + ax[1]) + (ax[2] + ax[3]);
      sy = (ay[0] + ay[1]) + (ay[2] + ay[3]);
      sz = (az[0] + az[1]) + (az[2] + az[3]);
    }
  }
  for (; k < end; ++k) add_spring_blocks(n, x, size_t(k), sx, sy, sz);
  return Vec3(sx, sy, sz);
}

// sum_{j in nb(i)} A_ij x_j over the neighbours j of the free vertex i, negated: springs give
// -B_s, triangles J_t. kLower / kUpper: only j < i / j > i.
enum class Side { kAll, kLower, kUpper };
template <class L, Side side>
FLAGSIM_INLINE Vec3 minus_offdiagonal(const ClothTopology& topo, const ClothSystem& A,
                                      const MatX3& x, Index i) {
  const NeighbourBlocks& n = A.off;
  const int32_t begin = side == Side::kUpper ? n.lower_end[size_t(i)] : topo.adj_offset[size_t(i)];
  const int32_t end =
      side == Side::kLower ? n.lower_end[size_t(i)] : topo.adj_offset[size_t(i) + 1];
  Vec3 acc = spring_blocks_times<L>(n, x.data(), begin, end);
  if (!A.J.empty()) {
    auto take = [i](Index j) {
      return side == Side::kAll ? j != i : side == Side::kLower ? j < i : j > i;
    };
    for (int32_t k = topo.tri_adj_offset[i]; k < topo.tri_adj_offset[i + 1]; ++k) {
      const int32_t t = topo.tri_adj[k];
      Vec3 sum = Vec3::Zero();
      for (int q = 0; q < 3; ++q)
        if (take(topo.triangles(t, q))) sum += x.row(topo.triangles(t, q));
      acc.noalias() -= A.J[t] * sum;
    }
  }
  return acc;
}

// The fine-level passes over the neighbour blocks, each a struct whose run<L> takes lane type L
// (see spring_blocks_times) for run_on_widest_lanes.

// Block Gauss-Seidel: x_i <- D_i^-1 (b_i - sum_{j != i} A_ij x_j), D_i A's diagonal block, over
// the free vertices in increasing (forward) or decreasing order. from_zero: the forward sweep that
// starts from x = 0 reads only the j < i it has already set.
struct FineGaussSeidel {
  template <class L>
  FLAGSIM_INLINE static void run(const ClothTopology& topo, const ClothSystem& A, const MatX3& b,
                                 MatX3& x, bool forward, bool from_zero) {
    const Index N = topo.num_vertices();
    for (Index n = 0; n < N; ++n) {
      const Index i = forward ? n : N - 1 - n;
      if (!free_vertex(topo, i)) continue;
      const Vec3 acc =
          Vec3(b.row(i)) + (from_zero ? minus_offdiagonal<L, Side::kLower>(topo, A, x, i)
                                      : minus_offdiagonal<L, Side::kAll>(topo, A, x, i));
      x.row(i) = (A.Pinv[i] * acc).transpose();
    }
  }
};

// out_i = (A p)_i = diag_i p_i + sum_{j != i} A_ij p_j for the vertices [begin, end).
struct FineProduct {
  template <class L>
  FLAGSIM_INLINE static void run(const ClothTopology& topo, const ClothSystem& A, const MatX3& p,
                                 MatX3& out, Index begin, Index end) {
    for (Index i = begin; i < end; ++i) {
      if (!free_vertex(topo, i)) {
        out.row(i).setZero();
        continue;
      }
      out.row(i) =
          (A.diag[size_t(i)] * Vec3(p.row(i)) - minus_offdiagonal<L, Side::kAll>(topo, A, p, i))
              .transpose();
    }
  }
};

// out_i = -sum_{j > i} A_ij x_j (zero on pinned rows).
struct FineUpperHalf {
  template <class L>
  FLAGSIM_INLINE static void run(const ClothTopology& topo, const ClothSystem& A, const MatX3& x,
                                 MatX3& out) {
    for (Index i = 0; i < topo.num_vertices(); ++i)
      if (free_vertex(topo, i))
        out.row(i) = minus_offdiagonal<L, Side::kUpper>(topo, A, x, i).transpose();
      else
        out.row(i).setZero();
  }
};

// -sum_{j on one side of i} A_ij x_j for a block substitution over the free vertex i: kLower (j <
// i, forward) or kUpper (j > i, backward). The neighbour nearest i on that side, the one the
// substitution has just set, is added last, in scalars, so that row i waits on that one block
// product and not on the whole row (the rows form one dependency chain).
template <class L, Side side>
FLAGSIM_INLINE Vec3 minus_offdiagonal_nearest_last(const ClothTopology& topo, const ClothSystem& A,
                                                   const MatX3& x, Index i) {
  static_assert(side != Side::kAll, "a substitution reads one side");
  const NeighbourBlocks& n = A.off;
  const bool lower = side == Side::kLower;
  int32_t begin = lower ? topo.adj_offset[size_t(i)] : n.lower_end[size_t(i)];
  int32_t end = lower ? n.lower_end[size_t(i)] : topo.adj_offset[size_t(i) + 1];
  if (begin == end) return minus_offdiagonal<L, side>(topo, A, x, i);  // triangles only
  const int32_t nearest = lower ? end - 1 : begin;
  if (lower)
    --end;
  else
    ++begin;
  Vec3 acc = spring_blocks_times<L>(n, x.data(), begin, end);
  if (!A.J.empty()) {
    for (int32_t k = topo.tri_adj_offset[i]; k < topo.tri_adj_offset[i + 1]; ++k) {
      const int32_t t = topo.tri_adj[k];
      Vec3 sum = Vec3::Zero();
      for (int q = 0; q < 3; ++q)
        if (lower ? topo.triangles(t, q) < i : topo.triangles(t, q) > i)
          sum += x.row(topo.triangles(t, q));
      acc.noalias() -= A.J[t] * sum;
    }
  }
  double sx = 0, sy = 0, sz = 0;
  add_spring_blocks(n, x.data(), size_t(nearest), sx, sy, sz);
  return acc + Vec3(sx, sy, sz);
}

// x = (D + L)^-1 b: block forward substitution with A's lower triangle L and diagonal blocks D
// (the forward Gauss-Seidel sweep from x = 0); zero on pinned rows.
struct FineLowerSolve {
  template <class L>
  FLAGSIM_INLINE static void run(const ClothTopology& topo, const ClothSystem& A, const MatX3& b,
                                 MatX3& x) {
    for (Index i = 0; i < topo.num_vertices(); ++i) {
      if (!free_vertex(topo, i)) {
        x.row(i).setZero();
        continue;
      }
      const Vec3 acc =
          Vec3(b.row(i)) + minus_offdiagonal_nearest_last<L, Side::kLower>(topo, A, x, i);
      x.row(i) = (A.Pinv[size_t(i)] * acc).transpose();
    }
  }
};

// Eisenstat (1981): with A = (D + L) + (D + U) - D,
//   (D + L)^-1 A (D + U)^-1 p = t + (D + L)^-1 (p - D t),  t = (D + U)^-1 p,
// one backward and one forward substitution, no product with A. Row i of the backward pass solves
// D_i t_i = p_i - sum_{j>i} A_ij t_j, so u_i = p_i - D_i t_i is that sum, no product with D. The
// forward pass replaces u by s = (D + L)^-1 u in place (row i reads the rows j < i it has already
// replaced) and writes w = t + s and D w = D t + D s = p + (its row's -sum_{j<i} A_ij s_j), D_i s_i
// being the row's right-hand side; pw = p . w, summed in vertex order.
struct FineEisenstat {
  template <class L>
  FLAGSIM_INLINE static void run(const ClothTopology& topo, const ClothSystem& A, const MatX3& p,
                                 MatX3& t, MatX3& u, MatX3& w, MatX3& Dw, double& pw) {
    const Index N = topo.num_vertices();
    for (Index i = N - 1; i >= 0; --i) {
      if (!free_vertex(topo, i)) {
        t.row(i).setZero();
        u.row(i).setZero();
        continue;
      }
      const Vec3 upper = minus_offdiagonal_nearest_last<L, Side::kUpper>(topo, A, t, i);
      t.row(i) = (A.Pinv[size_t(i)] * (Vec3(p.row(i)) + upper)).transpose();
      u.row(i) = -upper.transpose();  // p_i - D_i t_i, D_i t_i being the row's p_i + upper
    }
    double sum = 0;
    for (Index i = 0; i < N; ++i) {
      if (!free_vertex(topo, i)) {
        w.row(i).setZero();
        Dw.row(i).setZero();
        continue;
      }
      const Vec3 lower = minus_offdiagonal_nearest_last<L, Side::kLower>(topo, A, u, i);
      const Vec3 si = A.Pinv[size_t(i)] * (Vec3(u.row(i)) + lower);
      u.row(i) = si.transpose();
      const Vec3 pi = p.row(i), wi = Vec3(t.row(i)) + si;
      w.row(i) = wi.transpose();
      Dw.row(i) = (pi + lower).transpose();
      sum += pi.dot(wi);
    }
    pw = sum;
  }
};

// Pass::run<L>(args...) on the widest lanes of double this CPU has (on_widest_lanes). Every width
// gives the same bits (spring_blocks_times, BlockSum).
template <class Pass, class... Args>
void run_on_widest_lanes(Args&&... args) {
  const auto pass = [](auto c, Args&... a) FLAGSIM_INLINE_LAMBDA {
    Pass::template run<typename decltype(c)::L>(a...);
  };
  on_widest_lanes<double, void(Args & ...)>(pass)(args...);
}

// A 3-vector running sum s -= a y (a a column-major 3 x 3 block), each row as
// (a_r0 y_0 + a_r1 y_1) + a_r2 y_2 and then subtracted: on three scalars (void), a 16-byte vector
// and a scalar, or one 32-byte vector whose fourth lane reads the next column and is dropped (the
// caller keeps a readable double after every block). The same bits at every width.
template <class L>
struct BlockSum {
  double s0, s1, s2;
  FLAGSIM_INLINE explicit BlockSum(const double* b) : s0(b[0]), s1(b[1]), s2(b[2]) {}
  FLAGSIM_INLINE void sub(const double* a, const double* y) {
    s0 -= (a[0] * y[0] + a[3] * y[1]) + a[6] * y[2];
    s1 -= (a[1] * y[0] + a[4] * y[1]) + a[7] * y[2];
    s2 -= (a[2] * y[0] + a[5] * y[1]) + a[8] * y[2];
  }
  FLAGSIM_INLINE Vec3 get() const { return Vec3(s0, s1, s2); }
};
#ifdef FLAGSIM_HAVE_VECTORS
template <>
struct BlockSum<Lanes16<double>> {
  using V = Lanes16<double>::V;
  V s01;
  double s2;
  FLAGSIM_INLINE explicit BlockSum(const double* b) : s01(V{b[0], b[1]}), s2(b[2]) {}
  FLAGSIM_INLINE void sub(const double* a, const double* y) {
    s01 -= (load_lanes<V>(a) * y[0] + load_lanes<V>(a + 3) * y[1]) + load_lanes<V>(a + 6) * y[2];
    s2 -= (a[2] * y[0] + a[5] * y[1]) + a[8] * y[2];
  }
  FLAGSIM_INLINE Vec3 get() const { return Vec3(s01[0], s01[1], s2); }
};
template <>
struct BlockSum<Lanes32<double>> {
  using V = Lanes32<double>::V;
  V s;
  FLAGSIM_INLINE explicit BlockSum(const double* b) : s(V{b[0], b[1], b[2], 0.0}) {}
  FLAGSIM_INLINE void sub(const double* a, const double* y) {
    s -= (load_lanes<V>(a) * y[0] + load_lanes<V>(a + 3) * y[1]) + load_lanes<V>(a + 6) * y[2];
  }
  FLAGSIM_INLINE Vec3 get() const { return Vec3(s[0], s[1], s[2]); }
};
#endif

// b_v - sum over the 9-point stencil of vertex v = (r, c) of A_vw x_w, the centre included or not
// (BlockSum<Lanes>), the neighbour (0, last) (-1: the one a forward sweep has just set, +1:
// backward; 0: none) after all the others, so that a sweep's next vertex waits for one block
// product only. `interior` (all 8 neighbours inside): see for_each_stencil_neighbour.
template <class Lanes, bool with_centre, bool interior, int last>
FLAGSIM_INLINE Vec3 b_minus_stencil_at(const MultigridLevel& L, int r, int c) {
  const int C = L.cols;
  const Index v = Index(r) * C + c;
  const double* a = L.A[9 * size_t(v)].data();
  BlockSum<Lanes> acc(L.b.data() + 3 * v);
  for_each_stencil_neighbour<interior>(L.rows, C, r, c, [&](int dr, int dc) FLAGSIM_INLINE_LAMBDA {
    if ((!with_centre && dr == 0 && dc == 0) || (last != 0 && dr == 0 && dc == last)) return;
    acc.sub(a + 9 * stencil_slot(dr, dc), L.x.data() + 3 * (v + dr * C + dc));
  });
  if (last != 0 && (interior || (c + last >= 0 && c + last < C)))
    acc.sub(a + 9 * stencil_slot(0, last), L.x.data() + 3 * (v + last));
  return acc.get();
}

template <class Lanes, bool with_centre, int last>
FLAGSIM_INLINE Vec3 b_minus_stencil(const MultigridLevel& L, int r, int c) {
  return r > 0 && r + 1 < L.rows && c > 0 && c + 1 < L.cols
             ? b_minus_stencil_at<Lanes, with_centre, true, last>(L, r, c)
             : b_minus_stencil_at<Lanes, with_centre, false, last>(L, r, c);
}

// The coarse levels' passes, run<Lanes> on lane type Lanes (BlockSum), as the fine ones.

// Block Gauss-Seidel sweep with the 9-point block stencil.
struct LevelGaussSeidel {
  template <class Lanes, bool forward>
  FLAGSIM_INLINE static void sweep(MultigridLevel& L) {
    const int C = L.cols;
    const Index n = Index(L.rows) * C;
    for (Index m = 0; m < n; ++m) {
      const Index v = forward ? m : n - 1 - m;
      if (!L.active[v]) continue;
      L.x.row(v) = (L.Dinv[v] * b_minus_stencil < Lanes, false,
                    forward ? -1 : 1 > (L, int(v / C), int(v % C)))
                       .transpose();
    }
  }
  template <class Lanes>
  FLAGSIM_INLINE static void run(MultigridLevel& L, bool forward) {
    if (forward)
      sweep<Lanes, true>(L);
    else
      sweep<Lanes, false>(L);
  }
};

// L.r = L.b - A L.x
struct LevelResidual {
  template <class Lanes>
  FLAGSIM_INLINE static void run(MultigridLevel& L) {
    const int R = L.rows, C = L.cols;
    for (int r = 0; r < R; ++r)
      for (int c = 0; c < C; ++c)
        L.r.row(Index(r) * C + c) = b_minus_stencil<Lanes, true, 0>(L, r, c).transpose();
  }
};

// out.b = P^T r: each coarse vertex sums the residuals of its 2 x 2 fine vertices.
void restrict_to(int rows, int cols, const MatX3& r, MultigridLevel& out) {
  out.b.setZero();
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j)
      out.b.row(Index(i / 2) * out.cols + j / 2) += r.row(Index(i) * cols + j);
}

// x_v += the correction of v's 2 x 2 aggregate in Lc, for the vertices v of a rows x cols level
// with take(v) (P x_c, P piecewise constant).
template <class Take>
void prolong_add(int rows, int cols, const MultigridLevel& Lc, Take take, MatX3& x) {
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const Index v = Index(r) * cols + c;
      if (take(v)) x.row(v) += Lc.x.row(Index(r / 2) * Lc.cols + c / 2);
    }
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

// Coarse correction of level l: Lc.x ~= A_{l+1}^-1 Lc.b. Below the coarsest-but-one level, two
// cycles from zero combined as two steps of flexible CG (Notay and Vassilevski's K-cycle): c1 =
// cycle(b), c2 = cycle(b - alpha1 A c1), x = the A-optimal combination of c1 and c2. The optimal
// weights make up for the piecewise-constant prolongation's too-stiff coarse operators better than
// adding the second cycle's correction plainly (a W-cycle): 128 x 128 flag 14.3 -> 12.1 CG
// iterations per step, 64 x 64 11.0 -> 9.9. It makes the preconditioner (slightly) nonlinear, so
// the outer CG is the flexible one (integrators.cpp).
void coarse_correction(Multigrid& mg, size_t l) {
  MultigridLevel& Lc = mg.levels[l + 1];
  cycle_level(mg, l + 1);                 // c1 in Lc.x
  if (l + 2 == mg.levels.size()) return;  // the coarsest level is solved exactly
  Lc.b_in = Lc.b;
  run_on_widest_lanes<LevelResidual>(Lc);
  Lc.v1 = Lc.b_in - Lc.r;  // A c1
  const double rho1 = dot(Lc.x, Lc.v1);
  if (!(rho1 > 0)) return;  // b = 0 on the active vertices: c1 = 0
  const double alpha1 = dot(Lc.x, Lc.b_in) / rho1;
  Lc.x_sum = Lc.x;  // c1
  Lc.b = Lc.b_in - alpha1 * Lc.v1;
  cycle_level(mg, l + 1);  // c2 in Lc.x
  run_on_widest_lanes<LevelResidual>(Lc);
  Lc.r = Lc.b - Lc.r;  // A c2
  const double gamma = dot(Lc.x, Lc.v1), beta = dot(Lc.x, Lc.r), zeta = dot(Lc.x, Lc.b);
  const double den = beta - gamma * gamma / rho1;
  if (den > 0) {
    const double alpha2 = zeta / den;
    Lc.x = (alpha1 - gamma * alpha2 / rho1) * Lc.x_sum + alpha2 * Lc.x;
  } else {  // c2 adds nothing A-independent of c1
    Lc.x = alpha1 * Lc.x_sum;
  }
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
  run_on_widest_lanes<LevelGaussSeidel>(L, true);
  run_on_widest_lanes<LevelResidual>(L);
  restrict_to(L.rows, L.cols, L.r, Lc);
  coarse_correction(mg, l);
  prolong_add(L.rows, L.cols, Lc, [&](Index v) { return L.active[v] != 0; }, L.x);
  run_on_widest_lanes<LevelGaussSeidel>(L, false);
}

// Index into Lc.A of the block coupling the 2 x 2 aggregates of the level below's vertices (r, c)
// and (r2, c2) (neighbours or the same aggregate), in the first one's stencil.
inline Index coarse_index(const MultigridLevel& Lc, int r, int c, int r2, int c2) {
  const int R = r / 2, C = c / 2;
  return 9 * (Index(R) * Lc.cols + C) + stencil_slot(r2 / 2 - R, c2 / 2 - C);
}
inline Mat3& coarse_block(MultigridLevel& Lc, int r, int c, int r2, int c2) {
  return Lc.A[size_t(coarse_index(Lc, r, c, r2, c2))];
}

// The stencil's lower half from its upper half: block (v, w) = block (w, v), all blocks symmetric.
void mirror_lower_half(MultigridLevel& L) {
  for (int r = 0; r < L.rows; ++r)
    for (int c = 0; c < L.cols; ++c)
      for_each_stencil_neighbour(L.rows, L.cols, r, c, [&](int dr, int dc) {
        const int k = stencil_slot(dr, dc);
        if (k > kStencilCentre)
          L.A[9 * (Index(r + dr) * L.cols + c + dc) + (8 - k)] =
              L.A[9 * (Index(r) * L.cols + c) + k];
      });
}

// Inverse diagonal blocks; an inactive vertex gets identity (its equation reads x = b = 0).
void finish_level(MultigridLevel& L) {
  const Index n = Index(L.rows) * L.cols;
  for (Index v = 0; v < n; ++v) {
    if (!L.active[v]) {
      L.A[9 * v + kStencilCentre].setIdentity();
      L.Dinv[v].setIdentity();
    } else {
      L.Dinv[v] = L.A[9 * v + kStencilCentre].inverse();
    }
  }
}

// Level 0 = P^T A P from the terms of A: with P piecewise constant, a term X (x) w w^T becomes
// X (x) (P^T w)(P^T w)^T; a spring inside one aggregate cancels, one across two aggregates adds B
// to both diagonals and -B to both couplings (pinned ends dropped). The couplings are summed in
// the stencil's upper half only, at the blocks precomputed in multigrid_build, and mirrored:
// 128 x 128 setup 2.3 -> 0.9 ms, same bits.
void galerkin_fine(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg) {
  MultigridLevel& L0 = mg.levels.front();
  for (auto& a : L0.A) a.setZero();
  const int C = topo.cols;
  for (Index i = 0; i < topo.num_vertices(); ++i)
    if (mg.vertex_block[size_t(i)] >= 0) L0.A[size_t(mg.vertex_block[size_t(i)])] += A.D[i];
  for (Index s = 0; s < topo.num_springs(); ++s) {
    const int32_t* k = &mg.spring_block[3 * size_t(s)];
    if (k[0] < 0 && k[1] < 0) continue;
    const SpringBlock& B = A.B[size_t(s)];
    // B = a I + e e^T entry by entry into the blocks (no Mat3 temporary; see
    // assemble_implicit_system).
    const double b[3][3] = {{B.a + B.e[0] * B.e[0], B.e[0] * B.e[1], B.e[0] * B.e[2]},
                            {B.e[1] * B.e[0], B.a + B.e[1] * B.e[1], B.e[1] * B.e[2]},
                            {B.e[2] * B.e[0], B.e[2] * B.e[1], B.a + B.e[2] * B.e[2]}};
    for (int t = 0; t < 3; ++t) {
      if (k[t] < 0) continue;
      double* m = L0.A[size_t(k[t])].data();
      const double sign = t == 2 ? -1.0 : 1.0;
      for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r) m[3 * c + r] += sign * b[r][c];
    }
  }
  auto rc = [C](Index i, int& r, int& c) {
    r = int(i / C);
    c = int(i % C);
  };
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
        const Index k = coarse_index(L0, ri, ci, rj, cj);
        if (k % 9 >= kStencilCentre) L0.A[size_t(k)] += A.J[t];  // the upper half; mirrored below
      }
    }
  mirror_lower_half(L0);
  finish_level(L0);
}

// Lc = P^T A_L P: each aggregate's stencil sums the 9-point stencils of its 2 x 2 vertices of L.
void coarsen(const MultigridLevel& L, MultigridLevel& Lc) {
  for (auto& a : Lc.A) a.setZero();
  for (int r = 0; r < L.rows; ++r)
    for (int c = 0; c < L.cols; ++c) {
      const Index v = Index(r) * L.cols + c;
      if (!L.active[v]) continue;
      for_each_stencil_neighbour(L.rows, L.cols, r, c, [&](int dr, int dc) {
        const int r2 = r + dr, c2 = c + dc;
        if (!L.active[Index(r2) * L.cols + c2]) return;
        coarse_block(Lc, r, c, r2, c2) += L.A[9 * v + stencil_slot(dr, dc)];
      });
    }
  finish_level(Lc);
}

// The coarsest level's dense matrix, then its Cholesky factor in the lower triangle of F (for
// coarsest_solve).
void factor_coarsest(const MultigridLevel& Lc, Eigen::MatrixXd& F) {
  F.setZero();
  for (int r = 0; r < Lc.rows; ++r)
    for (int c = 0; c < Lc.cols; ++c) {
      const Index v = Index(r) * Lc.cols + c;
      for_each_stencil_neighbour(Lc.rows, Lc.cols, r, c, [&](int dr, int dc) {
        F.block<3, 3>(3 * v, 3 * (Index(r + dr) * Lc.cols + c + dc)) =
            Lc.A[9 * v + stencil_slot(dr, dc)];
      });
    }
  const Index n = F.rows();
  for (Index j = 0; j < n; ++j) {
    double d = F(j, j);
    for (Index k = 0; k < j; ++k) d -= F(j, k) * F(j, k);
    d = std::sqrt(d);  // A_c is SPD: P has full column rank on the active vertices
    F(j, j) = d;
    for (Index i = j + 1; i < n; ++i) {
      double s = F(i, j);
      for (Index k = 0; k < j; ++k) s -= F(i, k) * F(j, k);
      F(i, j) = s / d;
    }
  }
}

}  // namespace

void NeighbourBlocks::build(const ClothTopology& topo) {
  const Index N = topo.num_vertices();
  const size_t slots = topo.adj_other.size();
  entry.resize(slots);
  nb.resize(slots);
  lower_end.resize(size_t(N));
  for (auto* v : {&a, &ex, &ey, &ez}) v->assign(slots, 0.0);
  for (Index i = 0; i < N; ++i) {
    const int32_t b = topo.adj_offset[size_t(i)], e = topo.adj_offset[size_t(i) + 1];
    std::iota(entry.begin() + b, entry.begin() + e, b);
    std::sort(entry.begin() + b, entry.begin() + e, [&](int32_t p, int32_t q) {
      return std::make_pair(topo.adj_other[size_t(p)], p) <
             std::make_pair(topo.adj_other[size_t(q)], q);
    });
    lower_end[size_t(i)] = e;
    for (int32_t k = b; k < e; ++k) {
      nb[size_t(k)] = topo.adj_other[size_t(entry[size_t(k)])];
      if (nb[size_t(k)] > i && lower_end[size_t(i)] == e) lower_end[size_t(i)] = k;
    }
  }
}

void NeighbourBlocks::fill(const ClothTopology& topo, const std::vector<SpringBlock>& B) {
  parallel_for(Index(entry.size()), [&](Index k) {
    const SpringBlock& s = B[size_t(topo.adj_spring[size_t(entry[size_t(k)])])];
    a[size_t(k)] = s.a;
    ex[size_t(k)] = s.e[0];
    ey[size_t(k)] = s.e[1];
    ez[size_t(k)] = s.e[2];
  });
}

void apply_system(const ClothTopology& topo, const ClothSystem& A, const MatX3& p, MatX3& out) {
  // (A p)_i = diag_i p_i + sum_{j != i} A_ij p_j: the smoother's kernel plus the diagonal block,
  // in chunks of vertices (the wide kernel is a call, not inlined into the loop's body).
  constexpr Index kChunk = 256;
  const Index N = topo.num_vertices(), chunks = (N + kChunk - 1) / kChunk;
  parallel_for_if(N >= kParallelGrain, chunks, [&](Index c) {
    run_on_widest_lanes<FineProduct>(topo, A, p, out, c * kChunk, std::min(N, (c + 1) * kChunk));
  });
}

void lower_block_solve(const ClothTopology& topo, const ClothSystem& A, const MatX3& b, MatX3& x) {
  run_on_widest_lanes<FineLowerSolve>(topo, A, b, x);
}

double eisenstat_product(const ClothTopology& topo, const ClothSystem& A, const MatX3& p, MatX3& t,
                         MatX3& u, MatX3& w, MatX3& Dw) {
  double pw = 0;
  run_on_widest_lanes<FineEisenstat>(topo, A, p, t, u, w, Dw, pw);
  return pw;
}

bool multigrid_applies(const ClothTopology& topo) {
  return topo.rows >= 1 && topo.cols >= 1 && Index(topo.rows) * topo.cols == topo.num_vertices() &&
         topo.num_vertices() > kCoarsestVertices;
}

void multigrid_build(const ClothTopology& topo, Multigrid& mg) {
  mg.levels.clear();
  mg.fine_r.setZero(topo.num_vertices(), 3);
  int R = topo.rows, C = topo.cols;
  std::vector<uint8_t> active(topo.num_vertices());
  for (Index i = 0; i < topo.num_vertices(); ++i) active[i] = free_vertex(topo, i);
  while (Index(R) * C > kCoarsestVertices) {
    MultigridLevel L;
    L.rows = (R + 1) / 2;
    L.cols = (C + 1) / 2;
    const Index n = Index(L.rows) * L.cols;
    L.A.assign(9 * n + 1, Mat3::Zero());  // + 1: padding for b_minus_stencil_at's wide loads
    L.Dinv.assign(n, Mat3::Identity());
    L.active.assign(n, 0);
    for (int r = 0; r < R; ++r)
      for (int c = 0; c < C; ++c)
        if (active[Index(r) * C + c]) L.active[Index(r / 2) * L.cols + c / 2] = 1;
    for (MatX3* m : {&L.x, &L.b, &L.r, &L.x_sum, &L.b_in, &L.v1}) m->setZero(n, 3);
    active = L.active;
    R = L.rows;
    C = L.cols;
    mg.levels.push_back(std::move(L));
  }
  const Index n = 3 * Index(R) * C;
  mg.coarse_L.setZero(n, n);
  mg.coarse_y.setZero(n);
  // Level 0's block indices (see Multigrid).
  const MultigridLevel& L0 = mg.levels.front();
  auto block = [&](Index i, Index j) -> int32_t {  // the aggregates of fine vertices i and j
    const int C = topo.cols;
    return int32_t(coarse_index(L0, int(i / C), int(i % C), int(j / C), int(j % C)));
  };
  mg.vertex_block.assign(size_t(topo.num_vertices()), -1);
  for (Index i = 0; i < topo.num_vertices(); ++i)
    if (free_vertex(topo, i)) mg.vertex_block[size_t(i)] = block(i, i);
  mg.spring_block.assign(3 * size_t(topo.num_springs()), -1);
  for (Index s = 0; s < topo.num_springs(); ++s) {
    const Index i = topo.springs(s, 0), j = topo.springs(s, 1);
    const bool fi = free_vertex(topo, i), fj = free_vertex(topo, j);
    const int32_t ij = block(i, j);
    if (fi && fj && ij % 9 == kStencilCentre) continue;  // inside one aggregate: cancels
    int32_t* out = &mg.spring_block[3 * size_t(s)];
    if (fi) out[0] = block(i, i);
    if (fj) out[1] = block(j, j);
    if (fi && fj) out[2] = ij % 9 > kStencilCentre ? ij : block(j, i);
  }
}

void multigrid_setup(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg) {
  galerkin_fine(topo, A, mg);
  for (size_t l = 0; l + 1 < mg.levels.size(); ++l) coarsen(mg.levels[l], mg.levels[l + 1]);
  factor_coarsest(mg.levels.back(), mg.coarse_L);
}

void multigrid_vcycle(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg,
                      const MatX3& r, MatX3& z) {
  z.setZero();
  run_on_widest_lanes<FineGaussSeidel>(topo, A, r, z, true, true);
  // After a forward sweep x_i solves row i against the x_j, j < i, it had: the residual of row i
  // is what the j > i contribute, r_i - (A x)_i = -sum_{j > i} A_ij x_j (half a product).
  run_on_widest_lanes<FineUpperHalf>(topo, A, z, mg.fine_r);
  restrict_to(topo.rows, topo.cols, mg.fine_r, mg.levels.front());
  cycle_level(mg, 0);
  prolong_add(
      topo.rows, topo.cols, mg.levels.front(), [&](Index v) { return free_vertex(topo, v); }, z);
  run_on_widest_lanes<FineGaussSeidel>(topo, A, r, z, false, false);
}

}  // namespace flagsim
