#include "fluid/advect.h"

#include <algorithm>
#include <cmath>

namespace flagsim {

namespace {

/// Grid-node pair (i0, i1) and weight f of coordinate q (node units) along an axis of n nodes.
struct Axis {
  int i0, i1;
  double f;
};

inline Axis locate(double q, int n, bool periodic) {
  if (periodic) {
    const double fl = std::floor(q);
    long i = long(fl);
    i %= n;
    if (i < 0) i += n;
    const int i0 = int(i);
    return {i0, i0 + 1 == n ? 0 : i0 + 1, q - fl};
  }
  if (!(q > 0)) return {0, 0, 0.0};  // also catches NaN: never index out of range
  if (q >= n - 1) return {n - 1, n - 1, 0.0};
  const int i0 = int(q);
  return {i0, i0 + 1, q - i0};
}

template <class T>
inline T lerp(T a, T b, double f) {
  return T(a + f * (b - a));
}

struct Stencil {
  Axis a[3];
};

template <class T>
inline Stencil stencil_of(const MacGrid<T>& g, int c, const double p[3]) {
  Stencil s;
  for (int d = 0; d < 3; ++d)
    s.a[d] = locate(p[d] - GridGeometry::offset(c, d), g.shape[c].n[d], g.geo.periodic);
  return s;
}

template <class T>
inline T interpolate(const T* q, const Shape3& sh, const Stencil& s) {
  const Axis &x = s.a[0], &y = s.a[1], &z = s.a[2];
  const std::size_t r00 = (std::size_t(x.i0) * sh.n[1] + y.i0) * sh.n[2];
  const std::size_t r01 = (std::size_t(x.i0) * sh.n[1] + y.i1) * sh.n[2];
  const std::size_t r10 = (std::size_t(x.i1) * sh.n[1] + y.i0) * sh.n[2];
  const std::size_t r11 = (std::size_t(x.i1) * sh.n[1] + y.i1) * sh.n[2];
  const T c00 = lerp(q[r00 + z.i0], q[r00 + z.i1], z.f);
  const T c01 = lerp(q[r01 + z.i0], q[r01 + z.i1], z.f);
  const T c10 = lerp(q[r10 + z.i0], q[r10 + z.i1], z.f);
  const T c11 = lerp(q[r11 + z.i0], q[r11 + z.i1], z.f);
  return lerp(lerp(c00, c01, y.f), lerp(c10, c11, y.f), x.f);
}

template <class T>
inline void extrema(const T* q, const Shape3& sh, const Stencil& s, T& lo, T& hi) {
  lo = hi = q[sh.index(s.a[0].i0, s.a[1].i0, s.a[2].i0)];
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      for (int e = 0; e < 2; ++e) {
        const T v = q[sh.index(a ? s.a[0].i1 : s.a[0].i0, b ? s.a[1].i1 : s.a[1].i0,
                               e ? s.a[2].i1 : s.a[2].i0)];
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
}

/// Node index along an axis of n nodes: wrapped (periodic) or clamped to [0, n-1].
inline int node(int i, int n, bool periodic) {
  if (periodic) return i < 0 ? i + n : (i >= n ? i - n : i);
  return i < 0 ? 0 : (i >= n ? n - 1 : i);
}

/// Velocity (m/s) at node (i, j, k) of component c: its own value, and for each other component
/// e the mean of the 4 e-nodes around it (= trilinear interpolation at that point: weights 1/2).
template <class T>
inline void face_velocity(const MacGrid<T>& g, int c, int i, int j, int k, double vel[3]) {
  const int ijk[3] = {i, j, k};
  const bool per = g.geo.periodic;
  vel[c] = g.comp[c][g.shape[c].index(i, j, k)];
  for (int e = 0; e < 3; ++e) {
    if (e == c) continue;
    const Shape3& sh = g.shape[e];
    int lo[3], hi[3];
    for (int d = 0; d < 3; ++d) lo[d] = hi[d] = ijk[d];
    lo[c] = ijk[c] - 1;  // along c the e-nodes sit half a cell either side
    hi[e] = ijk[e] + 1;  // along e they sit on the faces either side
    int ic[2] = {node(lo[c], sh.n[c], per), node(ijk[c], sh.n[c], per)};
    int ie[2] = {node(ijk[e], sh.n[e], per), node(hi[e], sh.n[e], per)};
    double s = 0;
    for (int a = 0; a < 2; ++a)
      for (int b = 0; b < 2; ++b) {
        int idx[3] = {ijk[0], ijk[1], ijk[2]};
        idx[c] = ic[a];
        idx[e] = ie[b];
        s += g.comp[e][sh.index(idx[0], idx[1], idx[2])];
      }
    vel[e] = 0.25 * s;
  }
}

/// Runs body(c, i, j, k, index) over every node of every component, in parallel over (i, j).
template <class T, class F>
void for_each_node(const MacGrid<T>& g, F&& body) {
  for (int c = 0; c < 3; ++c) {
    const Shape3 sh = g.shape[c];
    const long rows = long(sh.n[0]) * sh.n[1];
#pragma omp parallel for schedule(static) if (sh.size() > 16384)
    for (long r = 0; r < rows; ++r) {
      const int i = int(r / sh.n[1]), j = int(r % sh.n[1]);
      std::size_t idx = std::size_t(r) * sh.n[2];
      for (int k = 0; k < sh.n[2]; ++k, ++idx) body(c, i, j, k, idx);
    }
  }
}

inline bool upstream_of_inflow(const GridGeometry& geo, const double p[3]) {
  return !geo.periodic && p[0] < 0;
}

}  // namespace

template <class T>
T sample_component(const MacGrid<T>& g, int c, const double p[3]) {
  return interpolate(g.comp[c].data(), g.shape[c], stencil_of(g, c, p));
}

template <class T>
long sample_velocity(const MacGrid<T>& g, const double* points, long m, double* out) {
  const GridGeometry& geo = g.geo;
  const double inv_h = 1.0 / geo.h;
  const double n[3] = {double(geo.nx), double(geo.ny), double(geo.nz)};
  long outside = 0;
#pragma omp parallel for schedule(static) reduction(+ : outside) if (m > 4096)
  for (long r = 0; r < m; ++r) {
    double p[3];
    bool out_of_box = false;
    for (int d = 0; d < 3; ++d) {
      double q = (points[3 * r + d] - geo.origin[d]) * inv_h;
      if (!(q >= 0 && q <= n[d])) {  // NaN counts as outside and lands on the min face
        out_of_box = true;
        q = q > n[d] ? n[d] : 0.0;
      }
      p[d] = q;
    }
    outside += out_of_box;
    for (int c = 0; c < 3; ++c) out[3 * r + c] = double(sample_component(g, c, p));
  }
  return outside;
}

template <class T>
void advect_semi_lagrangian(const MacGrid<T>& u, double dt, const SampleBoundary& bc, MacGrid<T>& out) {
  const double s = dt / u.geo.h;
  for_each_node(u, [&](int c, int i, int j, int k, std::size_t idx) {
    double vel[3];
    face_velocity(u, c, i, j, k, vel);
    const double p[3] = {i + GridGeometry::offset(c, 0) - s * vel[0],
                         j + GridGeometry::offset(c, 1) - s * vel[1],
                         k + GridGeometry::offset(c, 2) - s * vel[2]};
    out.comp[c][idx] = upstream_of_inflow(u.geo, p) ? T(bc.inflow[c]) : sample_component(u, c, p);
  });
}

template <class T>
void advect_maccormack(const MacGrid<T>& u, double dt, const SampleBoundary& bc, MacGrid<T>& hat,
                       MacGrid<T>& out) {
  advect_semi_lagrangian(u, dt, bc, hat);
  const double s = dt / u.geo.h;
  for_each_node(u, [&](int c, int i, int j, int k, std::size_t idx) {
    double vel[3];
    face_velocity(u, c, i, j, k, vel);
    double back[3], fwd[3];
    for (int d = 0; d < 3; ++d) {
      const double x = (d == 0 ? i : d == 1 ? j : k) + GridGeometry::offset(c, d);
      back[d] = x - s * vel[d];
      fwd[d] = x + s * vel[d];
    }
    const T h = hat.comp[c][idx];
    if (upstream_of_inflow(u.geo, back)) {  // inflow value: nothing to correct
      out.comp[c][idx] = h;
      return;
    }
    const T bar = upstream_of_inflow(u.geo, fwd) ? T(bc.inflow[c]) : sample_component(hat, c, fwd);
    const T corrected = T(h + 0.5 * (u.comp[c][idx] - bar));
    T lo, hi;
    extrema(u.comp[c].data(), u.shape[c], stencil_of(u, c, back), lo, hi);
    out.comp[c][idx] = std::min(hi, std::max(lo, corrected));
  });
}

#define FLAGSIM_INSTANTIATE_ADVECT(T)                                                             \
  template T sample_component<T>(const MacGrid<T>&, int, const double[3]);                       \
  template long sample_velocity<T>(const MacGrid<T>&, const double*, long, double*);             \
  template void advect_semi_lagrangian<T>(const MacGrid<T>&, double, const SampleBoundary&,      \
                                          MacGrid<T>&);                                          \
  template void advect_maccormack<T>(const MacGrid<T>&, double, const SampleBoundary&,           \
                                     MacGrid<T>&, MacGrid<T>&);
FLAGSIM_INSTANTIATE_ADVECT(float)
FLAGSIM_INSTANTIATE_ADVECT(double)

}  // namespace flagsim
