#include "fluid/pressure.h"
#include "common/parallel.h"
#include "common/simd.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <type_traits>
#include <vector>

#include "common/errors.h"
#include "fluid/params.h"
#ifdef FLAGSIM_HAVE_FFTW
#include <fftw3.h>
#endif

namespace flagsim {

namespace {

/// Vectors of DW doubles and of DW values of T (the divergence's lanes: it computes in double).
template <class T, int DW>
struct DivLanes {
  typedef double D __attribute__((vector_size(8 * DW)));
  typedef T P __attribute__((vector_size(sizeof(T) * DW)));
  typedef long long M __attribute__((vector_size(8 * DW)));  // a shuffle mask of D
};

/// One plane i of divergence: the (i, j) rows of cells, each value
///   T(((double(u1[k]) - u0[k]) + (double(v1[k]) - v0[k]) + (double(w0[k + 1]) - w0[k])) / h)
/// (times scale in double, back to T, when scale != 0), on vectors of DW doubles (DW = 1:
/// scalars). The same operations per lane as the scalar form, so the same bits at every width.
/// A periodic row's last cell reads face 0 of w: its last vector takes w0[0] into its top lane
/// by a shuffle, so rows whose length is a multiple of DW need no scalar cell.
template <int DW, int NZ, class T>
FLAGSIM_INLINE void divergence_plane_body(const MacGrid<T>& u, T* div, std::size_t stride,
                                          double scale, int i) {
  const GridGeometry& g = u.geo;
  const int ny = g.ny, nz = NZ > 0 ? NZ : g.nz;
  const bool per = g.periodic;
  const double inv_h = 1.0 / g.h;
  const Shape3 su = u.shape[0], sv = u.shape[1], sw = u.shape[2];
  const int ip = (per && i + 1 == g.nx) ? 0 : i + 1;
  const T *U = u.comp[0].data(), *V = u.comp[1].data(), *W = u.comp[2].data();
  auto cell = [&](double du, double dv, double dw) FLAGSIM_INLINE_LAMBDA {
    const T v = T((du + dv + dw) * inv_h);
    return scale == 0 ? v : T(scale * v);
  };
  for (int j = 0; j < ny; ++j) {
    const int jp = (per && j + 1 == ny) ? 0 : j + 1;
    const T *u0 = U + su.index(i, j, 0), *u1 = U + su.index(ip, j, 0);
    const T *v0 = V + sv.index(i, j, 0), *v1 = V + sv.index(i, jp, 0);
    const T* w0 = W + sw.index(i, j, 0);
    T* d = div + (std::size_t(i) * ny + j) * stride;
    int k = 0;
#ifdef FLAGSIM_HAVE_VECTORS
    if constexpr (DW > 1) {
      using D = typename DivLanes<T, DW>::D;
      using P = typename DivLanes<T, DW>::P;
      using M = typename DivLanes<T, DW>::M;
      auto ld = [](const T* p) FLAGSIM_INLINE_LAMBDA {
        P x;
        std::memcpy(&x, p, sizeof x);
        return __builtin_convertvector(x, D);
      };
      auto put = [&](int at, D w1) FLAGSIM_INLINE_LAMBDA {
        const D w = ld(w0 + at);
        P v = __builtin_convertvector(
            (((ld(u1 + at) - ld(u0 + at)) + (ld(v1 + at) - ld(v0 + at))) + (w1 - w)) * inv_h, P);
        if (scale != 0) v = __builtin_convertvector(scale * __builtin_convertvector(v, D), P);
        std::memcpy(d + at, &v, sizeof v);
      };
      const int vec_end = per ? nz - DW : nz;  // vectors whose w0[k + 1] lie in the row
#pragma GCC unroll 8
      for (; k + DW <= vec_end; k += DW) put(k, ld(w0 + k + 1));
      if (per && k == nz - DW) {  // w0[k + 1 ..], then w0[0]
        D top = D{};
        top += double(w0[0]);
        M mask;
        if constexpr (DW == 2)
          mask = M{1, 2};
        else
          mask = M{1, 2, 3, 4};
        put(k, __builtin_shuffle(ld(w0 + k), top, mask));
        k = nz;
      }
    }
#endif
    const int kend = per ? nz - 1 : nz;  // periodic: the last cell's top face is face 0
    for (; k < kend; ++k)
      d[k] = cell(double(u1[k]) - u0[k], double(v1[k]) - v0[k], double(w0[k + 1]) - w0[k]);
    if (per && k == nz - 1)
      d[k] = cell(double(u1[k]) - u0[k], double(v1[k]) - v0[k], double(w0[0]) - w0[k]);
  }
}

}  // namespace

template <class T>
void divergence(const MacGrid<T>& u, T* div, int row_stride, double scale) {
  const GridGeometry& g = u.geo;
  const std::size_t stride = row_stride > 0 ? std::size_t(row_stride) : std::size_t(g.nz);
  const auto plane = [&u, div, stride, scale](auto c, int i) FLAGSIM_INLINE_LAMBDA {
    divergence_plane_body<decltype(c)::W, decltype(c)::N>(u, div, stride, scale, i);
  };
  const auto plane_fn = on_widest_lanes<double, void(int)>(plane, g.nz);
  // One task per plane: per row, the call and its set-up cost more than a short row's cells.
  parallel_for_if(Index(g.cells().size()) > kGridParallelGrain, g.nx,
                  [&](Index i) { plane_fn(int(i)); });
}

Laplace7 pressure_operator(const GridGeometry& geo) {
  Laplace7 op;
  op.shape = geo.cells();
  if (!geo.periodic) {
    for (int d = 0; d < 3; ++d) op.lo[d] = op.hi[d] = Side::kNeumann;
    op.hi[0] = Side::kGhostZero;  // open outflow face, p = 0 beyond
  }
  return op;
}

Laplace7 diffusion_operator(const GridGeometry& geo, int c) {
  Laplace7 op;
  op.shape = geo.face_shape(c);
  if (!geo.periodic) {
    for (int d = 0; d < 3; ++d) op.lo[d] = op.hi[d] = Side::kNeumann;
    const Laplace7 p = pressure_operator(geo);
    // A face held by the pressure solve (Neumann for phi) is a fixed node for diffusion.
    if (p.lo[c] == Side::kNeumann) op.lo[c] = Side::kFixed;
    if (p.hi[c] == Side::kNeumann) op.hi[c] = Side::kFixed;
  }
  return op;
}

template <class T>
void subtract_gradient(const T* phi, MacGrid<T>& u, int row_stride) {
  const GridGeometry& g = u.geo;
  const Shape3 sc = g.cells();
  const std::size_t stride = row_stride > 0 ? std::size_t(row_stride) : std::size_t(sc.n[2]);
  auto phi_row = [&](int i, int j) { return phi + (std::size_t(i) * sc.n[1] + j) * stride; };
  const T inv_h = T(1.0 / g.h);
  const bool per = g.periodic;
  const Laplace7 p = pressure_operator(g);
  for (int c = 0; c < 3; ++c) {
    const Shape3 sh = u.shape[c];
    T* q = u.comp[c].data();
    const long rows = long(sh.n[0]) * sh.n[1];
    const int nc = sc.n[c];
    parallel_for_if(Index(sh.size()) > kGridParallelGrain, rows, [&](Index r) {
      const int i = int(r / sh.n[1]), j = int(r % sh.n[1]);
      T* dst = q + std::size_t(r) * sh.n[2];
      const int ij[2] = {i, j};
      if (c < 2) {
        // Face f = ij[c] lies between cells f-1 (lo) and f (hi) of the same k-row.
        const int f = ij[c];
        const bool held = !per && ((f == 0 && p.lo[c] == Side::kNeumann) ||
                                   (f == nc && p.hi[c] == Side::kNeumann));
        if (held) return;
        int lo[2] = {i, j}, hi[2] = {i, j};
        lo[c] = per ? (f == 0 ? nc - 1 : f - 1) : f - 1;
        const int n = sh.n[2];
        const T* ph = (per || f < nc) ? phi_row(hi[0], hi[1]) : nullptr;  // null: ghost 0
        const T* pl = lo[c] >= 0 ? phi_row(lo[0], lo[1]) : nullptr;
        if (ph && pl) {
          for (int k = 0; k < n; ++k) dst[k] -= (ph[k] - pl[k]) * inv_h;
        } else if (pl) {  // the open end: p = 0 in the ghost cell beyond
          for (int k = 0; k < n; ++k) dst[k] -= (T(0) - pl[k]) * inv_h;
        } else if (ph) {
          for (int k = 0; k < n; ++k) dst[k] -= (ph[k] - T(0)) * inv_h;
        }
      } else {
        const T* pr = phi_row(i, j);
        const int n2 = sc.n[2];
        if (per) {
          dst[0] -= (pr[0] - pr[n2 - 1]) * inv_h;
          for (int k = 1; k < n2; ++k) dst[k] -= (pr[k] - pr[k - 1]) * inv_h;
        } else {
          // k = 0 and k = n2 are walls (held); the z axis has no open side in the tunnel.
          for (int k = 1; k < n2; ++k) dst[k] -= (pr[k] - pr[k - 1]) * inv_h;
        }
      }
    });
  }
}

namespace {

/// Shuffle masks (__builtin_shuffle) for vectors of Bytes bytes of T: integers of T's size.
template <class T, int Bytes>
struct MaskOf {
  typedef std::conditional_t<sizeof(T) == 8, long long, int> E;
  typedef E M __attribute__((vector_size(Bytes)));
};

/// dst[k] -= (hi[k] - lo[k]) * inv_h for k in [0, n) (subtract_gradient's arithmetic, the same
/// bits) on lanes L (Lanes16 or Lanes32 of T, or void: scalars). zeros (per lane) and zero gain
/// v - v of every new value v: 0 while all are finite, NaN once one is not (NaN or infinity), and
/// NaN stays NaN (no integer masks: SSE2 has no 64-bit lane compares, and a mask reduction went
/// scalar). first_lo: when set, lane 0 of the first vector's lo is *first_lo and its other lanes
/// lo[0 ..] shifted up one (the w row: face 0 reads the row's last cell).
template <class L, int N, class T, class Z>
FLAGSIM_INLINE void gradient_row(T* dst, const T* hi, const T* lo, int n_, T inv_h, Z& zeros,
                                 T& zero, const T* first_lo = nullptr) {
  const int n = N > 0 ? N : n_;
  int k = 0;
  if constexpr (!std::is_void<L>::value) {
    using V = typename L::V;
    constexpr int W = L::W;
    if (first_lo && n >= W) {
      using M = typename MaskOf<T, sizeof(V)>::M;
      V top = V{};
      top += *first_lo;
      M mask;  // lane 0 from top, lanes 1.. from lo[0 ..]
      if constexpr (W == 2)
        mask = M{0, 2};
      else if constexpr (W == 4)
        mask = M{0, 4, 5, 6};
      else
        mask = M{0, 8, 9, 10, 11, 12, 13, 14};
      const V v = load_lanes<V>(dst) -
                  (load_lanes<V>(hi) - __builtin_shuffle(top, load_lanes<V>(lo), mask)) * inv_h;
      store_lanes(dst, v);
      zeros += v - v;
      k = W;
      --lo;  // from here on lo[k] is the cell below face k
      first_lo = nullptr;
    }
#pragma GCC unroll 8
    for (; k + W <= n; k += W) {
      const V v = load_lanes<V>(dst + k) - (load_lanes<V>(hi + k) - load_lanes<V>(lo + k)) * inv_h;
      store_lanes(dst + k, v);
      zeros += v - v;
    }
  }
  if (first_lo) {  // scalar w row: face 0
    dst[0] -= (hi[0] - *first_lo) * inv_h;
    zero += dst[0] - dst[0];
    k = 1;
    --lo;
  }
  for (; k < n; ++k) {
    dst[k] -= (hi[k] - lo[k]) * inv_h;
    zero += dst[k] - dst[k];
  }
}

/// The faces of plane i of the periodic grid (all three components, one (i, j) row of cells at a
/// time) take the gradient of phi (rows `stride` apart) on lanes L: subtract_gradient_periodic's
/// plane. Returns false when a new value is not finite.
template <class L, int N, class T>
FLAGSIM_INLINE bool gradient_periodic_plane(const T* phi, std::size_t stride, int nx, int ny,
                                            int nz_, T inv_h, T* U, T* V, T* W, int i) {
  const int nz = N > 0 ? N : nz_;
  using Z = std::conditional_t<std::is_void<L>::value, T, typename L::V>;
  Z zeros = Z{};
  T zero = 0;
  for (int j = 0; j < ny; ++j) {
    const std::size_t r = std::size_t(i) * ny + j;
    const std::size_t row = r * nz;
    const T* hi = phi + r * stride;  // cell (i, j): the faces' upper cell
    const T* lo_x = phi + (std::size_t(i == 0 ? nx - 1 : i - 1) * ny + j) * stride;
    const T* lo_y = phi + (std::size_t(i) * ny + (j == 0 ? ny - 1 : j - 1)) * stride;
    gradient_row<L, N>(U + row, hi, lo_x, nz, inv_h, zeros, zero);
    gradient_row<L, N>(V + row, hi, lo_y, nz, inv_h, zeros, zero);
    // Face k of w lies between cells k - 1 and k of the row; face 0 wraps to cell nz - 1.
    gradient_row<L, N>(W + row, hi, hi, nz, inv_h, zeros, zero, hi + nz - 1);
  }
  if constexpr (!std::is_void<L>::value)
    for (int l = 0; l < L::W; ++l) zero += zeros[l];
  return zero == 0;
}

}  // namespace

template <class T>
bool subtract_gradient_periodic(const T* phi, int row_stride, MacGrid<T>& u) {
  const GridGeometry& g = u.geo;
  const int nx = g.nx, ny = g.ny, nz = g.nz;
  const T inv_h = T(1.0 / g.h);
  const std::size_t stride = row_stride > 0 ? std::size_t(row_stride) : std::size_t(nz);
  T *U = u.comp[0].data(), *V = u.comp[1].data(), *W = u.comp[2].data();
  const auto plane = [=](auto c, int i) FLAGSIM_INLINE_LAMBDA {  // phi .. W by value
    using C = decltype(c);
    return gradient_periodic_plane<typename C::L, C::N>(phi, stride, nx, ny, nz, inv_h, U, V, W, i);
  };
  const auto plane_fn = on_widest_lanes<T, bool(int)>(plane, nz);
  std::atomic<bool> finite{true};  // an AND of per-plane answers: the same for any order
  // One task per plane, all three components: the potential's rows are read once, and a short
  // row's call and set-up are paid once per plane.
  parallel_for_if(Index(g.cells().size()) > kGridParallelGrain, nx, [&](Index i) {
    if (!plane_fn(int(i))) finite.store(false, std::memory_order_relaxed);
  });
  return finite.load();
}

template <class T>
void apply_tunnel_boundary(const Vec3& inflow, const double* weights, MacGrid<T>& u) {
  const GridGeometry& g = u.geo;
  for (int j = 0; j < g.ny; ++j)
    for (int k = 0; k < g.nz; ++k)
      u.at(0, 0, j, k) = T(weights ? inflow.x() * weights[std::size_t(j) * g.nz + k] : inflow.x());
  for (int i = 0; i < g.nx; ++i)
    for (int k = 0; k < g.nz; ++k) u.at(1, i, 0, k) = u.at(1, i, g.ny, k) = T(0);
  for (int i = 0; i < g.nx; ++i)
    for (int j = 0; j < g.ny; ++j) u.at(2, i, j, 0) = u.at(2, i, j, g.nz) = T(0);
}

namespace {

// set_mean_flow of one component on a grid below kGridParallelGrain, where deterministic_sum
// sums its blocks on one thread: the same block sums added in the same order, and the same
// shift, here in one function so the AVX copy vectorises both loops 32 bytes wide (the same
// operations per lane: the same bits).
template <class T>
FLAGSIM_INLINE void shift_mean_serial(T* q, std::size_t n, double target) {
  constexpr std::size_t kBlock = 4096;  // deterministic_sum's block (n is far below 256 of them)
  const auto f = [q](std::size_t i) FLAGSIM_INLINE_LAMBDA { return double(q[i]); };
  double sum = 0;
  for (std::size_t b = 0; b < n; b += kBlock) sum += ordered_sum(b, std::min(n, b + kBlock), f);
  const double shift = target - sum / double(n);
  if (shift == 0) return;
  for (std::size_t i = 0; i < n; ++i) q[i] = T(q[i] + shift);
}

}  // namespace

template <class T>
void set_mean_flow(const Vec3& target, MacGrid<T>& u) {
  const auto shift = [](auto, T* q, std::size_t n, double target)
                         FLAGSIM_INLINE_LAMBDA { shift_mean_serial(q, n, target); };
  const auto serial = on_widest_lanes<T, void(T*, std::size_t, double)>(shift);
  for (int c = 0; c < 3; ++c) {
    AlignedVector<T>& q = u.comp[c];
    const std::size_t n = q.size();
    if (Index(n) <= kGridParallelGrain) {
      serial(q.data(), n, target[c]);
      continue;
    }
    const double mean =
        deterministic_sum(n, [&](std::size_t i) { return double(q[i]); }) / double(n);
    const double shift = target[c] - mean;
    if (shift == 0) continue;
    parallel_for_cells(long(n), [&](Index i) { q[i] = T(q[i] + shift); });
  }
}

// ---- FFT projector ------------------------------------------------------------------------------

#ifdef FLAGSIM_HAVE_FFTW
namespace {

// FFTW's planner is not thread-safe (FFTW manual §5.4): plan creation and destruction serialise.
std::mutex& fftw_planner_mutex() {
  static std::mutex m;
  return m;
}

/// Threads for one grid's transforms: flagsim's thread count on grids of 32^3 cells and more
/// (below that a transform takes tens of microseconds and waking threads costs more than it
/// saves), else one. Fixed when the plans are made: set_num_threads() before building a Fluid.
int fft_threads(std::size_t cells) {
#ifdef FLAGSIM_HAVE_FFTW_OMP
  constexpr std::size_t kThreadedCells = 32 * 32 * 32;
  return cells >= kThreadedCells ? num_threads() : 1;
#else
  (void)cells;
  return 1;
#endif
}

template <class T>
struct Fftw;
template <>
struct Fftw<double> {
  using Plan = fftw_plan;
  using Complex = fftw_complex;
  static void threads(int n) {
#ifdef FLAGSIM_HAVE_FFTW_OMP
    static const bool ready = fftw_init_threads() != 0;  // once, under the planner mutex
    if (ready) fftw_plan_with_nthreads(n);
#else
    (void)n;
#endif
  }
  static Plan r2c(int n0, int n1, int n2, double* in, Complex* out) {
    return fftw_plan_dft_r2c_3d(n0, n1, n2, in, out, FFTW_ESTIMATE);
  }
  static Plan c2r(int n0, int n1, int n2, Complex* in, double* out) {
    return fftw_plan_dft_c2r_3d(n0, n1, n2, in, out, FFTW_ESTIMATE);
  }
  static void exec_r2c(Plan p, double* in, Complex* out) { fftw_execute_dft_r2c(p, in, out); }
  static void exec_c2r(Plan p, Complex* in, double* out) { fftw_execute_dft_c2r(p, in, out); }
  static void destroy(Plan p) { fftw_destroy_plan(p); }
};
template <>
struct Fftw<float> {
  using Plan = fftwf_plan;
  using Complex = fftwf_complex;
  static void threads(int n) {
#ifdef FLAGSIM_HAVE_FFTW_OMP
    static const bool ready = fftwf_init_threads() != 0;
    if (ready) fftwf_plan_with_nthreads(n);
#else
    (void)n;
#endif
  }
  static Plan r2c(int n0, int n1, int n2, float* in, Complex* out) {
    return fftwf_plan_dft_r2c_3d(n0, n1, n2, in, out, FFTW_ESTIMATE);
  }
  static Plan c2r(int n0, int n1, int n2, Complex* in, float* out) {
    return fftwf_plan_dft_c2r_3d(n0, n1, n2, in, out, FFTW_ESTIMATE);
  }
  static void exec_r2c(Plan p, float* in, Complex* out) { fftwf_execute_dft_r2c(p, in, out); }
  static void exec_c2r(Plan p, Complex* in, float* out) { fftwf_execute_dft_c2r(p, in, out); }
  static void destroy(Plan p) { fftwf_destroy_plan(p); }
};

}  // namespace

template <class T>
struct FftProjector<T>::Impl {
  using F = Fftw<T>;
  using C = std::complex<T>;
  GridGeometry geo;
  int nzc = 0;  // nz/2 + 1 complex entries along z
  std::size_t n_real = 0, n_cplx = 0;
  std::array<AlignedVector<C>, 3> hat;  // nx*ny*nzc each (no real buffer: see project)
  // Per-axis Fourier symbols: a_d(m) = (e^{i theta} - 1) / h (forward difference, i.e. MAC div
  // from faces to cells), lam_d(m) = (2 cos theta - 2) / h^2, theta = 2 pi m / n_d.
  std::array<std::vector<double>, 3> ar, ai;  // real and imaginary parts of a_d
  std::array<std::vector<double>, 3> lam;
  std::vector<double> plane_squares;  // nx: per plane, the squares of its new modes (finiteness)
  typename F::Plan fwd = nullptr, inv = nullptr;        // out of place: u's components <-> hat[c]
  typename F::Plan fwd_in = nullptr, inv_in = nullptr;  // in place in hat[0] (project)

  C* cplx(int c) { return hat[c].data(); }
  typename F::Complex* fc(int c) { return reinterpret_cast<typename F::Complex*>(hat[c].data()); }
};

template <class T>
FftProjector<T>::FftProjector(const GridGeometry& geo) : impl_(new Impl) {
  Impl& m = *impl_;
  m.geo = geo;
  m.nzc = geo.nz / 2 + 1;
  m.n_real = geo.cells().size();
  m.n_cplx = std::size_t(geo.nx) * geo.ny * m.nzc;
  for (int c = 0; c < 3; ++c) m.hat[c].assign(m.n_cplx, std::complex<T>(0));
  m.plane_squares.assign(std::size_t(geo.nx), 0.0);
  const double two_pi = 6.283185307179586476925286766559;
  for (int d = 0; d < 3; ++d) {
    const int n = geo.n(d);
    const int count = d == 2 ? m.nzc : n;
    m.ar[d].resize(count);
    m.ai[d].resize(count);
    m.lam[d].resize(count);
    for (int q = 0; q < count; ++q) {
      const double th = two_pi * q / n;
      m.ar[d][q] = (std::cos(th) - 1.0) / geo.h;
      m.ai[d][q] = std::sin(th) / geo.h;
      m.lam[d][q] = (2.0 * std::cos(th) - 2.0) / (geo.h * geo.h);
    }
  }
  std::lock_guard<std::mutex> lock(fftw_planner_mutex());
  Impl::F::threads(fft_threads(m.n_real));
  // The plans' real side is any other 64-byte aligned buffer of n_real values: the transforms
  // run with new arrays (the components, phi) of that alignment, and FFTW_ESTIMATE does not
  // touch the arrays while planning. hat[1] (n_cplx complex values >= n_real reals) serves, so
  // no grid-sized real buffer is kept for it (docs/design.md, "Memory").
  T* real = reinterpret_cast<T*>(m.hat[1].data());
  m.fwd = Impl::F::r2c(geo.nx, geo.ny, geo.nz, real, m.fc(0));
  m.inv = Impl::F::c2r(geo.nx, geo.ny, geo.nz, m.fc(0), real);
  T* padded = reinterpret_cast<T*>(m.hat[0].data());  // rows of 2 nzc reals (FFTW manual §4.3.4)
  m.fwd_in = Impl::F::r2c(geo.nx, geo.ny, geo.nz, padded, m.fc(0));
  m.inv_in = Impl::F::c2r(geo.nx, geo.ny, geo.nz, m.fc(0), padded);
}

template <class T>
FftProjector<T>::~FftProjector() {
  std::lock_guard<std::mutex> lock(fftw_planner_mutex());
  if (impl_->fwd) Impl::F::destroy(impl_->fwd);
  if (impl_->inv) Impl::F::destroy(impl_->inv);
  if (impl_->fwd_in) Impl::F::destroy(impl_->fwd_in);
  if (impl_->inv_in) Impl::F::destroy(impl_->inv_in);
}

template <class T>
T* FftProjector<T>::scratch(int& stride) const {
  stride = 2 * impl_->nzc;
  return reinterpret_cast<T*>(impl_->hat[0].data());
}

namespace {

/// Rows of at most this many modes (nz / 2 + 1 for the resolution limit nz <= 4096).
constexpr int kMaxModes = 2049;

/// One plane of project's spectral solve, its ny rows of nzc modes from `plane`: lap phi = div, so
/// phi_hat = div_hat / lambda, times scale for the inverse transform: each mode times
/// T(scale / lambda), lambda = lamx + lamy[j] + lamz[k]; the mean (lambda = 0) has no potential
/// and becomes 0. The factors of a row take DW double lanes (DW = 1: scalars; the division is the
/// cost), then the modes are multiplied as pairs of reals: the products std::complex<T> * T
/// forms, so the same bits at every width.
template <int DW, class T>
FLAGSIM_INLINE void potential_plane_body(std::complex<T>* plane, const double* lamy,
                                         const double* lamz, double lamx, int ny, int nzc,
                                         double scale) {
  T f[kMaxModes];
  for (int j = 0; j < ny; ++j) {
    const double lxy = lamx + lamy[j];
    bool mean = false;
    int k = 0, done = 0;  // modes [0, done) multiplied already
#ifdef FLAGSIM_HAVE_VECTORS
    if constexpr (DW > 1) {
      using D = typename DivLanes<T, DW>::D;
      using P = typename DivLanes<T, DW>::P;
      D zeros = D{};
      if constexpr (std::is_same<T, double>::value) {
        // double: each factor vector spread over its modes' (re, im) pairs and applied at once
        using M = typename DivLanes<T, DW>::M;
        M lower, upper;
        if constexpr (DW == 2) {
          lower = M{0, 0};
          upper = M{1, 1};
        } else {
          lower = M{0, 0, 1, 1};
          upper = M{2, 2, 3, 3};
        }
        T* re = reinterpret_cast<T*>(plane + std::size_t(j) * nzc);
        for (; k + DW <= nzc; k += DW) {
          const D l = lxy + load_lanes<D>(lamz + k);
          zeros += l == D{} ? zeros + 1.0 : D{};
          const D q = scale / l;
          T* m = re + 2 * k;
          store_lanes(m, load_lanes<D>(m) * __builtin_shuffle(q, lower));
          store_lanes(m + DW, load_lanes<D>(m + DW) * __builtin_shuffle(q, upper));
        }
        done = k;
      } else {
        for (; k + DW <= nzc; k += DW) {
          const D l = lxy + load_lanes<D>(lamz + k);
          zeros += l == D{} ? zeros + 1.0 : D{};
          const P q = __builtin_convertvector(scale / l, P);
          std::memcpy(f + k, &q, sizeof q);
        }
      }
      for (int lane = 0; lane < DW; ++lane) mean = mean || zeros[lane] != 0;
    }
#endif
    for (; k < nzc; ++k) {
      const double l = lxy + lamz[k];
      mean = mean || l == 0;
      f[k] = T(scale / l);
    }
    std::complex<T>* row = plane + std::size_t(j) * nzc;
    T* re = reinterpret_cast<T*>(row);  // (re, im) pairs (std::complex's array layout)
    for (int q = done; q < nzc; ++q) {
      re[2 * q] *= f[q];
      re[2 * q + 1] *= f[q];
    }
    if (mean)  // the mean mode: no potential
      for (int q = 0; q < nzc; ++q)
        if (lxy + lamz[q] == 0) row[q] = std::complex<T>(0);
  }
}

}  // namespace

template <class T>
bool FftProjector<T>::project(MacGrid<T>& u) {
  Impl& m = *impl_;
  const GridGeometry& g = m.geo;
  // phi: hat[0] as padded rows of reals, div u until the inverse transform writes the potential
  T* phi = reinterpret_cast<T*>(m.hat[0].data());
  const int stride = 2 * m.nzc;
  divergence(u, phi, stride);
  Impl::F::exec_r2c(m.fwd_in, phi, m.fc(0));
  const double scale = 1.0 / double(m.n_real);
  std::complex<T>* d = m.cplx(0);
  const double *lamx = m.lam[0].data(), *lamy = m.lam[1].data(), *lamz = m.lam[2].data();
  const int ny = g.ny, nzc = m.nzc;
  const auto plane = [=](auto c, int i) FLAGSIM_INLINE_LAMBDA {  // d .. scale by value
    potential_plane_body<decltype(c)::W>(d + std::size_t(i) * ny * nzc, lamy, lamz, lamx[i], ny,
                                         nzc, scale);
  };
  const auto plane_fn = on_widest_lanes<double, void(int)>(plane);
  parallel_for_if(Index(m.n_cplx) > kGridParallelGrain, g.nx, [&](Index i) { plane_fn(int(i)); });
  Impl::F::exec_c2r(m.inv_in, m.fc(0), phi);
  return subtract_gradient_periodic(phi, stride, u);
}

namespace {

/// One (i, j) row of diffuse_and_project's spectral update: what it reads and writes.
template <class T>
struct SpectralRow {
  T *p0, *p1, *p2;                 // the three transforms' row, interleaved (re, im)
  const double *azr, *azi, *lamz;  // per k
  double axr, axi, ayr, ayi, lxy;  // per row
  double scale, nu_dt;
};

/// The largest sum of squares (m^2/s^2) of one plane's new modes that still certifies the
/// inverse transforms finite: every mode is then below sqrt(max T) / (4 n), and a c2r output (a
/// sum of at most n modes, Hermitian halves included, as is every partial sum FFTW forms on the
/// way) is below sqrt(max T) / 4, far from overflow. A physical field is hundreds of orders of
/// magnitude below it; NaN or infinity fails the test, and so does any value too large to square.
template <class T>
double finite_plane_bound(std::size_t n_real) {
  const double b = std::sqrt(double(std::numeric_limits<T>::max())) / (4.0 * double(n_real));
  return b * b;
}

template <class S, class T>
FLAGSIM_INLINE void load_complex(const T* p, S& re, S& im) {
  if constexpr (std::is_same<S, double>::value) {
    re = p[0];
    im = p[1];
  } else {
    re = S{};
    im = S{};
    for (int l = 0; l < int(sizeof(S) / sizeof(double)); ++l) {
      re[l] = p[2 * l];
      im[l] = p[2 * l + 1];
    }
  }
}

template <class S, class T>
FLAGSIM_INLINE void store_complex(T* p, const S& re, const S& im) {
  if constexpr (std::is_same<S, double>::value) {
    p[0] = T(re);
    p[1] = T(im);
  } else {
    for (int l = 0; l < int(sizeof(S) / sizeof(double)); ++l) {
      p[2 * l] = T(re[l]);
      p[2 * l + 1] = T(im[l]);
    }
  }
}

/// Modes k.. of a row, one per lane of S (double or a vector of doubles); returns the sum of the
/// squares of the new modes' parts, per lane.
template <class S, class T>
FLAGSIM_INLINE S spectral_modes(const SpectralRow<T>& w, int k) {
  S xr, xi, yr, yi, zr, zi;
  load_complex(w.p0 + 2 * k, xr, xi);
  load_complex(w.p1 + 2 * k, yr, yi);
  load_complex(w.p2 + 2 * k, zr, zi);
  const S azr = load_lanes<S>(w.azr + k), azi = load_lanes<S>(w.azi + k);
  const S l = w.lxy + load_lanes<S>(w.lamz + k);
  // Backward Euler diffusion: (1 - nu dt lambda) u_hat_new = u_hat (Stam 2001 §3), then
  // phi_hat = (a . u_hat_new) / lambda and u_hat_new -= g phi_hat with g_d = -conj(a_d)
  // (backward difference from cells to faces), so that a . g = lambda. One division:
  // s = scale / (1 - nu dt l) and s / l = scale / (l (1 - nu dt l)). The mode lambda = 0 (the
  // mean) has no potential: s = scale, sp = 0.
  const S zero = S{}, one = zero + 1.0;
  const auto mean = l == zero;
  const S ls = mean ? one : l;
  const S inv = 1.0 / (ls * (1.0 - w.nu_dt * ls));
  const S s = mean ? zero + w.scale : w.scale * ls * inv;
  const S sp = mean ? zero : w.scale * inv;
  // phi = sp (a . u_hat) (complex), then u += conj(a) phi, in real arithmetic: std::complex
  // products check for NaN and call __muldc3, which keeps a loop scalar and branchy.
  const S pr = sp * (w.axr * xr - w.axi * xi + w.ayr * yr - w.ayi * yi + azr * zr - azi * zi);
  const S pi = sp * (w.axr * xi + w.axi * xr + w.ayr * yi + w.ayi * yr + azr * zi + azi * zr);
  const S ur = s * xr + w.axr * pr + w.axi * pi, ui = s * xi + w.axr * pi - w.axi * pr;
  const S vr = s * yr + w.ayr * pr + w.ayi * pi, vi = s * yi + w.ayr * pi - w.ayi * pr;
  const S wr = s * zr + azr * pr + azi * pi, wi = s * zi + azr * pi - azi * pr;
  store_complex(w.p0 + 2 * k, ur, ui);
  store_complex(w.p1 + 2 * k, vr, vi);
  store_complex(w.p2 + 2 * k, wr, wi);
  // The step's finiteness check, fused here (finite_plane_bound): the new modes' squares.
  return ur * ur + ui * ui + vr * vr + vi * vi + wr * wr + wi * wi;
}

/// A whole row: vectors of L (Lanes16<double>, Lanes32<double>; void: scalars), then the tail.
/// Returns the sum of the squares of its new modes' parts.
template <class L, class T>
FLAGSIM_INLINE double spectral_row_body(const SpectralRow<T>& w, int nzc) {
  int k = 0;
  double squares = 0;
#ifdef FLAGSIM_HAVE_VECTORS
  if constexpr (!std::is_void<L>::value) {
    typename L::V lanes = {};
    for (; k + L::W <= nzc; k += L::W) lanes += spectral_modes<typename L::V>(w, k);
    for (int l = 0; l < L::W; ++l) squares += lanes[l];
  }
#endif
  for (; k < nzc; ++k) squares += spectral_modes<double>(w, k);
  return squares;
}

/// The n1 rows j of a plane i, w set for j = 0; the y symbols per j from (ayr, ayi, lamy).
/// Returns the sum of the squares of the plane's new modes' parts.
template <class L, class T>
FLAGSIM_INLINE double spectral_plane_body(SpectralRow<T> w, const double* ayr, const double* ayi,
                                          const double* lamy, double lamx, int n1, int nzc) {
  double squares = 0;
  for (int j = 0; j < n1; ++j) {
    w.ayr = ayr[j];
    w.ayi = ayi[j];
    w.lxy = lamx + lamy[j];
    squares += spectral_row_body<L>(w, nzc);
    w.p0 += 2 * nzc;
    w.p1 += 2 * nzc;
    w.p2 += 2 * nzc;
  }
  return squares;
}

}  // namespace

template <class T>
bool FftProjector<T>::diffuse_and_project(MacGrid<T>& u, double nu_dt, const Vec3* mean) {
  Impl& m = *impl_;
  const GridGeometry& g = m.geo;
  for (int c = 0; c < 3; ++c) Impl::F::exec_r2c(m.fwd, u.comp[c].data(), m.fc(c));
  std::complex<T>* h0 = m.cplx(0);
  std::complex<T>* h1 = m.cplx(1);
  std::complex<T>* h2 = m.cplx(2);
  // One call per plane: rows are short.
  const auto plane = [&](auto c, int i) FLAGSIM_INLINE_LAMBDA {
    const std::size_t base = std::size_t(i) * g.ny * m.nzc;
    SpectralRow<T> w;
    w.p0 = reinterpret_cast<T*>(h0 + base);
    w.p1 = reinterpret_cast<T*>(h1 + base);
    w.p2 = reinterpret_cast<T*>(h2 + base);
    w.azr = m.ar[2].data();
    w.azi = m.ai[2].data();
    w.lamz = m.lam[2].data();
    w.axr = m.ar[0][i];
    w.axi = m.ai[0][i];
    w.scale = 1.0 / double(m.n_real);
    w.nu_dt = nu_dt;
    m.plane_squares[std::size_t(i)] = spectral_plane_body<typename decltype(c)::L>(
        w, m.ar[1].data(), m.ai[1].data(), m.lam[1].data(), m.lam[0][i], g.ny, m.nzc);
  };
  const auto plane_fn = on_widest_lanes<double, void(int)>(plane);
  parallel_for_if(Index(m.n_cplx) > kGridParallelGrain, g.nx, [&](Index i) { plane_fn(int(i)); });
  const double bound = finite_plane_bound<T>(m.n_real);
  bool finite = true;
  for (const double squares : m.plane_squares) finite = finite && squares <= bound;
  if (mean) {
    h0[0] = std::complex<T>(T((*mean)[0]));
    h1[0] = std::complex<T>(T((*mean)[1]));
    h2[0] = std::complex<T>(T((*mean)[2]));
    finite = finite && mean->squaredNorm() <= bound;
  }
  for (int c = 0; c < 3; ++c) Impl::F::exec_c2r(m.inv, m.fc(c), u.comp[c].data());
  return finite;
}

#else  // no FFTW

template <class T>
struct FftProjector<T>::Impl {};

template <class T>
FftProjector<T>::FftProjector(const GridGeometry&) {
  require_fftw("pressure", false);
}
template <class T>
FftProjector<T>::~FftProjector() = default;
template <class T>
bool FftProjector<T>::project(MacGrid<T>&) {
  return false;
}
template <class T>
bool FftProjector<T>::diffuse_and_project(MacGrid<T>&, double, const Vec3*) {
  return false;
}
template <class T>
T* FftProjector<T>::scratch(int& stride) const {
  stride = 0;
  return nullptr;
}

#endif

#define FLAGSIM_INSTANTIATE_PRESSURE(T)                                            \
  template void divergence<T>(const MacGrid<T>&, T*, int, double);                 \
  template void subtract_gradient<T>(const T*, MacGrid<T>&, int);                  \
  template bool subtract_gradient_periodic<T>(const T*, int, MacGrid<T>&);         \
  template void apply_tunnel_boundary<T>(const Vec3&, const double*, MacGrid<T>&); \
  template void set_mean_flow<T>(const Vec3&, MacGrid<T>&);                        \
  template class FftProjector<T>;
FLAGSIM_INSTANTIATE_PRESSURE(float)
FLAGSIM_INSTANTIATE_PRESSURE(double)

}  // namespace flagsim
