// Matrix-free 7-point Laplacian on a 3-D array with per-side boundary conditions and an optional
// solid mask, and the (preconditioned) conjugate gradient solver used by the pressure and
// diffusion solves (Bridson, "Fluid Simulation for Computer Graphics", 2nd ed., §5.3-5.4: MIC(0);
// the multigrid preconditioner is in fluid/multigrid.h).
#pragma once
#include <cstdint>

#include "fluid/grid.h"

namespace flagsim {

/// Boundary of one side of one axis of a node array.
enum class Side : uint8_t {
  kPeriodic,   ///< wraps (both sides of the axis)
  kNeumann,    ///< zero gradient: no coupling beyond the last node
  kGhostZero,  ///< a ghost node beyond the last node holds 0 (Dirichlet)
  kFixed,      ///< the end node itself is a known value, not an unknown
};

/// K = -sum over axes of (second difference), i.e. -h^2 times the discrete Laplacian, for the
/// nodes of a `shape` array. K is symmetric positive (semi-)definite on the unknown nodes.
struct Laplace7 {
  Shape3 shape;
  Side lo[3] = {Side::kPeriodic, Side::kPeriodic, Side::kPeriodic};
  Side hi[3] = {Side::kPeriodic, Side::kPeriodic, Side::kPeriodic};
  /// Optional per-node mask (shape's size), 1 = solid: not an unknown (0 there), and no coupling
  /// across a face to it (zero flux). nullptr: no solids.
  const uint8_t* solid = nullptr;
  /// True when K is singular (no GhostZero and no Fixed side: constants are its null space; with
  /// solids, constants over the fluid nodes). Solids that cut the fluid into pockets which touch
  /// no GhostZero side leave one null vector per pocket: the solvers keep only the mean over all
  /// fluid nodes out, so such a pocket's right-hand side must sum to zero on its own (it does
  /// when it is the divergence of a field with no flux through solid faces).
  bool singular() const;
  /// True when node n (flat index) is solid.
  bool is_solid(std::size_t n) const { return solid && solid[n]; }
  /// True when node index i along axis d is a fixed (known) node.
  bool fixed(int d, int i) const {
    return (i == 0 && lo[d] == Side::kFixed) || (i == shape.n[d] - 1 && hi[d] == Side::kFixed);
  }
};

/// y = (alpha I + beta K) x on unknown nodes; y = 0 on fixed and solid nodes (x on fixed nodes is
/// read as known, x on solid nodes is not read).
template <class T>
void apply_laplace7(const Laplace7& op, double alpha, double beta, const T* x, T* y);

/// MIC(0) factor of K with periodic couplings dropped (the wrap terms stay on the diagonal, so
/// the factored matrix is SPD): Bridson §5.4, tau = 0.97, sigma = 0.25. Solid nodes and the
/// couplings to them are left out (z = 0 there).
template <class T>
struct MicPreconditioner {
  Laplace7 op;
  AlignedVector<T> inv_diag;    ///< 1 / sqrt(e) per node
  AlignedVector<uint8_t> plus;  ///< bit d: node couples to its +d neighbour (no wrap)
  void build(const Laplace7& k);
  /// z = M^-1 r (forward then backward substitution; sequential in index order).
  void apply(const T* r, T* z) const;
};

/// Scratch vectors for conjugate gradient on n nodes (allocated once).
template <class T>
struct CgScratch {
  AlignedVector<T> r, z, s, q;
  void resize(std::size_t n) {
    r.assign(n, T(0));
    z.assign(n, T(0));
    s.assign(n, T(0));
    q.assign(n, T(0));
  }
};

struct CgResult {
  int iterations = 0;
  double residual = 0;  ///< final max |r| / max |b| (0 when b = 0)
  bool converged = true;
};

/// Solves (alpha I + beta K) x = b on the unknown nodes from the initial guess in x (fixed nodes
/// of x hold their known values and couple into the residual; solid nodes of x are set to 0).
/// Preconditioner: MIC(0) when `mic` is given (requires alpha = 0, beta = 1), Jacobi otherwise.
/// Stops at max|r| <= tol max|b| (over the unknown nodes) or after max_iter iterations. For
/// singular K, b's mean over the unknown nodes is removed first. No allocation.
template <class T>
CgResult solve_cg(const Laplace7& op, double alpha, double beta, const T* b, T* x, double tol,
                  int max_iter, const MicPreconditioner<T>* mic, CgScratch<T>& w);

template <class T>
class PoissonMultigrid;

/// The same for K x = b (alpha = 0, beta = 1), preconditioned by one multigrid V-cycle per
/// iteration (MGPCG; mg built for this op, fluid/multigrid.h). No allocation.
template <class T>
CgResult solve_cg(const Laplace7& op, const T* b, T* x, double tol, int max_iter,
                  PoissonMultigrid<T>& mg, CgScratch<T>& w);

}  // namespace flagsim
