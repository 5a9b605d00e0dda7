// Trilinear sampling of the staggered field and self-advection of the velocity:
// semi-Lagrangian (Stam 1999 §2.2, linear backtrace) and MacCormack with the clamping limiter
// (Selle, Fedkiw, Kim, Liu, Rossignac 2008, §3 and §4).
#pragma once
#include "fluid/grid.h"
#include "fluid/solids.h"

namespace flagsim {

/// Boundary data for sampling. Periodic grids wrap. Bounded grids hold each component's nearest
/// node value beyond its last node (zero-gradient: free slip on walls, outflow); in advection a
/// departure point upstream of the inflow face (x < origin.x) takes `inflow` (m/s) times the
/// profile's factor at that point instead.
struct SampleBoundary {
  Vec3 inflow{0, 0, 0};  ///< m/s, tunnel inflow velocity (ignored when periodic)
  InflowShape shape;     ///< the inflow profile's factor at the departure point (1: uniform)
};

/// Trilinear value of component c at point p given in cell units, p = (x - origin) / h.
/// Uses a + f (b - a) so that a uniform field is reproduced exactly.
template <class T>
T sample_component(const MacGrid<T>& g, int c, const double p[3]);

/// Velocity at arbitrary world points: out.row(m) = u(points.row(m)) (m/s). Points outside the
/// domain box are moved to the nearest point of the box (the nearest boundary value) and counted.
/// points, out: (M x 3) m, m/s. Returns the number of points outside. No allocation.
template <class T>
long sample_velocity(const MacGrid<T>& g, const double* points, long m, double* out);

/// The transpose of sample_velocity: adds scale * values.row(r) onto the nodes that sample
/// reads at points.row(r), each node times the weight it has there (the same cells, the same
/// clamping to the domain box, the same trilinear weights), so for any field g and values J
///   sum over nodes of g . (spread J) = scale * sum over points of sample(g) . J.
/// points, values: (M x 3) m and any unit; the grid gains scale x that unit. The weights at a
/// point sum to 1 per component, so the sum over the nodes of each component gains scale x the
/// sum of the values. Serial in point order: the same bits for any thread count. No allocation.
template <class T>
void spread_velocity(const double* points, long m, const double* values, double scale,
                     MacGrid<T>& g);

/// Per point, the largest over the three components of the sum of the squared weights sample
/// gives the nodes it reads there (1/8 at the centre of a component's cell, 1 on a node): the
/// share of a unit velocity change spread there that sampling at the point reads back.
/// points (M x 3) m, out (M). No allocation.
template <class T>
void sample_weight_squares(const MacGrid<T>& g, const double* points, long m, double* out);

/// Semi-Lagrangian self-advection: out = u(x - dt u(x)) at every face (Stam 1999).
/// u, out: same geometry, distinct; dt in s. This and advect_maccormack are the generic kernels,
/// the reference the Fluid's padded path (advect_padded) is tested against.
template <class T>
void advect_semi_lagrangian(const MacGrid<T>& u, double dt, const SampleBoundary& bc,
                            MacGrid<T>& out);

/// MacCormack (Selle et al. 2008 eq. 9): hat = A(u), bar = A^R(hat), out = hat + (u - bar) / 2,
/// clamped to the extrema of the 8 nodes the first backtrace interpolated from (§4). hat is
/// scratch of u's geometry. u, hat, out distinct.
template <class T>
void advect_maccormack(const MacGrid<T>& u, double dt, const SampleBoundary& bc, MacGrid<T>& hat,
                       MacGrid<T>& out);

/// Copy of one component with G ghost layers on every side, so a stencil within G nodes of any
/// node needs no index arithmetic: a periodic grid's ghosts wrap, a bounded grid's repeat the
/// nearest node (the clamp of advect_semi_lagrangian's sampling). Allocated once.
template <class T>
struct PaddedComponent {
  /// 3: departures of up to 3 cells on every axis take the vector paths (advect.cpp far_sample;
  /// the benchmark field moves 2.4 cells per step at 128^3).
  static constexpr int kGhost = 3;
  int n[3] = {0, 0, 0};   ///< unpadded node counts
  int p1 = 0, p2 = 0;     ///< padded sizes of axes 1 and 2
  bool clamped = false;   ///< ghosts repeat the nearest node (bounded grid) instead of wrapping
  AlignedVector<T> data;  ///< (m0 + 2G) x (m1 + 2G) x (m2 + 2G), m = n or resize_clamped's
  /// Wrapped ghosts, m = n.
  void resize(const Shape3& s);
  /// Clamped ghosts in a box of m >= n nodes per axis (the nodes beyond n are ghosts too): the
  /// three components of a bounded grid, sized with m = (nx + 1, ny + 1, nz + 1), share their
  /// strides, so one index reaches a node of each.
  void resize_clamped(const Shape3& s, const int m[3]);
  /// data <- src (n0 x n1 x n2, C order) with its ghosts.
  void fill(const T* src);
  /// dst (n0 x n1 x n2, C order) <- the interior of data: undoes fill.
  void unpad(T* dst) const;
  /// Index of node (i, j, k), each in [-G, m + G).
  std::size_t index(int i, int j, int k) const {
    return (std::size_t(i + kGhost) * p1 + std::size_t(j + kGhost)) * p2 + std::size_t(k + kGhost);
  }
};

/// Scratch of the padded advection (advect_padded): padded copies of u^n and
/// of the MacCormack predictor (hat: only when resized for MacCormack).
template <class T>
struct AdvectScratch {
  std::array<PaddedComponent<T>, 3> u, hat;
  /// Wrapped ghosts for a periodic grid, clamped ones in a common box for a bounded grid.
  void resize(const GridGeometry& g, bool maccormack = true);
};

/// Self-advection in place (u <- A(u)), semi-Lagrangian or MacCormack, the scheme of
/// advect_semi_lagrangian / advect_maccormack read from ghost-padded copies of u^n (scratch, sized
/// for u's geometry). Periodic grid: departures within a cell of their node take a wrap-free
/// upwind form (the same value to round-off), the others the generic kernels' arithmetic (their
/// bits). Bounded grid: the generic kernels' bits on every node (departures within the ghosts on
/// vectors, the others and the planes beside the inflow face node by node); bc: its inflow.
/// hat: scratch of u's geometry (MacCormack; unused, and may be empty, otherwise). No allocation.
/// viscous_beta = nu dt / h^2 > 0 (periodic only) adds the explicit viscous step of u^n,
/// u <- A(u^n) + beta h^2 lap u^n (7-point MAC Laplacian per component; fused into the
/// semi-Lagrangian pass, a pass of its own after MacCormack): stable for beta <= 1/6; the Fluid
/// takes it only where beta is small (docs/design.md, "Explicit viscosity on periodic fft grids").
template <class T>
void advect_padded(MacGrid<T>& u, double dt, bool maccormack, AdvectScratch<T>& scratch,
                   MacGrid<T>& hat, const SampleBoundary& bc = {}, double viscous_beta = 0);

/// advect_padded in two parts: the padded copies of u^n (reads u only), then the advection from
/// them (writes u). Between the two, u^n may still be read elsewhere (the Simulation's pipeline
/// samples it: Fluid::WriteGate).
template <class T>
void fill_advect_source(const MacGrid<T>& u, AdvectScratch<T>& scratch);
template <class T>
void advect_from_source(MacGrid<T>& u, double dt, bool maccormack, AdvectScratch<T>& scratch,
                        MacGrid<T>& hat, const SampleBoundary& bc = {}, double viscous_beta = 0);

}  // namespace flagsim
