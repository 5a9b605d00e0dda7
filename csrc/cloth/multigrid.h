// The implicit cloth system (Baraff-Witkin 1998 eq. 16) in compact form, and an aggregation
// multigrid V-cycle that preconditions its CG solve on grid flags.
#pragma once
#include <cstdint>
#include <vector>

#include "cloth/forces.h"
#include "cloth/topology.h"
#include "common/types.h"

namespace flagsim {

/// A = M - h df/dv - h^2 df/dx on the free vertices (Baraff-Witkin's filter drops pinned rows and
/// columns): with 1_i the indicator of vertex i and (x) the Kronecker product,
///   A = sum_i D_i (x) 1_i 1_i^T + sum_s B_s (x) (1_i - 1_j)(1_i - 1_j)^T + sum_t J_t (x) 1_t 1_t^T
/// D_i = m_i I + h Dv_i (kg), B_s = h^2 K_s + h k_d I per spring s = (i, j) (kg), J_t = (h/9) Jw_t
/// per triangle t ("triangle" drag only, kg). Every term is symmetric positive semi-definite.
struct ClothSystem {
  std::vector<Mat3> D;         ///< (N)
  std::vector<SpringBlock> B;  ///< (S)
  std::vector<Mat3> J;         ///< (T) or empty
  std::vector<Mat3> Pinv;      ///< (N) inverses of A's 3x3 diagonal blocks (block Jacobi)
};

/// out = A p (N x 3); rows of pinned vertices are zero, p's pinned rows must be zero.
void apply_system(const ClothTopology& topo, const ClothSystem& A, const MatX3& p, MatX3& out);

/// One coarse level: a rows x cols grid whose vertex (r, c) aggregates the 2 x 2 vertices
/// (2r..2r+1, 2c..2c+1) of the level below. Its Galerkin operator P^T A P (P piecewise constant,
/// 3x3 identity blocks) couples each vertex to its 8 neighbours at most.
struct MultigridLevel {
  int rows = 0, cols = 0;
  std::vector<Mat3> A;           ///< (9 rows cols): A[9 v + 3 (dr + 1) + dc + 1] couples v, v + (dr, dc)
  std::vector<Mat3> Dinv;        ///< (rows cols) inverse diagonal blocks (identity if inactive)
  std::vector<uint8_t> active;   ///< (rows cols) 1 if it aggregates at least one free vertex
  MatX3 x, b, r;                 ///< (rows cols x 3) solution, right-hand side, residual
  MatX3 x_sum, b_in;             ///< (rows cols x 3) W-cycle: first pass's x, the level's b
};

/// A 3x3 block padded to 4 rows (row 3 zero), so a block times a vector is three 4-wide
/// multiply-adds of its columns (SSE2, no -march needed).
using Mat43f = Eigen::Matrix<float, 4, 3>;
using MatX4f = Eigen::Matrix<float, Eigen::Dynamic, 4, Eigen::RowMajor>;

/// Offsets (dr, dc) of the couplings a grid flag's springs and triangles make from vertex (r, c)
/// to later vertices (row-major order); the earlier ones are their mirror images.
constexpr int kFineStencil = 6;
constexpr int kFineOffset[kFineStencil][2] = {{0, 1}, {0, 2}, {1, -1}, {1, 0}, {1, 1}, {2, 0}};
constexpr int kFinePad = 2;  ///< zero border around the fine grid, in vertices

/// The smoother's fine level in single precision (the preconditioner need not be double; PCG
/// is), laid out as the grid: vertex (r, c) at p = (r + 2) W + c + 2, W = cols + 4, in a zero
/// border of 2, so the neighbour p + o_k of any vertex is read without an index or bounds check.
struct MultigridFine {
  int stride = 0;                ///< W = cols + 4
  /// (kFineStencil Np) M[6 p + k] = -A_{p, p + o_k} = -A_{p + o_k, p} (A's blocks are
  /// symmetric), Np = (rows + 4) W
  std::vector<Mat43f, Eigen::aligned_allocator<Mat43f>> M;
  std::vector<Mat43f, Eigen::aligned_allocator<Mat43f>> Dinv;  ///< (Np) inverse diagonal blocks; 0 for pinned and border
  MatX4f b, x;                   ///< (Np x 4, column 3 zero) right-hand side, smoothed solution
  std::vector<int32_t> spring_slot;  ///< (S) index into M of spring s, -1 if an end is pinned
  std::vector<int32_t> tri_slot;     ///< (3 T) index into M of triangle t's pairs (0,1), (0,2), (1,2), or -1
};

/// Levels are sized once per topology (multigrid_build); no allocation afterwards.
struct Multigrid {
  MultigridFine fine;
  std::vector<MultigridLevel> levels;  ///< levels[0] aggregates the cloth's vertices
  Eigen::MatrixXd coarse_L;  ///< (3n x 3n) Cholesky factor of the coarsest level (n vertices)
  VecX coarse_y;             ///< (3n)
};

/// True when topo is a rows x cols grid (vertex r cols + c) that multigrid_build can coarsen and
/// whose springs and triangles couple only vertices kFineOffset apart.
bool multigrid_applies(const ClothTopology& topo);

/// Levels down to at most kCoarsestVertices vertices (solved directly).
void multigrid_build(const ClothTopology& topo, Multigrid& mg);

/// Galerkin operators of every level from A, and the coarsest level's Cholesky factor.
void multigrid_setup(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg);

/// z = V(r): one symmetric V-cycle (forward block Gauss-Seidel before, backward after the coarse
/// correction, exact coarsest solve), a symmetric positive definite approximation of A^-1.
/// r, z (N x 3); r's pinned rows must be zero, z's come out zero. Returns r.z (for PCG).
double multigrid_vcycle(const ClothTopology& topo, const ClothSystem& A, Multigrid& mg, const MatX3& r,
                      MatX3& z);

}  // namespace flagsim
