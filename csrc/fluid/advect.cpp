#include "fluid/advect.h"
#include "common/parallel.h"
#include "common/simd.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace flagsim {

namespace {

/// floor for |q| < 2^31 without a libm call (std::floor is one unless SSE4.1 is enabled).
inline int ifloor(double q) {
  const int i = int(q);
  return i - (q < i);
}

/// Grid-node pair (i0, i1) and weight f of coordinate q (node units) along an axis of n nodes.
struct Axis {
  int i0, i1;
  double f;
};

inline Axis locate(double q, int n, bool periodic) {
  if (periodic) {
    q = q > -1e9 ? (q < 1e9 ? q : 1e9) : -1e9;  // NaN or absurd departure: stay in range
    int i = ifloor(q);
    const double f = q - i;
    if (unsigned(i) >= unsigned(n)) {
      i %= n;
      if (i < 0) i += n;
    }
    return {i, i + 1 == n ? 0 : i + 1, f};
  }
  if (!(q > 0)) return {0, 0, 0.0};  // also catches NaN
  if (q >= n - 1) return {n - 1, n - 1, 0.0};
  const int i0 = int(q);
  return {i0, i0 + 1, q - i0};
}

template <class T>
inline T lerp(T a, T b, double f) {
  return a + T(f) * (b - a);  // in T: a float grid interpolates in float, without conversions
}

/// Trilinear interpolation of the 8 nodes v of a cell, ordered (x, y, z) = 000, 001, 010, 011,
/// 100, ...: along z, then y, then x. Uses a + f (b - a): a uniform field comes out exactly.
template <class T>
FLAGSIM_INLINE T trilinear(const T v[8], double fx, double fy, double fz) {
  const T c00 = lerp(v[0], v[1], fz), c01 = lerp(v[2], v[3], fz);
  const T c10 = lerp(v[4], v[5], fz), c11 = lerp(v[6], v[7], fz);
  return lerp(lerp(c00, c01, fy), lerp(c10, c11, fy), fx);
}

/// MacCormack's correction (Selle et al. 2008 eq. 9): the predictor hat plus half the error the
/// reverse step bar = A^R(hat) makes on u.
template <class T>
inline T maccormack_correct(T hat, T u, T bar) {
  return T(hat + 0.5 * (u - bar));
}

/// MacCormack's limiter (Selle et al. 2008 §4): value clamped to the extrema of the 8 nodes the
/// backward trace interpolated from.
template <class T>
inline T maccormack_clamp(const T nodes[8], T value) {
  T lo = nodes[0], hi = nodes[0];
  for (int a = 1; a < 8; ++a) {
    lo = std::min(lo, nodes[a]);
    hi = std::max(hi, nodes[a]);
  }
  return std::min(hi, std::max(lo, value));
}

/// A node x (cell units) moved by d = s u, s = dt / h: back = x - d, the semi-Lagrangian departure
/// point (Stam 1999 §2.2), and fwd = x + d, where MacCormack's reverse step samples.
struct Trace {
  double d[3], back[3], fwd[3];
};
FLAGSIM_INLINE Trace trace(const double x[3], double s, const double vel[3]) {
  Trace t;
  for (int a = 0; a < 3; ++a) {
    t.d[a] = s * vel[a];
    t.back[a] = x[a] - t.d[a];
    t.fwd[a] = x[a] + t.d[a];
  }
  return t;
}

/// The advection kernels' loops run on a team from kGridParallelGrain cells.
inline bool on_team(const Shape3& sh) { return Index(sh.size()) > kGridParallelGrain; }

/// row(i, j, base) for every row (i, j) of an array of shape sh, base = index of (i, j, 0), one
/// task per row.
template <class F>
void for_each_row(const Shape3& sh, F&& row) {
  parallel_for_if(on_team(sh), long(sh.n[0]) * sh.n[1], [&](Index r) {
    row(int(r / sh.n[1]), int(r % sh.n[1]), std::size_t(r) * sh.n[2]);
  });
}

/// plane(i) for every plane i of an array of shape sh, one task per plane: for a kernel that is
/// one call per plane (a call per row costs its prologue every 32 nodes).
template <class F>
void for_each_plane(const Shape3& sh, F&& plane) {
  parallel_for_if(on_team(sh), sh.n[0], [&](Index i) { plane(int(i)); });
}

/// Trilinear interpolation of one component array (shape sh, staggering offset off) at a point p
/// in cell units. Uses a + f (b - a) so that a uniform field is reproduced exactly.
template <class T>
struct Interpolator {
  const T* q;  // node (0, 0, 0)
  int n0, n1, n2;
  std::size_t sx, sy;  // strides along x and y
  double o0, o1, o2;
  bool periodic;

  Interpolator(const MacGrid<T>& g, int c)
      : q(g.comp[c].data()),
        n0(g.shape[c].n[0]),
        n1(g.shape[c].n[1]),
        n2(g.shape[c].n[2]),
        sx(std::size_t(n1) * n2),
        sy(std::size_t(n2)),
        o0(GridGeometry::offset(c, 0)),
        o1(GridGeometry::offset(c, 1)),
        o2(GridGeometry::offset(c, 2)),
        periodic(g.geo.periodic) {}
  /// Component c's clamped padded copy (its ghosts are never read: the clamp stays on the nodes).
  Interpolator(const PaddedComponent<T>& p, int c)
      : q(p.data.data() + p.index(0, 0, 0)),
        n0(p.n[0]),
        n1(p.n[1]),
        n2(p.n[2]),
        sx(std::size_t(p.p1) * p.p2),
        sy(std::size_t(p.p2)),
        o0(GridGeometry::offset(c, 0)),
        o1(GridGeometry::offset(c, 1)),
        o2(GridGeometry::offset(c, 2)),
        periodic(false) {}

  struct Corners {
    std::size_t r00, r01, r10, r11;
    int k0, k1;
    double fx, fy, fz;
  };

  FLAGSIM_INLINE Corners corners(double px, double py, double pz) const {
    const Axis x = locate(px - o0, n0, periodic);
    const Axis y = locate(py - o1, n1, periodic);
    const Axis z = locate(pz - o2, n2, periodic);
    return {std::size_t(x.i0) * sx + std::size_t(y.i0) * sy,
            std::size_t(x.i0) * sx + std::size_t(y.i1) * sy,
            std::size_t(x.i1) * sx + std::size_t(y.i0) * sy,
            std::size_t(x.i1) * sx + std::size_t(y.i1) * sy,
            z.i0,
            z.i1,
            x.f,
            y.f,
            z.f};
  }

  /// The 8 nodes of an interpolation, in trilinear's order.
  FLAGSIM_INLINE void nodes(const Corners& c, T v[8]) const {
    const T w[8] = {q[c.r00 + c.k0], q[c.r00 + c.k1], q[c.r01 + c.k0], q[c.r01 + c.k1],
                    q[c.r10 + c.k0], q[c.r10 + c.k1], q[c.r11 + c.k0], q[c.r11 + c.k1]};
    std::copy(w, w + 8, v);
  }
  FLAGSIM_INLINE T operator()(const Corners& c) const {
    T v[8];
    nodes(c, v);
    return trilinear(v, c.fx, c.fy, c.fz);
  }
  FLAGSIM_INLINE T operator()(double px, double py, double pz) const {
    return (*this)(corners(px, py, pz));
  }
};

/// Node index along an axis of n nodes: wrapped (periodic) or clamped to [0, n-1].
inline int node(int i, int n, bool periodic) {
  if (periodic) return i < 0 ? i + n : (i >= n ? i - n : i);
  return i < 0 ? 0 : (i >= n ? n - 1 : i);
}

/// Velocity at the nodes of one row (i, j, k = 0..n2-1) of component c: its own value, and for
/// each other component e the mean of the 4 e-nodes around the node (= trilinear interpolation
/// there: all weights 1/2). Along c the e-nodes sit half a cell either side, along e on the
/// faces either side. Each of the 4 nodes is a row pointer plus a k shift of -1, 0 or +1.
template <class T>
struct RowVelocity {
  const T* own;
  const T* rows[2][4];
  int shift[2][4];
  int comp[2];
  int n2e[2];
  bool periodic;

  RowVelocity(const MacGrid<T>& g, int c, int i, int j) {
    periodic = g.geo.periodic;
    own = g.comp[c].data() + g.shape[c].index(i, j, 0);
    int slot = 0;
    for (int e = 0; e < 3; ++e) {
      if (e == c) continue;
      const Shape3& sh = g.shape[e];
      comp[slot] = e;
      n2e[slot] = sh.n[2];
      int q = 0;
      for (int a = 0; a < 2; ++a)      // along c: ijk[c] - 1 + a
        for (int b = 0; b < 2; ++b) {  // along e: ijk[e] + b
          int idx[3] = {i, j, 0};
          int dk = 0;
          if (c == 2)
            dk += a - 1;
          else
            idx[c] = node(idx[c] - 1 + a, sh.n[c], periodic);
          if (e == 2)
            dk += b;
          else
            idx[e] = node(idx[e] + b, sh.n[e], periodic);
          rows[slot][q] = g.comp[e].data() + sh.index(idx[0], idx[1], 0);
          shift[slot][q] = dk;
          ++q;
        }
      ++slot;
    }
  }

  /// Range [1, k_end) of k where every k + shift lies inside the e-rows (no wrap or clamp).
  int interior_end() const { return std::min(n2e[0], n2e[1]) - 1; }

  inline void at(int k, double vel[3]) const {
    for (int s = 0; s < 2; ++s) {
      const int n = n2e[s];
      T sum = 0;  // in T: no conversions on a float grid
      for (int q = 0; q < 4; ++q) {
        const int kk = node(k + shift[s][q], n, periodic);
        sum += rows[s][q][kk];
      }
      vel[comp[s]] = double(T(0.25) * sum);
    }
  }
  inline void at_interior(int k, double vel[3]) const {
    for (int s = 0; s < 2; ++s) {
      T sum = 0;  // in T: no conversions on a float grid
      for (int q = 0; q < 4; ++q) sum += rows[s][q][k + shift[s][q]];
      vel[comp[s]] = double(T(0.25) * sum);
    }
  }
  inline void velocity(int k, int k_end, double vel[3]) const {
    if (k >= 1 && k < k_end)
      at_interior(k, vel);
    else
      at(k, vel);
  }
};

/// Semi-Lagrangian value of node k of a row (Stam 1999 §2.2): the field at the departure point, or
/// the inflow upstream of a tunnel's inflow face.
template <class Row>
FLAGSIM_INLINE auto semi_lagrangian(const Row& w, const Trace& t, int k) {
  return w.upstream(t.back) ? w.inflow_at(t.back) : w.sample(t, k);
}

/// MacCormack value of node k of a row from its predictor hat (Selle et al. 2008 eq. 9, §4).
template <class Row, class T>
FLAGSIM_INLINE T maccormack(const Row& w, const Trace& t, int k, T hat) {
  if (w.upstream(t.back)) return hat;  // inflow value: nothing to correct
  const T bar = w.upstream(t.fwd) ? w.inflow_at(t.fwd) : w.sample_hat(t, k);
  T v[8];
  w.nodes(t, k, v);
  return maccormack_clamp(v, maccormack_correct(hat, w.own(k), bar));
}

/// The kernels' view of one row (i, j) of component c of a bounded or periodic grid (generic
/// indexing: wrap or clamp at every sample), of u and of the MacCormack predictor hat.
template <class T>
struct GenericRow {
  Interpolator<T> q, qhat;
  RowVelocity<T> rv;
  int c, k_end;
  double x0, y0;
  T inflow;
  InflowShape shape;
  bool tunnel;
  GenericRow(const MacGrid<T>& u, const MacGrid<T>& hat, int c, int i, int j,
             const SampleBoundary& bc)
      : q(u, c),
        qhat(hat, c),
        rv(u, c, i, j),
        c(c),
        k_end(rv.interior_end()),
        x0(i + q.o0),
        y0(j + q.o1),
        inflow(T(bc.inflow[c])),
        shape(bc.shape),
        tunnel(!u.geo.periodic) {}
  T inflow_at(const double p[3]) const { return T(double(inflow) * shape.at(p)); }
  void node(int k, double x[3]) const {
    x[0] = x0;
    x[1] = y0;
    x[2] = k + q.o2;
  }
  FLAGSIM_INLINE void velocity(int k, double vel[3]) const {
    vel[c] = rv.own[k];
    rv.velocity(k, k_end, vel);
  }
  T own(int k) const { return rv.own[k]; }
  bool upstream(const double p[3]) const { return tunnel && p[0] < 0; }
  FLAGSIM_INLINE T sample(const Trace& t, int) const { return q(t.back[0], t.back[1], t.back[2]); }
  FLAGSIM_INLINE T sample_hat(const Trace& t, int) const {
    return qhat(t.fwd[0], t.fwd[1], t.fwd[2]);
  }
  FLAGSIM_INLINE void nodes(const Trace& t, int, T v[8]) const {
    q.nodes(q.corners(t.back[0], t.back[1], t.back[2]), v);
  }
};

/// dst[k] = the semi-Lagrangian value of node k, k in [0, n).
template <class Row, class T>
void semi_lagrangian_row(const Row& w, double s, int n, T* dst) {
  for (int k = 0; k < n; ++k) {
    double x[3], vel[3];
    w.node(k, x);
    w.velocity(k, vel);
    dst[k] = semi_lagrangian(w, trace(x, s, vel), k);
  }
}

/// dst[k] = the MacCormack value of node k from hat[k], k in [0, n).
template <class Row, class T>
void maccormack_row(const Row& w, double s, int n, const T* hat, T* dst) {
  for (int k = 0; k < n; ++k) {
    double x[3], vel[3];
    w.node(k, x);
    w.velocity(k, vel);
    dst[k] = maccormack(w, trace(x, s, vel), k, hat[k]);
  }
}

}  // namespace

template <class T>
T sample_component(const MacGrid<T>& g, int c, const double p[3]) {
  return Interpolator<T>(g, c)(p[0], p[1], p[2]);
}

// Point r of points in cell units, moved to the nearest point of the domain box when outside
// (NaN lands on the min face); true when it was outside.
inline bool cell_coordinates(const GridGeometry& geo, double inv_h, const double* point,
                             double p[3]) {
  const double n[3] = {double(geo.nx), double(geo.ny), double(geo.nz)};
  bool out_of_box = false;
  for (int d = 0; d < 3; ++d) {
    double q = (point[d] - geo.origin[d]) * inv_h;
    if (!(q >= 0 && q <= n[d])) {  // NaN counts as outside and lands on the min face
      out_of_box = true;
      q = q > n[d] ? n[d] : 0.0;
    }
    p[d] = q;
  }
  return out_of_box;
}

template <class T>
long sample_velocity(const MacGrid<T>& g, const double* points, long m, double* out) {
  const double inv_h = 1.0 / g.geo.h;
  const Interpolator<T> iu(g, 0), iv(g, 1), iw(g, 2);
  auto one = [&](long r) -> long {
    double p[3];
    const bool out_of_box = cell_coordinates(g.geo, inv_h, points + 3 * r, p);
    out[3 * r + 0] = double(iu(p[0], p[1], p[2]));
    out[3 * r + 1] = double(iv(p[0], p[1], p[2]));
    out[3 * r + 2] = double(iw(p[0], p[1], p[2]));
    return out_of_box;
  };
  long outside = 0;
  // No `if` clause: libgomp allocates one-thread teams (see use_team).
  if (use_team(m > kParallelGrain)) {
#pragma omp parallel for schedule(static) reduction(+ : outside)
    for (long r = 0; r < m; ++r) outside += one(r);
  } else {
    for (long r = 0; r < m; ++r) outside += one(r);
  }
  return outside;
}

// The 8 nodes of trilinear's order (000, 001, 010, ...: x, y, z bits) get
// (1 - fx or fx) (1 - fy or fy) (1 - fz or fz) of the value: the weights of sample's lerps.
template <class T>
void spread_velocity(const double* points, long m, const double* values, double scale,
                     MacGrid<T>& g) {
  const double inv_h = 1.0 / g.geo.h;
  const Interpolator<T> at[3] = {Interpolator<T>(g, 0), Interpolator<T>(g, 1),
                                 Interpolator<T>(g, 2)};
  for (long r = 0; r < m; ++r) {
    double p[3];
    cell_coordinates(g.geo, inv_h, points + 3 * r, p);
    for (int c = 0; c < 3; ++c) {
      const auto k = at[c].corners(p[0], p[1], p[2]);
      const double v = scale * values[3 * r + c];
      const double wx[2] = {1.0 - k.fx, k.fx}, wy[2] = {1.0 - k.fy, k.fy},
                   wz[2] = {1.0 - k.fz, k.fz};
      const std::size_t row[2][2] = {{k.r00, k.r01}, {k.r10, k.r11}};
      const int kz[2] = {k.k0, k.k1};
      T* q = g.comp[c].data();
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b)
          for (int e = 0; e < 2; ++e) q[row[a][b] + kz[e]] += T(v * (wx[a] * wy[b] * wz[e]));
    }
  }
}

template <class T>
void advect_semi_lagrangian(const MacGrid<T>& u, double dt, const SampleBoundary& bc,
                            MacGrid<T>& out) {
  const double s = dt / u.geo.h;
  for (int c = 0; c < 3; ++c)
    for_each_row(u.shape[c], [&](int i, int j, std::size_t base) {
      semi_lagrangian_row(GenericRow<T>(u, u, c, i, j, bc), s, u.shape[c].n[2],
                          out.comp[c].data() + base);
    });
}

template <class T>
void advect_maccormack(const MacGrid<T>& u, double dt, const SampleBoundary& bc, MacGrid<T>& hat,
                       MacGrid<T>& out) {
  advect_semi_lagrangian(u, dt, bc, hat);
  const double s = dt / u.geo.h;
  for (int c = 0; c < 3; ++c)
    for_each_row(u.shape[c], [&](int i, int j, std::size_t base) {
      maccormack_row(GenericRow<T>(u, hat, c, i, j, bc), s, u.shape[c].n[2],
                     hat.comp[c].data() + base, out.comp[c].data() + base);
    });
}

// ---- periodic fast path on ghost-padded copies -------------------------------------------------

template <class T>
void PaddedComponent<T>::resize(const Shape3& s) {
  resize_clamped(s, s.n);
  clamped = false;
}

template <class T>
void PaddedComponent<T>::resize_clamped(const Shape3& s, const int m[3]) {
  for (int d = 0; d < 3; ++d) n[d] = s.n[d];
  clamped = true;
  p1 = m[1] + 2 * kGhost;
  p2 = m[2] + 2 * kGhost;
  data.assign(std::size_t(m[0] + 2 * kGhost) * p1 * p2, T(0));
}

#ifdef FLAGSIM_HAVE_VECTORS
namespace {

/// n values from s to d by vectors of S, the last one overlapping (n >= the lanes of S).
template <class S, class T>
FLAGSIM_INLINE void copy_by_vectors(const T* s, std::size_t n, T* d) {
  constexpr std::size_t W = sizeof(S) / sizeof(T);
  std::size_t k = 0;
  for (; k + W <= n; k += W) store_lanes<S>(d + k, load_lanes<S, T>(s + k));
  if (k < n) store_lanes<S>(d + n - W, load_lanes<S, T>(s + n - W));
}

// One padded plane of PaddedComponent::fill: rows b in [0, n1) of plane s_plane (n1 x n2, C
// order, n1 >= G, n2 >= G) into d (the padded plane's row -G), p2 = n2 + 2 G apart, each row's
// interior by vectors of S, its ghosts by scalars; then the ghost rows, which wrap along j, as
// two blocks of G padded rows copied from the plane's own rows n1 - G.. and 0... Written out
// because GCC turns a copy loop, however written, into a memmove call per row (at 16^3, with the
// call's set-up, ~50 instructions for 16 values); the pragma keeps these loops as loops. It must
// be on the function they are compiled in: hence two functions here, not on_widest_lanes.
template <class S, class T>
FLAGSIM_INLINE void fill_plane_rows(const T* s_plane, int n1, int n2, int p2, T* d) {
  constexpr int G = PaddedComponent<T>::kGhost;
  constexpr int W = int(sizeof(S) / sizeof(T));
  T* const top = d;
  d += std::size_t(G) * p2;
  for (int b = 0; b < n1; ++b, d += p2) {
    const T* s = s_plane + std::size_t(b) * n2;
    if (W > G && b > 0 && b + 1 < n1) {
      // The ghosts by one vector each side, their other lanes landing on interior nodes that the
      // copy below overwrites: the right ones from s - (W - G) (the row before's last values),
      // the left ones from s + n2 - G (into the next row's first): inside the plane.
      store_lanes<S>(d + n2 + 2 * G - W, load_lanes<S, T>(s + G - W));
      store_lanes<S>(d, load_lanes<S, T>(s + n2 - G));
    } else {
      for (int g = 0; g < G; ++g) {
        d[g] = s[n2 - G + g];
        d[G + n2 + g] = s[g];
      }
    }
    copy_by_vectors<S>(s, std::size_t(n2), d + G);
  }
  const std::size_t block = std::size_t(G) * p2;
  copy_by_vectors<S>(top + std::size_t(n1) * p2, block, top);              // rows -G.. <- n1 - G..
  copy_by_vectors<S>(top + block, block, top + std::size_t(n1 + G) * p2);  // rows n1.. <- 0..
}

#pragma GCC push_options
#pragma GCC optimize("no-tree-loop-distribute-patterns")
template <class T>
void fill_plane_narrow(const T* s_plane, int n1, int n2, int p2, T* d) {
  fill_plane_rows<typename Lanes16<T>::V>(s_plane, n1, n2, p2, d);
}
#ifdef FLAGSIM_HAVE_AVX_DISPATCH
template <class T>
FLAGSIM_TARGET_AVX void fill_plane_wide(const T* s_plane, int n1, int n2, int p2, T* d) {
  fill_plane_rows<typename Lanes32<T>::V>(s_plane, n1, n2, p2, d);
}
#endif
#pragma GCC pop_options

}  // namespace
#endif

template <class T>
void PaddedComponent<T>::fill(const T* src) {
  constexpr int G = kGhost;
  const int n0 = n[0], n1 = n[1], n2 = n[2];
  const bool parallel = Index(data.size()) > kCopyParallelGrain;
  if (clamped) {
    // Every padded row (i, j) is source row (clamp i, clamp j): its nodes, then its last node
    // repeated to the padded end, after G copies of its first node.
    const int m0 = int(data.size() / (std::size_t(p1) * p2)) - 2 * G;
    const int tail = p2 - G - n2;
    parallel_for_if(parallel, m0 + 2 * G, [&](Index plane) {
      const int a = std::min(std::max(int(plane) - G, 0), n0 - 1);
      T* d = data.data() + std::size_t(plane) * p1 * p2;
      for (int b = -G; b < p1 - G; ++b, d += p2) {
        const T* s =
            src + (std::size_t(a) * n1 + std::size_t(std::min(std::max(b, 0), n1 - 1))) * n2;
        std::fill(d, d + G, s[0]);
        std::copy(s, s + n2, d + G);
        std::fill(d + G + n2, d + G + n2 + tail, s[n2 - 1]);
      }
    });
    return;
  }
  // i in [-G, n + G): one conditional add or subtract when n >= G, a modulo otherwise.
  auto wrap = [](int i, int n) {
    return n >= G ? (i < 0 ? i + n : i >= n ? i - n : i) : ((i % n) + n) % n;
  };
#ifdef FLAGSIM_HAVE_VECTORS
  // Rows of at least a vector, on planes of at least G rows, go through the vector copy.
  const int vb = vector_bytes();
  const bool rows_by_vectors = n1 >= G && n2 >= G && n2 * int(sizeof(T)) >= (vb == 32 ? 32 : 16);
#endif
#ifdef FLAGSIM_HAVE_VECTORS
  if (rows_by_vectors && n0 >= G) {
    // The n0 planes from src, then the ghost planes (which wrap along i) as copies of padded
    // planes: one contiguous block each.
    parallel_for_if(parallel, n0, [&](Index a) {
      const T* s_plane = src + std::size_t(a) * n1 * n2;
      T* d = data.data() + index(int(a), -G, -G);
#ifdef FLAGSIM_HAVE_AVX_DISPATCH
      if (vb == 32) return fill_plane_wide(s_plane, n1, n2, p2, d);
#endif
      fill_plane_narrow(s_plane, n1, n2, p2, d);
    });
    const std::size_t plane_size = std::size_t(p1) * p2;
    parallel_for_if(parallel, 2 * G, [&](Index g) {
      const int a = g < G ? int(g) - G : n0 + int(g) - G;  // -G.. -1, n0.. n0 + G - 1
      const T* s = data.data() + index(a < 0 ? a + n0 : a - n0, -G, -G);
      std::copy(s, s + plane_size, data.data() + index(a, -G, -G));
    });
    return;
  }
#endif
  parallel_for_if(parallel, n0 + 2 * G, [&](Index plane) {
    const int a = int(plane) - G;
    const T* s_plane = src + std::size_t(wrap(a, n0)) * n1 * n2;
    T* d = data.data() + index(a, -G, -G);
    for (int b = -G; b < n1 + G; ++b, d += p2) {
      const T* s = s_plane + std::size_t(wrap(b, n1)) * n2;
      if (n2 >= G) {
        for (int g = 0; g < G; ++g) {  // the ghosts inline: a memmove call of G values costs more
          d[g] = s[n2 - G + g];
          d[G + n2 + g] = s[g];
        }
        std::copy(s, s + n2, d + G);
      } else {
        for (int k = -G; k < n2 + G; ++k) d[k + G] = s[wrap(k, n2)];
      }
    }
  });
}

template <class T>
void PaddedComponent<T>::unpad(T* dst) const {
  for (int i = 0; i < n[0]; ++i)
    for (int j = 0; j < n[1]; ++j) {
      const T* s = data.data() + index(i, j, 0);
      std::copy(s, s + n[2], dst + (std::size_t(i) * n[1] + std::size_t(j)) * n[2]);
    }
}

template <class T>
void AdvectScratch<T>::resize(const GridGeometry& g, bool maccormack) {
  const int m[3] = {g.nx + 1, g.ny + 1, g.nz + 1};  // every component's nodes fit
  auto size = [&](PaddedComponent<T>& p, int c) {
    if (g.periodic)
      p.resize(g.face_shape(c));
    else
      p.resize_clamped(g.face_shape(c), m);
  };
  for (int c = 0; c < 3; ++c) {
    size(u[c], c);
    if (maccormack)
      size(hat[c], c);
    else
      hat[c] = PaddedComponent<T>();
  }
}

namespace {

/// Node pair of coordinate q along a padded periodic axis of n nodes: the lower node index in
/// [-G, n + G - 2] (wrapped into [0, n) when the departure is further than the ghosts reach).
struct PaddedAxis {
  int i0;
  double f;
};
template <int G>
inline PaddedAxis locate_padded(double q, int n) {
  q = q > -1e9 ? (q < 1e9 ? q : 1e9) : -1e9;  // NaN or absurd departure: stay in range
  int i = ifloor(q);
  const double f = q - i;
  if (i < -G || i > n + G - 2) {
    i %= n;
    if (i < 0) i += n;
  }
  return {i, f};
}

/// Trilinear sampling of a padded component at g (node units); the same arithmetic (and so the
/// same bits) as Interpolator on the unpadded array.
template <class T>
struct PaddedSampler {
  const T* q;
  int n0, n1, n2;
  std::size_t sx, sy;
  explicit PaddedSampler(const PaddedComponent<T>& p)
      : q(p.data.data()),
        n0(p.n[0]),
        n1(p.n[1]),
        n2(p.n[2]),
        sx(std::size_t(p.p1) * p.p2),
        sy(std::size_t(p.p2)) {}

  struct Corner {
    std::size_t base;
    double fx, fy, fz;
  };
  inline Corner corner(const PaddedComponent<T>& p, double g0, double g1, double g2) const {
    constexpr int G = PaddedComponent<T>::kGhost;
    const PaddedAxis x = locate_padded<G>(g0, n0), y = locate_padded<G>(g1, n1),
                     z = locate_padded<G>(g2, n2);
    return {p.index(x.i0, y.i0, z.i0), x.f, y.f, z.f};
  }
  /// corner() for a departure within one cell of node (i, j, k) on every axis (|d| <= 1, so the
  /// lower node is in [i - 2, i + 1], inside the ghosts): no clamping, no range checks.
  inline Corner near_corner(std::size_t node, int i, int j, int k, double g0, double g1,
                            double g2) const {
    const int x = ifloor(g0), y = ifloor(g1), z = ifloor(g2);
    return {node + std::ptrdiff_t(x - i) * std::ptrdiff_t(sx) +
                std::ptrdiff_t(y - j) * std::ptrdiff_t(sy) + (z - k),
            g0 - x, g1 - y, g2 - z};
  }
  inline Corner any_corner(const PaddedComponent<T>& p, std::size_t node, int i, int j, int k,
                           double d0, double d1, double d2, double g0, double g1, double g2) const {
    if (std::fabs(d0) <= 1 && std::fabs(d1) <= 1 && std::fabs(d2) <= 1)  // false for NaN
      return near_corner(node, i, j, k, g0, g1, g2);
    return corner(p, g0, g1, g2);
  }
  /// The 8 nodes of an interpolation, in trilinear's order.
  inline void nodes(const Corner& c, T v[8]) const {
    const T* b = q + c.base;
    const T w[8] = {b[0], b[1], b[sy], b[sy + 1], b[sx], b[sx + 1], b[sx + sy], b[sx + sy + 1]};
    std::copy(w, w + 8, v);
  }
  inline T value(const Corner& c) const {
    T v[8];
    nodes(c, v);
    return trilinear(v, c.fx, c.fy, c.fz);
  }
};

/// Velocity at node (i, j, k) of component C from padded u^n (see RowVelocity: same sums, same
/// order). idx: the node's padded index (identical for all components of a periodic grid).
template <int C, class T>
inline void padded_velocity(const std::array<PaddedComponent<T>, 3>& u, std::size_t idx,
                            const std::ptrdiff_t stride[3], double vel[3]) {
  vel[C] = u[C].data[idx];
  for (int e = 0; e < 3; ++e) {
    if (e == C) continue;
    const T* q = u[e].data.data() + idx;
    const std::ptrdiff_t dc = stride[C], de = stride[e];
    T sum = 0;  // in T, as RowVelocity
    sum += q[-dc];
    sum += q[de - dc];
    sum += q[0];
    sum += q[de];
    vel[e] = double(T(0.25) * sum);
  }
}

/// A vector of Bytes bytes of the unsigned integer B.
template <class B, std::size_t Bytes>
struct BitsOf {
  typedef B U __attribute__((vector_size(Bytes)));
};

/// |x| per lane (the sign bit cleared: one and, where a select from x and -x takes four), for T
/// or a vector of T.
template <class S>
FLAGSIM_INLINE S abs_lanes(S x) {
  if constexpr (std::is_floating_point<S>::value) {
    return std::fabs(x);
  } else {
    using E = std::remove_reference_t<decltype(x[0])>;
    using B = std::conditional_t<sizeof(E) == 8, std::uint64_t, std::uint32_t>;
    typename BitsOf<B, sizeof(S)>::U bits;
    std::memcpy(&bits, &x, sizeof x);
    bits &= ~(B(1) << (8 * sizeof(E) - 1));
    std::memcpy(&x, &bits, sizeof x);
    return x;
  }
}

/// Semi-Lagrangian sample at node k of one row when the departure is within one cell of the node
/// on every axis (|d| < 1): the departure point lies in the cell on the upwind side of the node,
/// so each axis interpolates between the node and its upwind neighbour, node + |d| (upwind - node),
/// the upwind neighbour being the lower one where d > 0 and the upper one where d < 0. Loads are
/// contiguous along k and the neighbour is picked per lane by a select, so the interpolation
/// touches only the 4 rows of the upwind cell: z, then y, then x (Interpolator's order; the same
/// to round-off, measured from the node rather than from the lower corner). S is T (scalar) or a
/// vector of T (one node per lane); rows[3 (a + 1) + (b + 1)] is the padded row at x offset a,
/// y offset b (a, b in -1..1) from the node's row. A uniform field comes out exactly.
template <class S, class T>
FLAGSIM_INLINE S upwind_sample(const T* const rows[9], int k, S d0, S d1, S d2) {
  const S zero = S{};                                            // 0 in every lane
  const auto lo0 = d0 > zero, lo1 = d1 > zero, lo2 = d2 > zero;  // upwind is the lower neighbour
  // |d| (+0 for either zero; NaN for NaN, a lane the caller redoes: padded_sl)
  const S w0 = abs_lanes(d0), w1 = abs_lanes(d1), w2 = abs_lanes(d2);
  // Row r at the node (mid) and at its upwind neighbour along z (up).
  auto at = [&](const T* row, S& mid, S& up) {
    row += k;
    mid = load_lanes<S>(row);
    const S below = load_lanes<S>(row - 1), above = load_lanes<S>(row + 1);
    up = lo2 ? below : above;
  };
  auto pick = [](auto mask, S a, S b) { return mask ? a : b; };
  S m00, u00, m0b, u0b, ma0, ua0, mab, uab;  // rows (0, 0), (0, y up), (x up, 0), (x up, y up)
  at(rows[4], m00, u00);
  {
    S ml, ul, mh, uh;
    at(rows[3], ml, ul);
    at(rows[5], mh, uh);
    m0b = pick(lo1, ml, mh);
    u0b = pick(lo1, ul, uh);
    at(rows[1], ml, ul);
    at(rows[7], mh, uh);
    ma0 = pick(lo0, ml, mh);
    ua0 = pick(lo0, ul, uh);
  }
  {
    S m_ll, u_ll, m_lh, u_lh, m_hl, u_hl, m_hh,
        u_hh;  // (x, y) = (-1, -1), (-1, 1), (1, -1), (1, 1)
    at(rows[0], m_ll, u_ll);
    at(rows[2], m_lh, u_lh);
    at(rows[6], m_hl, u_hl);
    at(rows[8], m_hh, u_hh);
    const S ml = pick(lo1, m_ll, m_lh), ul = pick(lo1, u_ll, u_lh);
    const S mh = pick(lo1, m_hl, m_hh), uh = pick(lo1, u_hl, u_hh);
    mab = pick(lo0, ml, mh);
    uab = pick(lo0, ul, uh);
  }
  const S c00 = m00 + w2 * (u00 - m00), c0b = m0b + w2 * (u0b - m0b);
  const S ca0 = ma0 + w2 * (ua0 - ma0), cab = mab + w2 * (uab - mab);
  const S y0 = c00 + w1 * (c0b - c00), ya = ca0 + w1 * (cab - ca0);
  return y0 + w0 * (ya - y0);
}

/// One row (i, j) of padded_sl's fast path, node by node from k = 0: what the row needs.
template <class T>
struct SlRow {
  const T *own, *e1, *e2;  // the row's start in the padded component and in the other two
  const T* rows9[9];       // see upwind_sample
  std::ptrdiff_t dc, d1s, d2s, sx, sy;
  T st;      // dt / h
  double s;  // dt / h in double (the general sampler's trace)
  T beta;    // nu dt / h^2 (explicit diffusion of u^n; read only when the kernel diffuses)
  T* dst;
  int i, j;       // the row's node indices along x and y
  double x0, x1;  // the row's nodes along x and y in cell units: i + offset, j + offset
};

/// beta times the 7-point Laplacian (h^2 units) of a padded component at node k of a row, given
/// as the row and its four neighbours across y and x (rows[3 (a + 1) + (b + 1)]: x offset a, y
/// offset b, as upwind_sample's, so the fast path loads each value once for both): the explicit
/// viscous term nu dt lap u^n (add_viscous_term). Summed as differences from the node, z, y, x
/// pairs, so a uniform field gives exactly 0. S is T or a vector of T: the same operations per
/// lane, the same bits.
template <class S, class T>
FLAGSIM_INLINE S viscous_term(const T* const rows[9], int k, T beta) {
  const T* p = rows[4] + k;
  const S c = load_lanes<S>(p);
  const S z = (load_lanes<S>(p - 1) - c) + (load_lanes<S>(p + 1) - c);
  const S y = (load_lanes<S>(rows[3] + k) - c) + (load_lanes<S>(rows[5] + k) - c);
  const S x = (load_lanes<S>(rows[1] + k) - c) + (load_lanes<S>(rows[7] + k) - c);
  return beta * ((z + y) + x);
}

/// viscous_term of the row that starts at own, sx and sy the component's x and y strides.
template <class S, class T>
FLAGSIM_INLINE S viscous_term(const T* own, std::ptrdiff_t sx, std::ptrdiff_t sy, int k, T beta) {
  const T* const rows[9] = {nullptr,  own - sx, nullptr,  own - sy, own,
                            own + sy, nullptr,  own + sx, nullptr};
  return viscous_term<S>(rows, k, beta);
}

/// The velocity at node k (own value, 4-node means of the other components, as
/// padded_velocity), per axis, for component C: m/s.
template <int C, class S, class T>
FLAGSIM_INLINE void node_velocity(const SlRow<T>& w, int k, S& u0, S& u1, S& u2) {
  const S vc = load_lanes<S>(w.rows9[4] + k);  // w.own + k
  const S v1 =
      T(0.25) * (((load_lanes<S>(w.e1 + k - w.dc) + load_lanes<S>(w.e1 + k + w.d1s - w.dc)) +
                  load_lanes<S>(w.e1 + k)) +
                 load_lanes<S>(w.e1 + k + w.d1s));
  const S v2 =
      T(0.25) * (((load_lanes<S>(w.e2 + k - w.dc) + load_lanes<S>(w.e2 + k + w.d2s - w.dc)) +
                  load_lanes<S>(w.e2 + k)) +
                 load_lanes<S>(w.e2 + k + w.d2s));
  u0 = C == 0 ? vc : v1;
  u1 = C == 1 ? vc : C == 0 ? v1 : v2;
  u2 = C == 2 ? vc : v2;
}

/// The departure displacement (cells) of node k in T: node_velocity times dt / h.
template <int C, class S, class T>
FLAGSIM_INLINE void departure(const SlRow<T>& w, int k, S& d0, S& d1, S& d2) {
  node_velocity<C>(w, k, d0, d1, d2);
  d0 = w.st * d0;
  d1 = w.st * d1;
  d2 = w.st * d2;
}

#ifdef FLAGSIM_HAVE_VECTORS
/// Whether every lane of a vector compare's result (0 or all ones per lane) is set: the lanes read
/// as 64-bit words and folded, not extracted one by one.
template <class M>
FLAGSIM_INLINE bool all_lanes(const M& m) {
  static_assert(sizeof(M) % 8 == 0, "masks of 8 bytes or more");
  std::uint64_t w[sizeof(M) / 8];
  std::memcpy(w, &m, sizeof(M));
  std::uint64_t a = ~std::uint64_t(0);
  for (const std::uint64_t x : w) a &= x;
  return a == ~std::uint64_t(0);
}

/// Whether every lane, and whether any lane, of a vector compare's result (0 or all ones per
/// lane) is set. In the AVX code one vmovmskpd / vmovmskps reads the lanes' sign bits (GCC
/// extracts and ORs the lanes one by one).
template <class M>
FLAGSIM_INLINE void all_any_lanes(const M& m, bool& all, bool& any) {
  constexpr int kLanes = int(sizeof(m) / sizeof(m[0]));
#ifdef FLAGSIM_HAVE_AVX_DISPATCH
  if constexpr (sizeof(M) == 32) {
    int bits;
    if constexpr (kLanes == 4)
      __asm__("vmovmskpd %1, %0" : "=r"(bits) : "x"(m));
    else
      __asm__("vmovmskps %1, %0" : "=r"(bits) : "x"(m));
    all = bits == (1 << kLanes) - 1;
    any = bits != 0;
    return;
  }
#endif
  all = true;
  any = false;
  for (int lane = 0; lane < kLanes; ++lane) {
    all = all && m[lane];
    any = any || m[lane];
  }
}

/// Lanes of T, as many as given: the lower nodes' indices (int) and the departure points
/// (double) in far_sample. double <-> int32 conversions are one instruction each (cvttpd2dq,
/// cvtdq2pd), int64 ones are not before AVX-512.
template <class T, int Lanes>
struct LanesOf {
  typedef T V __attribute__((vector_size(sizeof(T) * Lanes)));
};

/// The general sampler's value (PaddedRow::sample: departure x - (dt / h) u in double, lower node
/// by floor, weights from it, trilinear along z, y, x in T) for the W nodes k.. of a row whose
/// departures lie within the ghosts (|d| < G on every axis), u0..u2 the nodes' velocities
/// (node_velocity): the same operations lane by lane, so the same bits, without wrapping or range
/// checks and on vectors. The departure points are computed in parts of as many doubles as V has
/// bytes for (a float vector: two parts): GCC lowers a compare of doubles wider than the machine's
/// vectors lane by lane (vcomisd, seta: a float grid's far path ran 1.5x the double's per node).
/// Where the lanes' lower nodes share one offset from their node on each axis (~78 % of such
/// vectors of 4 lanes at 128^3, ~55 % of 8) the 8 nodes are 8 contiguous vector loads, else they
/// are loaded lane by lane (loading both candidates and selecting per lane measured no faster).
/// far_cell: that sampling's cell, the 8 nodes v (trilinear's order) of each lane's cell in the
/// padded component whose node (i, j, 0) is at row (the strides of w's), and the weights wt (in
/// T), at the departure x - d or, Fwd, at x + d (MacCormack's reverse step: trace's fwd). A
/// clamped component's ghosts repeat its nearest node, so there the cell holds the generic
/// kernels' clamped nodes. Returns false, v and wt untouched, when a departure is a ghost layer's
/// reach or more (or not finite).
template <int C, bool Fwd, class V, class T>
FLAGSIM_INLINE bool far_cell(const SlRow<T>& w, const T* row, int k, const V& u0, const V& u1,
                             const V& u2, V v[8], V wt[3]) {
  constexpr int G = PaddedComponent<T>::kGhost;
  constexpr int W = int(sizeof(V) / sizeof(T));
  constexpr int DW = int(sizeof(V) / sizeof(double));  // lanes of a part
  constexpr int H = W / DW;                            // parts: 1 (double) or 2 (float)
  using D = typename LanesOf<double, DW>::V;
  using I = typename LanesOf<int, DW>::V;
  using P = typename LanesOf<T, DW>::V;  // a part of V
  constexpr double kO0 = C == 0 ? 0.0 : 0.5, kO1 = C == 1 ? 0.0 : 0.5, kO2 = C == 2 ? 0.0 : 0.5;
  // Part h of s u in double: trace()'s departure. A double grid's st is s, so there it is the
  // caller's st u (the same bits, computed once).
  auto part = [&w](const V& x, int h) FLAGSIM_INLINE_LAMBDA {
    if constexpr (std::is_same<T, double>::value) return D(w.st * x);
    P y;
    std::memcpy(&y, reinterpret_cast<const char*>(&x) + h * sizeof(P), sizeof(P));
#ifdef FLAGSIM_HAVE_AVX_DISPATCH
    if constexpr (sizeof(D) == 32) {  // AVX code: one vcvtps2pd (GCC splits it into 3)
      D yd;
      __asm__("vcvtps2pd %1, %0" : "=x"(yd) : "x"(y));
      return D(w.s * yd);
    }
#endif
    return D(w.s * __builtin_convertvector(y, D));
  };
  auto floor_of = [](D g, D& f) FLAGSIM_INLINE_LAMBDA {
    D fl;
#ifdef FLAGSIM_HAVE_AVX_DISPATCH
    if constexpr (sizeof(D) == 32) {
      // AVX code: vroundpd toward -inf, one instruction for the eight below (GCC splits the
      // int32 -> double conversion of 4 lanes into 4); the same value (g is never -0 here).
      // (inline asm: GCC declares the builtin only in code parsed for AVX, and this lambda
      // becomes AVX code by inlining)
      __asm__("vroundpd $9, %1, %0" : "=x"(fl) : "x"(g));  // floor, no precision exception
    } else
#endif
    {
      const D t = __builtin_convertvector(__builtin_convertvector(g, I), D);  // toward zero
      D one = D{};
      one += 1.0;
      fl = t - (g < t ? one : D{});  // floor, exactly (|g| < 2^31 here)
    }
    f = g - fl;
    return __builtin_convertvector(fl, I);
  };
  D f[3][H];
  I o[3][H];  // lower node's offset from the lane's node, per axis and part
  D iota;
  for (int l = 0; l < DW; ++l) iota[l] = double(l);
  D reach = D{};
  reach += double(G);
  for (int h = 0; h < H; ++h) {
    const D d0 = part(u0, h), d1 = part(u1, h), d2 = part(u2, h);
    const auto ok = (abs_lanes(d0) < reach) & (abs_lanes(d1) < reach) &
                    (abs_lanes(d2) < reach);  // false for NaN
    if (!all_lanes(ok)) return false;
    const D lane = iota + double(k + h * DW);  // the lanes' k, exactly
    // back = x - d (fwd = x + d), g = back - offset (node units), as trace() and
    // PaddedRow::corner.
    const D g0 = (Fwd ? (D{} + w.x0) + d0 : (D{} + w.x0) - d0) - kO0;
    const D g1 = (Fwd ? (D{} + w.x1) + d1 : (D{} + w.x1) - d1) - kO1;
    const D g2 = (Fwd ? (lane + kO2) + d2 : (lane + kO2) - d2) - kO2;
    o[0][h] = floor_of(g0, f[0][h]) - w.i;
    o[1][h] = floor_of(g1, f[1][h]) - w.j;
    o[2][h] = floor_of(g2, f[2][h]) - __builtin_convertvector(lane, I);
  }
  // One offset per axis for all lanes (contiguous loads), compared as vectors (extracting the
  // 3 W offsets one by one cost 7 % more of the advection at 128^3).
  auto same = [&](int h) FLAGSIM_INLINE_LAMBDA {
    return (o[0][h] == o[0][0][0]) & (o[1][h] == o[1][0][0]) & (o[2][h] == o[2][0][0]);
  };
  auto eq = same(0);
  for (int h = 1; h < H; ++h) eq &= same(h);
  const bool common = all_lanes(eq);
  const std::ptrdiff_t at[8] = {0, 1, w.sy, w.sy + 1, w.sx, w.sx + 1, w.sx + w.sy, w.sx + w.sy + 1};
  if (common) {
    const T* b = row + k + o[0][0][0] * w.sx + o[1][0][0] * w.sy + o[2][0][0];
    for (int a = 0; a < 8; ++a) v[a] = load_lanes<V>(b + at[a]);
  } else {  // lane by lane (a cell face crossed within the vector: ~22 % at 128^3, 4 lanes)
    // Gathered into arrays, then loaded: lanes set one by one in a vector read to GCC as the
    // unset rest used (-Wmaybe-uninitialized, even when zeroed first).
    T g[8][W];
    for (int l = 0; l < W; ++l) {
      const int h = l / DW, r = l % DW;
      const T* p = row + (k + l) + o[0][h][r] * w.sx + o[1][h][r] * w.sy + o[2][h][r];
      g[0][l] = p[0];
      g[1][l] = p[1];
      g[2][l] = p[w.sy];
      g[3][l] = p[w.sy + 1];
      g[4][l] = p[w.sx];
      g[5][l] = p[w.sx + 1];
      g[6][l] = p[w.sx + w.sy];
      g[7][l] = p[w.sx + w.sy + 1];
    }
    for (int a = 0; a < 8; ++a) v[a] = load_lanes<V>(g[a]);
  }
  // lerp in T (lerp(): a + T(f) (b - a)); for a double grid the conversions are no-ops.
  for (int a = 0; a < 3; ++a)
    for (int h = 0; h < H; ++h) {
      const P x = __builtin_convertvector(f[a][h], P);
      std::memcpy(reinterpret_cast<char*>(&wt[a]) + h * sizeof(P), &x, sizeof(P));
    }
  return true;
}

/// trilinear() on lanes: the same operations per lane.
template <class V>
FLAGSIM_INLINE V trilinear_lanes(const V v[8], const V wt[3]) {
  const V c00 = v[0] + wt[2] * (v[1] - v[0]), c01 = v[2] + wt[2] * (v[3] - v[2]);
  const V c10 = v[4] + wt[2] * (v[5] - v[4]), c11 = v[6] + wt[2] * (v[7] - v[6]);
  const V y0 = c00 + wt[1] * (c01 - c00), y1 = c10 + wt[1] * (c11 - c10);
  return y0 + wt[0] * (y1 - y0);
}

/// The semi-Lagrangian value by far_cell: the general sampler's bits. Returns false, out
/// untouched, when a departure is a ghost layer's reach or more (or not finite).
template <int C, class V, class T>
FLAGSIM_INLINE bool far_sample(const SlRow<T>& w, int k, const V& u0, const V& u1, const V& u2,
                               V& out) {
  V v[8], wt[3];
  if (!far_cell<C, false>(w, w.own, k, u0, u1, u2, v, wt)) return false;
  out = trilinear_lanes(v, wt);
  return true;
}
#endif

/// The fast path over a row: vectors of L (Lanes16 or Lanes32; void: scalars only), the tail in
/// scalars. Departures of a cell or more: far_sample where it applies. Returns
/// false if some node's departure is a cell or more away (or not finite) and was not sampled so.
template <int C, bool D, class L, int N2, class T>
FLAGSIM_INLINE bool sl_row_body(const SlRow<T>& w, int n2_) {
  const int n2 = N2 > 0 ? N2 : n2_;
  // D: add the explicit viscous term of u^n to every node's value (add_viscous_term).
  auto viscous = [&](auto value, int k) FLAGSIM_INLINE_LAMBDA {
    if constexpr (D) value += viscous_term<decltype(value)>(w.rows9, k, w.beta);
    return value;
  };
  bool near = true;
  int k = 0;
#ifdef FLAGSIM_HAVE_VECTORS
  if constexpr (!std::is_void<L>::value) {
    using V = typename L::V;
    V one = V{};
    one += T(1);
    auto vector_at = [&](int k) FLAGSIM_INLINE_LAMBDA {
      V u0, u1, u2;
      node_velocity<C>(w, k, u0, u1, u2);
      const V d0 = w.st * u0, d1 = w.st * u1, d2 = w.st * u2;
      const auto in = (abs_lanes(d0) < one) & (abs_lanes(d1) < one) & (abs_lanes(d2) < one);
      bool all_in, any_in;
      all_any_lanes(in, all_in, any_in);
      V far;
      if (!all_in && far_sample<C>(w, k, u0, u1, u2, far)) {
        // the lanes within a cell keep the upwind form's value (its rounding, as before)
        store_lanes(
            w.dst + k,
            viscous(any_in ? (in ? upwind_sample<V, T>(w.rows9, k, d0, d1, d2) : far) : far, k));
        return;
      }
      // a lane a cell or more away that far_sample did not take: the caller redoes the row
      near = near && all_in;
      store_lanes(w.dst + k, viscous(upwind_sample<V, T>(w.rows9, k, d0, d1, d2), k));
    };
    if constexpr (N2 > 0) {
      // A row length known here: the vectors unrolled, addressed by constant offsets (no
      // per-vector pointer increments, and a row set-up GCC makes shorter).
#pragma GCC unroll 8
      for (; k + L::W <= N2; k += L::W) vector_at(k);
    } else {
      for (; k + L::W <= n2; k += L::W) vector_at(k);
    }
  }
#endif
  for (; k < n2; ++k) {
    T d0, d1, d2;
    departure<C>(w, k, d0, d1, d2);
    near = near && std::fabs(d0) < 1 && std::fabs(d1) < 1 && std::fabs(d2) < 1;  // false for NaN
    w.dst[k] = viscous(upwind_sample<T, T>(w.rows9, k, d0, d1, d2), k);
  }
  return near;
}

/// The fast path over the n1 rows of a plane, w set for its row j = 0. Returns false if some
/// node's departure is a cell or more away (or not finite).
template <int C, bool D, class L, int N2, class T>
FLAGSIM_INLINE bool sl_plane_body(SlRow<T> w, int n1, int n2_, std::ptrdiff_t sy,
                                  unsigned char* row_done) {
  const int n2 = N2 > 0 ? N2 : n2_;
  bool near = true;
  for (int j = 0; j < n1; ++j) {
    w.j = j;
    w.x1 = j + GridGeometry::offset(C, 1);
    row_done[j] = sl_row_body<C, D, L, N2>(w, n2);
    near = row_done[j] && near;
    w.own += sy;
    w.e1 += sy;
    w.e2 += sy;
    for (const T*& row : w.rows9) row += sy;
    w.dst += n2;
  }
  return near;
}

/// What the node-by-node views of a row (i, j) of component C on padded copies share: the node's
/// position, its velocity (padded_velocity: the neighbours read without wrapping or clamping) and
/// its own value.
template <int C, class T>
struct PaddedRowBase {
  static constexpr double kO0 = C == 0 ? 0.0 : 0.5, kO1 = C == 1 ? 0.0 : 0.5;
  static constexpr double kO2 = C == 2 ? 0.0 : 0.5;
  const AdvectScratch<T>& sc;
  std::ptrdiff_t stride[3];
  int i, j;
  std::size_t idx0;  // padded index of (i, j, 0)
  PaddedRowBase(const AdvectScratch<T>& sc, int i, int j)
      : sc(sc), i(i), j(j), idx0(sc.u[C].index(i, j, 0)) {
    stride[0] = std::ptrdiff_t(sc.u[C].p1) * sc.u[C].p2;
    stride[1] = sc.u[C].p2;
    stride[2] = 1;
  }
  void node(int k, double x[3]) const {
    x[0] = i + kO0;
    x[1] = j + kO1;
    x[2] = k + kO2;
  }
  void velocity(int k, double vel[3]) const { padded_velocity<C>(sc.u, idx0 + k, stride, vel); }
  T own(int k) const { return sc.u[C].data[idx0 + k]; }
};

/// The kernels' view of row (i, j) of component C of a periodic grid from its padded copies (see
/// GenericRow): departures within a cell of the node sample without wrapping.
template <int C, class T>
struct PaddedRow : PaddedRowBase<C, T> {
  using B = PaddedRowBase<C, T>;
  using B::i, B::idx0, B::j, B::kO0, B::kO1, B::kO2, B::sc;
  PaddedSampler<T> q, qhat;
  PaddedRow(const AdvectScratch<T>& sc, int i, int j) : B(sc, i, j), q(sc.u[C]), qhat(sc.hat[C]) {}
  bool upstream(const double*) const { return false; }
  T inflow_at(const double*) const { return T(0); }  // never taken: a periodic grid has no inflow
  typename PaddedSampler<T>::Corner corner(const PaddedSampler<T>& s, const PaddedComponent<T>& p,
                                           const Trace& t, const double g[3], int k) const {
    return s.any_corner(p, idx0 + k, i, j, k, t.d[0], t.d[1], t.d[2], g[0] - kO0, g[1] - kO1,
                        g[2] - kO2);
  }
  T sample(const Trace& t, int k) const { return q.value(corner(q, sc.u[C], t, t.back, k)); }
  T sample_hat(const Trace& t, int k) const {
    return qhat.value(corner(qhat, sc.hat[C], t, t.fwd, k));
  }
  void nodes(const Trace& t, int k, T v[8]) const { q.nodes(corner(q, sc.u[C], t, t.back, k), v); }
};

constexpr int kMaxRows = 4096;

/// Plane i's view for the vector kernels (padded_sl, padded_far), set for its row j = 0: the
/// rows of the padded copies (all components share their strides), dt / h, beta = nu dt / h^2
/// and out's plane (unpadded).
template <int C, class T>
SlRow<T> plane_row(const AdvectScratch<T>& sc, int i, double s, T beta, T* out) {
  const PaddedComponent<T>& p = sc.u[C];
  constexpr int E1 = C == 0 ? 1 : 0, E2 = C == 2 ? 1 : 2;  // the other two components
  const std::ptrdiff_t sx = std::ptrdiff_t(p.p1) * p.p2, sy = p.p2;
  const std::ptrdiff_t stride[3] = {sx, sy, 1};
  const std::size_t idx0 = p.index(i, 0, 0);
  SlRow<T> w;
  w.own = p.data.data() + idx0;
  w.e1 = sc.u[E1].data.data() + idx0;
  w.e2 = sc.u[E2].data.data() + idx0;
  for (int a = -1; a <= 1; ++a)
    for (int b = -1; b <= 1; ++b) w.rows9[3 * (a + 1) + (b + 1)] = w.own + a * sx + b * sy;
  w.dc = stride[C];
  w.d1s = stride[E1];
  w.d2s = stride[E2];
  w.sx = sx;
  w.sy = sy;
  w.st = T(s);
  w.s = s;
  w.beta = beta;
  w.dst = out + std::size_t(i) * p.n[1] * p.n[2];
  w.i = i;
  w.j = 0;
  w.x0 = i + GridGeometry::offset(C, 0);
  return w;
}

/// Semi-Lagrangian pass of component C: out (unpadded) from padded u^n.
///
/// Each plane i first takes the fast path, row by row: upwind_sample on vectors (32 bytes with
/// AVX, else 16: SSE2 on any x86-64, GCC and Clang generic vectors), each row's tail in scalars.
/// A vector with a node whose departure is a cell or more away on some axis (CFL >= 1) takes
/// far_sample (the general sampler's arithmetic on vectors, for double and float grids alike,
/// when the departures stay within the ghosts); the nodes it cannot take (departures past the
/// ghosts, not finite) are then redone in their rows by the general sampler (any_corner: floor,
/// wrap). The upwind form
/// agrees with the general sampler to round-off (tests/cpp/fluid/test_advect.cpp); far_sample is
/// it bit for bit. D: every node also gains the explicit viscous term beta lap u^n
/// (viscous_term), beta = nu dt / h^2.
template <int C, bool D, class T>
void padded_sl(const AdvectScratch<T>& sc, double s, T beta, T* out) {
  const PaddedComponent<T>& p = sc.u[C];
  const std::ptrdiff_t sy = p.p2;
  const int n1 = p.n[1], n2 = p.n[2];
  const auto plane = [n1, n2, sy](auto c, const SlRow<T>& w, unsigned char* row_done)
                         FLAGSIM_INLINE_LAMBDA {
                           using K = decltype(c);
                           return sl_plane_body<C, D, typename K::L, K::N>(w, n1, n2, sy, row_done);
                         };
  const auto plane_fn = on_widest_lanes<T, bool(const SlRow<T>&, unsigned char*)>(plane, n2);
  for_each_plane(Shape3{{p.n[0], n1, n2}}, [&](int i) {
    const SlRow<T> w = plane_row<C>(sc, i, s, beta, out);
    unsigned char row_done[kMaxRows];  // rows of at most 4096 nodes (the resolution limit)
    if (plane_fn(w, row_done)) return;
    // Departures of a cell or more (or not finite) that far_sample did not take: those nodes
    // again, by the general sampler, in the rows that have them.
    for (int j = 0; j < n1; ++j) {
      if (row_done[j]) continue;
      const PaddedRow<C, T> row(sc, i, j);
      T* dst = w.dst + std::size_t(j) * n2;
      for (int k = 0; k < n2; ++k) {
        double x[3], vel[3];  // each vel exactly a T: the fast path's velocity, summed in its order
        row.node(k, x);
        row.velocity(k, vel);
        if (std::fabs(w.st * T(vel[0])) < 1 && std::fabs(w.st * T(vel[1])) < 1 &&
            std::fabs(w.st * T(vel[2])) < 1)
          continue;  // the fast path's departure (same T arithmetic): its value stands
        dst[k] = semi_lagrangian(row, trace(x, s, vel), k);
        if constexpr (D) dst[k] += viscous_term<T>(w.own + j * sy, w.sx, sy, k, beta);
      }
    }
  });
}

/// out += beta lap u^n for component C (viscous_term, the same bits as padded_sl's fused term).
template <int C, class T>
void padded_viscous(const AdvectScratch<T>& sc, T beta, T* out) {
  const PaddedComponent<T>& p = sc.u[C];
  const std::ptrdiff_t sx = std::ptrdiff_t(p.p1) * p.p2, sy = p.p2;
  for_each_row(Shape3{{p.n[0], p.n[1], p.n[2]}}, [&](int i, int j, std::size_t base) {
    const T* own = p.data.data() + p.index(i, j, 0);
    T* dst = out + base;
    for (int k = 0; k < p.n[2]; ++k) dst[k] += viscous_term<T>(own, sx, sy, k, beta);
  });
}

template <int C, class T>
void padded_sl_any(const AdvectScratch<T>& sc, double s, double beta, T* out) {
  if (beta > 0)
    padded_sl<C, true>(sc, s, T(beta), out);
  else
    padded_sl<C, false>(sc, s, T(0), out);
}

/// The kernels' view of row (i, j) of component C of a bounded grid from its clamped padded
/// copies (see GenericRow, whose arithmetic and bits it has): the velocity's nodes read without
/// clamps (the ghosts repeat the nearest node), the samples clamped onto the nodes as there.
template <int C, class T>
struct ClampedRow : PaddedRowBase<C, T> {
  Interpolator<T> q, qhat;
  T inflow;
  InflowShape shape;
  ClampedRow(const AdvectScratch<T>& sc, int i, int j, const SampleBoundary& bc)
      : PaddedRowBase<C, T>(sc, i, j),
        q(sc.u[C], C),
        qhat(sc.hat[C].data.empty() ? sc.u[C] : sc.hat[C], C),
        inflow(T(bc.inflow[C])),
        shape(bc.shape) {}
  T inflow_at(const double p[3]) const { return T(double(inflow) * shape.at(p)); }
  bool upstream(const double p[3]) const { return p[0] < 0; }
  T sample(const Trace& t, int) const { return q(t.back[0], t.back[1], t.back[2]); }
  T sample_hat(const Trace& t, int) const { return qhat(t.fwd[0], t.fwd[1], t.fwd[2]); }
  void nodes(const Trace& t, int, T v[8]) const {
    q.nodes(q.corners(t.back[0], t.back[1], t.back[2]), v);
  }
};

#ifdef FLAGSIM_HAVE_VECTORS
/// maccormack_correct then maccormack_clamp on lanes: the same operations per lane (a float
/// grid's correction in double, as there; std::min and std::max as the selects they are).
template <class V>
FLAGSIM_INLINE V maccormack_lanes(V hat, V u, V bar, const V nodes[8]) {
  using E = std::remove_reference_t<decltype(hat[0])>;
  V value;
  if constexpr (std::is_same<E, double>::value) {
    value = hat + 0.5 * (u - bar);
  } else {
    using D = typename LanesOf<double, int(sizeof(V) / sizeof(E))>::V;
    const D x = __builtin_convertvector(hat, D) + 0.5 * __builtin_convertvector(u - bar, D);
    value = __builtin_convertvector(x, V);
  }
  V lo = nodes[0], hi = nodes[0];
  for (int a = 1; a < 8; ++a) {
    lo = nodes[a] < lo ? nodes[a] : lo;
    hi = hi < nodes[a] ? nodes[a] : hi;
  }
  const V m = lo < value ? value : lo;
  return m < hi ? m : hi;
}
#endif

/// One row of padded_far on vectors of L (void: none), the last one overlapping the one before
/// (a node's value depends on the copies only). Mc: MacCormack's corrected, clamped value from
/// the predictor h (the unpadded row) and its padded copy (the row at hat_row); else the
/// semi-Lagrangian value by far_sample. Returns false when some departure is a ghost layer's
/// reach or more (or not finite), or the row is shorter than a vector: the caller redoes the row.
template <int C, bool Mc, class L, class T>
FLAGSIM_INLINE bool far_row_body(const SlRow<T>& w, int n2, const T* hat_row, const T* h) {
#ifdef FLAGSIM_HAVE_VECTORS
  if constexpr (!std::is_void<L>::value) {
    using V = typename L::V;
    if (n2 < L::W) return false;
    bool ok = true;
    auto at = [&](int k) FLAGSIM_INLINE_LAMBDA {
      V u0, u1, u2;
      node_velocity<C>(w, k, u0, u1, u2);
      V out;
      if constexpr (Mc) {
        V hv[8], hw[3], nv[8], nw[3];
        if (!far_cell<C, true>(w, hat_row, k, u0, u1, u2, hv, hw) ||
            !far_cell<C, false>(w, w.own, k, u0, u1, u2, nv, nw)) {
          ok = false;
          return;
        }
        out = maccormack_lanes(load_lanes<V>(h + k), load_lanes<V>(w.own + k),
                               trilinear_lanes(hv, hw), nv);
      } else if (!far_sample<C>(w, k, u0, u1, u2, out)) {
        ok = false;
        return;
      }
      store_lanes(w.dst + k, out);
    };
    int k = 0;
    for (; k + L::W <= n2; k += L::W) at(k);
    if (k < n2) at(n2 - L::W);
    return ok;
  }
#endif
  (void)w, (void)n2, (void)hat_row, (void)h;
  return false;
}

/// One pass of component C from the padded copies into out, node for node the generic kernels'
/// value (their bits): Mc, MacCormack's correction from the predictor h (unpadded; its padded
/// copy in sc.hat); else the semi-Lagrangian value (a bounded grid's: the periodic one is
/// padded_sl's). Rows whose departures all lie within the ghosts run on vectors (far_cell, the
/// general sampler's arithmetic), the others node by node: PaddedRow (periodic), ClampedRow
/// (bounded; also every plane within the ghosts' reach of the inflow face, where a departure may
/// fall upstream of it and take the inflow).
template <int C, bool Mc, class T>
void padded_far(const AdvectScratch<T>& sc, double s, const SampleBoundary& bc, const T* h,
                T* out) {
  constexpr int G = PaddedComponent<T>::kGhost;
  const PaddedComponent<T>& p = sc.u[C];
  const bool bounded = p.clamped;
  const std::ptrdiff_t sy = p.p2;
  const int n1 = p.n[1], n2 = p.n[2];
  const T* hat0 = Mc ? sc.hat[C].data.data() : nullptr;
  const auto plane = [n1, n2, sy](auto c, SlRow<T> w, const T* hat_row, const T* h_plane,
                                  unsigned char* row_done) FLAGSIM_INLINE_LAMBDA {
    using K = decltype(c);
    bool all = true;
    for (int j = 0; j < n1; ++j) {
      w.j = j;
      w.x1 = j + GridGeometry::offset(C, 1);
      row_done[j] = far_row_body<C, Mc, typename K::L>(w, n2, hat_row, h_plane);
      all = row_done[j] && all;
      w.own += sy;
      for (const T*& row : w.rows9) row += sy;
      w.e1 += sy;
      w.e2 += sy;
      w.dst += n2;
      if (Mc) {
        hat_row += sy;
        h_plane += n2;
      }
    }
    return all;
  };
  const auto plane_fn =
      on_widest_lanes<T, bool(SlRow<T>, const T*, const T*, unsigned char*)>(plane);
  for_each_plane(Shape3{{p.n[0], n1, n2}}, [&](int i) {
    const std::size_t idx0 = p.index(i, 0, 0);
    const std::size_t base = std::size_t(i) * n1 * n2;
    const SlRow<T> w = plane_row<C>(sc, i, s, T(0), out);
    unsigned char row_done[kMaxRows];           // rows of at most 4096 nodes (the resolution limit)
    const bool by_nodes = bounded && w.x0 < G;  // a departure may cross the inflow face
    if (!by_nodes && plane_fn(w, Mc ? hat0 + idx0 : nullptr, Mc ? h + base : nullptr, row_done))
      return;
    for (int j = 0; j < n1; ++j) {
      if (!by_nodes && row_done[j]) continue;
      const std::size_t r = base + std::size_t(j) * n2;
      const auto redo = [&](const auto& row) {
        if constexpr (Mc)
          maccormack_row(row, s, n2, h + r, out + r);
        else
          semi_lagrangian_row(row, s, n2, out + r);
      };
      if (bounded)
        redo(ClampedRow<C, T>(sc, i, j, bc));
      else
        redo(PaddedRow<C, T>(sc, i, j));
    }
  });
}

}  // namespace

template <class T>
void advect_padded(MacGrid<T>& u, double dt, bool maccormack, AdvectScratch<T>& scratch,
                   MacGrid<T>& hat, const SampleBoundary& bc, double viscous_beta) {
  fill_advect_source(u, scratch);
  advect_from_source(u, dt, maccormack, scratch, hat, bc, viscous_beta);
}

template <class T>
void fill_advect_source(const MacGrid<T>& u, AdvectScratch<T>& scratch) {
  for (int c = 0; c < 3; ++c) scratch.u[c].fill(u.comp[c].data());
}

template <class T>
void advect_from_source(MacGrid<T>& u, double dt, bool maccormack, AdvectScratch<T>& scratch,
                        MacGrid<T>& hat, const SampleBoundary& bc, double viscous_beta) {
  const double s = dt / u.geo.h;
  // Semi-Lagrangian (into hat for MacCormack, else straight into u: only padded copies are read;
  // a periodic grid's viscous term fused in).
  MacGrid<T>& sl = maccormack ? hat : u;
  if (!u.geo.periodic) {
    padded_far<0, false>(scratch, s, bc, static_cast<const T*>(nullptr), sl.comp[0].data());
    padded_far<1, false>(scratch, s, bc, static_cast<const T*>(nullptr), sl.comp[1].data());
    padded_far<2, false>(scratch, s, bc, static_cast<const T*>(nullptr), sl.comp[2].data());
  } else {
    const double beta = maccormack ? 0.0 : viscous_beta;
    padded_sl_any<0>(scratch, s, beta, sl.comp[0].data());
    padded_sl_any<1>(scratch, s, beta, sl.comp[1].data());
    padded_sl_any<2>(scratch, s, beta, sl.comp[2].data());
  }
  if (!maccormack) return;
  for (int c = 0; c < 3; ++c) scratch.hat[c].fill(hat.comp[c].data());
  padded_far<0, true>(scratch, s, bc, hat.comp[0].data(), u.comp[0].data());
  padded_far<1, true>(scratch, s, bc, hat.comp[1].data(), u.comp[1].data());
  padded_far<2, true>(scratch, s, bc, hat.comp[2].data(), u.comp[2].data());
  if (u.geo.periodic && viscous_beta > 0) {  // MacCormack: the viscous term in a pass of its own
    padded_viscous<0>(scratch, T(viscous_beta), u.comp[0].data());
    padded_viscous<1>(scratch, T(viscous_beta), u.comp[1].data());
    padded_viscous<2>(scratch, T(viscous_beta), u.comp[2].data());
  }
}

template <class T>
void sample_weight_squares(const MacGrid<T>& g, const double* points, long m, double* out) {
  const double inv_h = 1.0 / g.geo.h;
  const Interpolator<T> at[3] = {Interpolator<T>(g, 0), Interpolator<T>(g, 1),
                                 Interpolator<T>(g, 2)};
  auto sq = [](double f) { return (1.0 - f) * (1.0 - f) + f * f; };
  for (long r = 0; r < m; ++r) {
    double p[3];
    cell_coordinates(g.geo, inv_h, points + 3 * r, p);
    double w = 0;
    for (int c = 0; c < 3; ++c) {
      const auto k = at[c].corners(p[0], p[1], p[2]);
      // a clamped axis (bounded, outside the nodes) has f = 0: one node of weight 1
      w = std::max(w, sq(k.fx) * sq(k.fy) * sq(k.fz));
    }
    out[r] = w;
  }
}

#define FLAGSIM_INSTANTIATE_ADVECT(T)                                                            \
  template T sample_component<T>(const MacGrid<T>&, int, const double[3]);                       \
  template long sample_velocity<T>(const MacGrid<T>&, const double*, long, double*);             \
  template void spread_velocity<T>(const double*, long, const double*, double, MacGrid<T>&);     \
  template void sample_weight_squares<T>(const MacGrid<T>&, const double*, long, double*);       \
  template void advect_semi_lagrangian<T>(const MacGrid<T>&, double, const SampleBoundary&,      \
                                          MacGrid<T>&);                                          \
  template void advect_maccormack<T>(const MacGrid<T>&, double, const SampleBoundary&,           \
                                     MacGrid<T>&, MacGrid<T>&);                                  \
  template struct PaddedComponent<T>;                                                            \
  template struct AdvectScratch<T>;                                                              \
  template void advect_padded<T>(MacGrid<T>&, double, bool, AdvectScratch<T>&, MacGrid<T>&,      \
                                 const SampleBoundary&, double);                                 \
  template void fill_advect_source<T>(const MacGrid<T>&, AdvectScratch<T>&);                     \
  template void advect_from_source<T>(MacGrid<T>&, double, bool, AdvectScratch<T>&, MacGrid<T>&, \
                                      const SampleBoundary&, double);
FLAGSIM_INSTANTIATE_ADVECT(float)
FLAGSIM_INSTANTIATE_ADVECT(double)

}  // namespace flagsim
