// Geometric multigrid for the pressure operator K of fluid/poisson.h (7 points, per-side
// boundary conditions, solid cells), used as the preconditioner of conjugate gradient: MGPCG
// (McAdams, Sifakis and Teran 2010, "A parallel multigrid Poisson solver for fluids simulation on
// large grids"). One V-cycle per CG iteration:
//   level 0 = K's grid; each coarser level halves every axis that can be halved (see below); a
//   coarse cell is fluid when any of its children is;
//   coarse operators rediscretised as finite volumes: the conductance of a coarse face is the sum
//   of the fine conductances across it times (fine distance / coarse distance), so a solid wall
//   of fine cells stays a wall on every level and open cells keep the 7-point stencil (2x the
//   fine conductance per level in 3-D);
//   red-black Gauss-Seidel smoothing (smooth_sweeps(l) before, the reverse order after: the
//   cycle is a symmetric operator, as CG needs; more sweeps on the cheap coarse levels),
//   trilinear prolongation renormalised over the fluid coarse cells (so a constant is
//   interpolated exactly beside solids and domain ends), the restriction its transpose; with
//   one colouring pass the residual is taken on colour 0 only (colour 1's is 0 right after its
//   half-sweep) and the prolongation adds to colour 0 only (colour 1's half-sweep overwrites the
//   rest unread);
//   the coarsest level solved exactly by a dense Cholesky factor (with one rank-one term per
//   pocket that touches no Dirichlet side, so singular systems factor too), or, when it is too
//   large to factor, by kCoarsestSweeps symmetric Gauss-Seidel sweeps.
// Each leg on a level (down: smoothing and the residual; up: the prolongation and smoothing) is
// one temporally blocked pass over its planes, with the bits of the stage-by-stage order
// (run_stages in the .cpp).
// Deterministic for any thread count: every update of one colour is independent of the others,
// transfers are per cell, the coarsest solve is sequential. All memory is taken in build().
//
// Which axes halve: a periodic axis while its length is even, a bounded one while it is longer
// than one cell (an odd one is padded by a solid half cell); an axis halves only while its cell
// is no longer than the shortest other one (so coarse cells are at most 2:1), and coarsening
// stops at kCoarsestCells cells. Limit: a periodic axis of odd length stops halving at once and
// holds the others to twice its cell size, so the coarsest level can be large (then the sweeps,
// and more CG iterations): prefer even periodic lengths (powers of two times a small factor).
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "fluid/grid.h"
#include "fluid/poisson.h"

namespace flagsim {

/// Gauss-Seidel sweeps (red then black) before the coarse correction on level 0; as many after.
constexpr int kSmoothSweeps = 2;
/// The same on the coarser levels (an eighth of the cells or fewer each: more sweeps there are
/// cheap and take an iteration off).
constexpr int kCoarseSmoothSweeps = 3;
/// Sweeps before (and after) the coarse correction on level l.
constexpr int smooth_sweeps(int l) { return l == 0 ? kSmoothSweeps : kCoarseSmoothSweeps; }
/// Coarsening stops once a level has at most this many cells.
constexpr std::size_t kCoarsestCells = 64;
/// Largest coarsest level factored densely (its factor takes 8 n^2 bytes: 32 MiB at 2048).
constexpr std::size_t kMaxDirectCells = 2048;
/// Symmetric Gauss-Seidel sweeps on a coarsest level too large to factor.
constexpr int kCoarsestSweeps = 32;
/// Bytes per cell the hierarchy takes, an upper bound (bytes(): 37.3 for a double grid, 33 for a
/// float one, at 32^3-128^3), counted by FluidParams::memory_bytes.
constexpr double kMultigridBytesPerCell = 40;

/// One level of the hierarchy: an n0 x n1 x n2 cell grid (C order) and its operator
///   (A x)_i = diag_i x_i - sum_d (c_d[i] x[i + e_d] + c_d[i - e_d] x[i - e_d]),
/// c_d[i] the conductance between cell i and its +d neighbour (wrapping on periodic axes; 0 at a
/// bounded end and to a solid cell), diag_i the sum of cell i's six conductances plus those of
/// its Dirichlet (GhostZero) sides.
template <class T>
struct MultigridLevel {
  Shape3 shape;
  bool periodic[3] = {false, false, false};
  bool dirichlet[3][2] = {{false, false}, {false, false}, {false, false}};  ///< GhostZero sides
  bool halved[3] = {false, false, false};  ///< axis halved on the way to the next coarser level
  int scale[3] = {1, 1, 1};                ///< cell size in fine cells along each axis
  /// Level 0: every conductance 1 and x = 0 on solid cells, so the sum over all six neighbours
  /// is the sum over the fluid ones and the mask lives in diag only (c is not kept).
  bool unit = false;
  std::array<AlignedVector<T>, 3> c;  ///< conductances, shape.size() each
  AlignedVector<T> diag, inv_diag;    ///< inv_diag 0 on solid (inactive) cells
  AlignedVector<T> x, b, r;           ///< solution, right-hand side, residual scratch
  AlignedVector<T> inv_norm;  ///< 1 / (prolongation weights from fluid coarse cells); not coarsest
  /// Transfers to the next coarser level, per axis: restriction entries (fine index, weight) per
  /// coarse index (r_count of them: 4 on a halved axis, else 1) and prolongation entries (coarse
  /// index, weight) per fine index (p_count: 2 or 1); weight 0 beyond a bounded end.
  int r_count[3] = {1, 1, 1}, p_count[3] = {1, 1, 1};
  std::array<std::vector<int32_t>, 3> r_idx, p_idx;
  std::array<AlignedVector<T>, 3> r_w, p_w;
  /// Colouring passes: 1, plus 1 per periodic axis of odd length > 1 (its wrap joins two cells
  /// of one colour; the cells on its last slab are updated in a pass of their own).
  int passes = 1;
};

template <class T>
struct LevelArgs;

/// The V-cycle's scalar, whatever the grid's: a preconditioner needs no more than float (CG in
/// the grid's precision sets the accuracy), and float halves the memory it streams.
using MgScalar = float;

template <class T>
class PoissonMultigrid {
 public:
  /// Builds the hierarchy for op (alpha = 0, beta = 1; sides Periodic, Neumann or GhostZero,
  /// Fixed throws InvalidArgument), with op.solid when set. Allocates everything apply needs.
  void build(const Laplace7& op);
  /// z = M^-1 r: one V-cycle from z = 0 (r, z: op.shape.size(), z = 0 on solid cells). A
  /// symmetric positive (semi-)definite linear operator of r. No allocation.
  void apply(const T* r, T* z);
  /// y = K x for x = 0 on solid cells (y = 0 there): CG's product (natural rows in and out; it
  /// allocates split copies: a check for tests, not for a step).
  void apply_operator(const T* x, T* y);
  /// K x = b by CG preconditioned with apply (MGPCG), from the initial guess in x, as solve_cg
  /// (fluid/poisson.h) defines it: stops at max|r| <= tol max|b| over the unknowns or after
  /// max_iter iterations; a singular K solves for the part of b with zero mean over the
  /// unknowns. The unknowns are the cells with an open face or a Dirichlet side (x = 0 on the
  /// others: solid cells, and fluid cells walled in on all six sides). CG runs on the levels'
  /// split rows (x and b copied in, x out, once per solve: w.z holds the split x), z = M r is the
  /// cycle's float level-0 x. Fused passes: the new direction with the product and s . q (one
  /// temporally blocked pass), the update with max|r| and sum r, the V-cycle's exit with r . z;
  /// each dot product is summed per plane in a fixed order, then over the planes in order (any
  /// thread count: same bits). No allocation.
  CgResult solve(const T* b, T* x, double tol, int max_iter, CgScratch<T>& w);

  int levels() const { return int(levels_.size()); }
  const MultigridLevel<MgScalar>& level(int l) const { return levels_[std::size_t(l)]; }
  /// True when the coarsest level is solved by a dense factor (false: by sweeps).
  bool direct_coarsest() const { return !chol_.empty(); }
  /// Bytes held by the hierarchy and its coarsest factor.
  std::size_t bytes() const;

 private:
  // build's parts, in order.
  void allocate_scratch();
  void build_product(const Laplace7& op);
  /// The coarsest level's dense factor (none: it is swept).
  void factor_coarsest();
  /// Every level's per-cell arrays to rows split by the parity of k.
  void split_layout();
  /// One V-cycle: z = M r on natural rows; z == nullptr (the solve's): r split as the levels,
  /// M r left in level 0's x, r . z and sum z per plane in part_.
  void vcycle(const T* r, T* z);
  /// natural <-> split rows (the levels' layout), plane by plane.
  void split_copy(const LevelArgs<T>& a, T* natural, T* split, bool to_split);
  LevelArgs<MgScalar> args(int l);
  LevelArgs<T> cg_args();
  std::vector<MultigridLevel<MgScalar>> levels_;
  MultigridLevel<T> product_;         ///< level 0's shape and diag in T: CG's product
  AlignedVector<MgScalar> zero_row_;  ///< zeros, a row of the widest level: missing neighbours
  AlignedVector<T> zero_row_t_;       ///< the same in T
  AlignedVector<MgScalar> parity_;    ///< 1, 0, 1, 0, ...: colour 0 of a row
  std::vector<int32_t> cell_of_;      ///< coarsest: dense index -> cell
  std::vector<double> chol_;          ///< coarsest: lower Cholesky factor, m x m row-major
  std::vector<double> rhs_;           ///< coarsest: m
  bool singular_ = false, any_inactive_ = false;
  std::size_t n_active_ = 0;                 ///< level 0's unknowns
  std::array<std::vector<double>, 2> part_;  ///< per-plane partial sums of the solve
};

}  // namespace flagsim
