// The implicit cloth system (Baraff-Witkin 1998 eq. 16) in compact form, and an aggregation
// multigrid cycle (K-cycle below the first level) that preconditions its CG solve on grid flags.
#pragma once
#include <cstdint>
#include <vector>

#include "cloth/forces.h"
#include "cloth/topology.h"
#include "common/types.h"

namespace flagsim {

/// A's spring blocks by vertex, as the products and the smoother read them: the neighbours j of
/// vertex i in increasing order in slots [topo.adj_offset[i], topo.adj_offset[i + 1]) (those below
/// i first, up to lower_end[i]), each block B_s = a I + e e^T of the spring (i, j) in four arrays.
/// The shape is fixed by the topology (build); fill copies a step's blocks in.
struct NeighbourBlocks {
  std::vector<int32_t> nb;            ///< (2 S) the neighbour j
  std::vector<int32_t> entry;         ///< (2 S) the topology's adjacency slot (adj_spring) it holds
  std::vector<int32_t> lower_end;     ///< (N)
  std::vector<double> a, ex, ey, ez;  ///< (2 S)
  void build(const ClothTopology& topo);
  void fill(const ClothTopology& topo, const std::vector<SpringBlock>& B);
};

/// A = M - h df/dv - h^2 df/dx on the free vertices (Baraff-Witkin's filter drops pinned rows and
/// columns): with 1_i the indicator of vertex i and (x) the Kronecker product,
///   A = sum_i D_i (x) 1_i 1_i^T + sum_s B_s (x) (1_i - 1_j)(1_i - 1_j)^T + sum_t J_t (x) 1_t 1_t^T
/// D_i = m_i I + h Dv_i (kg), B_s = h^2 K_s + h k_d I per spring s = (i, j) (kg), J_t = (h/9) Jw_t
/// per triangle t ("triangle" drag only, kg). Every term is symmetric positive semi-definite.
struct ClothSystem {
  std::vector<Mat3> D;         ///< (N)
  std::vector<SpringBlock> B;  ///< (S)
  std::vector<Mat3> J;         ///< (T) or empty
  std::vector<Mat3> diag;      ///< (N) A's 3x3 diagonal blocks
  std::vector<Mat3> Pinv;      ///< (N) their inverses (block Jacobi, Gauss-Seidel)
  NeighbourBlocks off;         ///< B by vertex (the off-diagonal blocks are -B)
};

/// out = A p (N x 3); rows of pinned vertices are zero, p's pinned rows must be zero.
void apply_system(const ClothTopology& topo, const ClothSystem& A, const MatX3& p, MatX3& out);

/// Symmetric block Gauss-Seidel (SSOR, omega 1) in Eisenstat's form, with A = L + D + U (D the
/// 3x3 diagonal blocks ClothSystem::diag, L = U^T the strict lower block triangle in vertex order).
/// x = (D + L)^-1 b (N x 3); b's pinned rows must be zero, x's come out zero.
void lower_block_solve(const ClothTopology& topo, const ClothSystem& A, const MatX3& b, MatX3& x);

/// w = (D + L)^-1 A (D + U)^-1 p as t + (D + L)^-1 (p - D t) with t = (D + U)^-1 p (Eisenstat
/// 1981: one backward and one forward block substitution, no product with A), and D w; returns
/// p . w. p (N x 3, zero pinned rows); t, w, Dw (N x 3) out, zero pinned rows; u (N x 3) scratch.
double eisenstat_product(const ClothTopology& topo, const ClothSystem& A, const MatX3& p, MatX3& t,
                         MatX3& u, MatX3& w, MatX3& Dw);

/// sum_ik a_ik b_ik: the inner product of two N x 3 fields (the CG and K-cycle dot products).
inline double dot(const MatX3& a, const MatX3& b) { return (a.array() * b.array()).sum(); }

/// One coarse level: a rows x cols grid whose vertex (r, c) aggregates the 2 x 2 vertices
/// (2r..2r+1, 2c..2c+1) of the level below. Its Galerkin operator P^T A P (P piecewise constant,
/// 3x3 identity blocks) couples each vertex to its 8 neighbours at most.
struct MultigridLevel {
  int rows = 0, cols = 0;
  std::vector<Mat3> A;     ///< (9 rows cols + 1): A[9 v + 3 (dr + 1) + dc + 1] couples v, v + (dr,
                           ///< dc); the last block is padding (zero) for the vector loads
  std::vector<Mat3> Dinv;  ///< (rows cols) inverse diagonal blocks (identity if inactive)
  std::vector<uint8_t> active;  ///< (rows cols) 1 if it aggregates at least one free vertex
  MatX3 x, b, r;                ///< (rows cols x 3) solution, right-hand side, residual
  MatX3 x_sum, b_in, v1;        ///< (rows cols x 3) K-cycle: first pass's x, the level's b, A x
};

/// Levels are sized once per topology (multigrid_build); no allocation afterwards.
struct Multigrid {
  std::vector<MultigridLevel> levels;  ///< levels[0] aggregates the cloth's vertices
  Eigen::MatrixXd coarse_L;  ///< (3n x 3n) Cholesky factor of the coarsest level (n vertices)
  VecX coarse_y;             ///< (3n)
  MatX3 fine_r;              ///< (N x 3) fine residual
  /// Where level 0's setup adds the system's terms, indices into levels[0].A or -1 (fixed by the
  /// topology): per vertex, its aggregate's diagonal block (-1 if pinned); per spring, +B_s at
  /// the two aggregates' diagonal blocks and -B_s at their coupling in the stencil's upper half
  /// (the lower half is its mirror image: every term is symmetric).
  std::vector<int32_t> vertex_block;  ///< (N)
  std::vector<int32_t> spring_block;  ///< (3 S)
};

/// True when topo is a rows x cols grid (vertex r cols + c) that multigrid_build can coarsen.
bool multigrid_applies(const ClothTopology& topo);

/// Levels down to at most kCoarsestVertices vertices (solved directly).
void multigrid_build(const ClothTopology& topo, Multigrid& mg);

/// Galerkin operators of every level from A, and the coarsest level's Cholesky factor.
void multigrid_setup(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg);

/// z = V(r): one symmetric cycle (forward block Gauss-Seidel before, backward after the coarse
/// correction, K-cycles below the first level, exact coarsest solve), an approximation of A^-1
/// that is positive definite but, through the K-cycle's weights, not exactly linear: use it in
/// flexible CG.
/// r, z (N x 3); r's pinned rows must be zero, z's come out zero.
void multigrid_vcycle(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg,
                      const MatX3& r, MatX3& z);

}  // namespace flagsim
