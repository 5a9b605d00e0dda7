// Trilinear sampling of the staggered field and self-advection of the velocity:
// semi-Lagrangian (Stam 1999 §2.2, linear backtrace) and MacCormack with the clamping limiter
// (Selle, Fedkiw, Kim, Liu, Rossignac 2008, §3 and §4).
#pragma once
#include "fluid/grid.h"

namespace flagsim {

/// Boundary data for sampling. Periodic grids wrap. Bounded grids hold each component's nearest
/// node value beyond its last node (zero-gradient: free slip on walls, outflow); in advection a
/// departure point upstream of the inflow face (x < origin.x) takes `inflow` (m/s) instead.
struct SampleBoundary {
  Vec3 inflow{0, 0, 0};  ///< m/s, tunnel inflow velocity (ignored when periodic)
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

/// Semi-Lagrangian self-advection: out = u(x - dt u(x)) at every face (Stam 1999).
/// u, out: same geometry, distinct; dt in s.
template <class T>
void advect_semi_lagrangian(const MacGrid<T>& u, double dt, const SampleBoundary& bc, MacGrid<T>& out);

/// MacCormack (Selle et al. 2008 eq. 9): hat = A(u), bar = A^R(hat), out = hat + (u - bar) / 2,
/// clamped to the extrema of the 8 nodes the first backtrace interpolated from (§4). hat is
/// scratch of u's geometry. u, hat, out distinct.
template <class T>
void advect_maccormack(const MacGrid<T>& u, double dt, const SampleBoundary& bc, MacGrid<T>& hat,
                       MacGrid<T>& out);

}  // namespace flagsim
