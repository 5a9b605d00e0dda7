#include "fluid/turbulence.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "common/parallel.h"

namespace flagsim {

namespace {

// SplitMix64 (Steele, Lea, Flood 2014) finaliser: a well-mixed 64-bit hash of one word.
inline uint64_t mix(uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

// Perlin 2002's twelve gradients, the edge midpoints of a cube.
constexpr double kGrad[12][3] = {{1, 1, 0}, {-1, 1, 0}, {1, -1, 0}, {-1, -1, 0},
                                 {1, 0, 1}, {-1, 0, 1}, {1, 0, -1}, {-1, 0, -1},
                                 {0, 1, 1}, {0, -1, 1}, {0, 1, -1}, {0, -1, -1}};

// Gradient noise n(q) of one (channel, slice) key and, with kGradient, its gradient dn/dq:
//   n = sum over the 8 lattice corners o of w_o(f) g_o . (f - o),  w_o = prod_d (o_d ? s_d :
//   1-s_d), s = fade(f) (Perlin 2002), f = q - floor(q). In three parts: each axis's cell and
// fade, the corners' gradients (which depend on the cell only), and the sum. n's bits do not
// depend on kGradient.

// Perlin 2002's quintic fade 6 f^5 - 15 f^4 + 10 f^3 (space within a cell, time between slices).
inline double fade(double f) { return f * f * f * (f * (f * 6.0 - 15.0) + 10.0); }

// One axis of q: the cell i0 = floor(q), f = q - i0, the fade s(f) and, with kGradient, ds/df.
struct AxisFade {
  int64_t i0;
  double f, s, ds;
};
template <bool kGradient>
inline AxisFade axis_fade(double q) {
  const double fl = std::floor(q);
  const double f = q - fl;
  return {static_cast<int64_t>(fl), f, fade(f),
          kGradient ? 30.0 * f * f * (f - 1.0) * (f - 1.0) : 0.0};
}

// The gradients of the 8 corners of lattice cell (i, j, k): corner o = (ox, oy, oz), the bits of
// o; hash mix(key ^ mix(i ^ mix(j ^ mix(k)))), the inner mixes shared between corners.
inline void corner_gradients(uint64_t key, int64_t i, int64_t j, int64_t k, const double* g[8]) {
  const uint64_t mz[2] = {mix(uint64_t(k)), mix(uint64_t(k + 1))};
  uint64_t myz[4];
  for (int o = 0; o < 4; ++o) myz[o] = mix(uint64_t(j + (o & 1)) ^ mz[o >> 1]);
  for (int o = 0; o < 8; ++o) {
    const int ox = o & 1, oy = (o >> 1) & 1, oz = (o >> 2) & 1;
    g[o] = kGrad[mix(key ^ mix(uint64_t(i + ox) ^ myz[oy | (oz << 1)])) % 12];
  }
}

// The sum over the corners, given their gradients g and the three axes' fades.
template <bool kGradient>
inline double corner_sum(const double* const g[8], const AxisFade a[3], Vec3* grad) {
  double n = 0;
  if (kGradient) grad->setZero();
  for (int o = 0; o < 8; ++o) {
    const int ox = o & 1, oy = (o >> 1) & 1, oz = (o >> 2) & 1;
    const double* go = g[o];
    const double r[3] = {a[0].f - ox, a[1].f - oy, a[2].f - oz};
    const double dot = go[0] * r[0] + go[1] * r[1] + go[2] * r[2];
    const double w[3] = {ox ? a[0].s : 1 - a[0].s, oy ? a[1].s : 1 - a[1].s,
                         oz ? a[2].s : 1 - a[2].s};
    const double W = w[0] * w[1] * w[2];
    n += W * dot;
    if (kGradient) {
      const double dw[3] = {ox ? a[0].ds : -a[0].ds, oy ? a[1].ds : -a[1].ds,
                            oz ? a[2].ds : -a[2].ds};
      Vec3& gr = *grad;
      gr[0] += W * go[0] + dot * dw[0] * w[1] * w[2];
      gr[1] += W * go[1] + dot * w[0] * dw[1] * w[2];
      gr[2] += W * go[2] + dot * w[0] * w[1] * dw[2];
    }
  }
  return n;
}

template <bool kGradient>
double gradient_noise(uint64_t key, const Vec3& q, Vec3* grad) {
  const AxisFade a[3] = {axis_fade<kGradient>(q[0]), axis_fade<kGradient>(q[1]),
                         axis_fade<kGradient>(q[2])};
  const double* g[8];
  corner_gradients(key, a[0].i0, a[1].i0, a[2].i0, g);
  return corner_sum<kGradient>(g, a, grad);
}

inline uint64_t channel_key(uint32_t seed, int channel, int64_t slice) {
  return mix((uint64_t(seed) << 2 | uint64_t(channel)) ^ mix(uint64_t(slice)));
}

}  // namespace

double noise_ramp(double r, double* derivative) {
  if (r >= 1) {
    if (derivative) *derivative = 0;
    return 1;
  }
  if (r <= 0) {
    if (derivative) *derivative = 0;
    return 0;
  }
  const double r2 = r * r;
  if (derivative) *derivative = 15.0 / 8.0 - 30.0 / 8.0 * r2 + 15.0 / 8.0 * r2 * r2;
  return r * (15.0 / 8.0 - 10.0 / 8.0 * r2 + 3.0 / 8.0 * r2 * r2);
}

double obstacle_distance(const ObstacleParams& o, const Vec3& x, Vec3* gradient) {
  return solid_distance(o, x, gradient);
}

CurlNoise::CurlNoise(const TurbulenceParams& params, std::vector<ObstacleParams> solids)
    : p_(params), solids_(std::move(solids)), enabled_(params.enabled()) {}

CurlNoise::Frame CurlNoise::frame(double t) const {
  return {p_.intensity.at(t, 0.0), p_.length_scale.at(t, TurbulenceParams::kDefaultLength),
          p_.evolution.integral(t, TurbulenceParams::kDefaultEvolution)};
}

// psi_c = A L [(1 - b) n_{c,k}(x / L) + b n_{c,k+1}(x / L)], k = floor(phase), b = fade(phase - k):
// d psi_c / dx = A [(1 - b) grad n_{c,k} + b grad n_{c,k+1}] (the L cancels).
void CurlNoise::raw(const Vec3& x, const Frame& f, Vec3& psi, Mat3* jacobian) const {
  const double k = std::floor(f.phase), fr = f.phase - k;
  const double b = fade(fr);
  const auto slice = static_cast<int64_t>(k);
  const Vec3 q = x / f.length;
  for (int c = 0; c < 3; ++c) {
    Vec3 g0, g1;
    const double n0 = gradient_noise<true>(channel_key(p_.seed, c, slice), q, &g0);
    const double n1 = gradient_noise<true>(channel_key(p_.seed, c, slice + 1), q, &g1);
    psi[c] = f.intensity * f.length * ((1 - b) * n0 + b * n1);
    if (jacobian) jacobian->row(c) = f.intensity * ((1 - b) * g0 + b * g1).transpose();
  }
}

double CurlNoise::ramp(const Vec3& x, Vec3* gradient) const {
  if (gradient) gradient->setZero();
  if (solids_.empty()) return 1.0;
  double d = std::numeric_limits<double>::infinity();
  Vec3 g = Vec3::Zero();
  for (const ObstacleParams& o : solids_) {
    Vec3 gi;
    const double di = obstacle_distance(o, x, &gi);
    if (di < d) {
      d = di;
      g = gi;
    }
  }
  double dr = 0;
  const double a = noise_ramp(d / p_.ramp_distance, &dr);
  if (gradient) *gradient = (dr / p_.ramp_distance) * g;
  return a;
}

// u = curl(alpha psi) = alpha curl psi + grad alpha x psi (Bridson 2007 §2.3, without the
// tangential-flow term): psi = 0 on the solid, so u there is grad alpha x psi, tangential.
Vec3 CurlNoise::velocity(const Vec3& x, double t) const {
  if (!enabled_) return Vec3::Zero();
  const Frame f = frame(t);
  if (f.intensity == 0) return Vec3::Zero();
  Vec3 psi;
  Mat3 J;
  raw(x, f, psi, &J);
  const Vec3 curl(J(2, 1) - J(1, 2), J(0, 2) - J(2, 0), J(1, 0) - J(0, 1));
  Vec3 ga;
  const double a = ramp(x, &ga);
  return a * curl + ga.cross(psi);
}

double CurlNoise::potential(int axis, const Vec3& x, double t) const {
  if (!enabled_) return 0.0;
  const Frame f = frame(t);
  if (f.intensity == 0) return 0.0;
  Vec3 psi;
  raw(x, f, psi, nullptr);
  return ramp(x, nullptr) * psi[axis];
}

Shape3 edge_shape(const GridGeometry& geo, int a) {
  Shape3 s = geo.cells();
  if (!geo.periodic)
    for (int d = 0; d < 3; ++d)
      if (d != a) s.n[d] += 1;
  return s;
}

Vec3 edge_position(const GridGeometry& geo, int a, int i, int j, int k) {
  return geo.origin +
         geo.h * Vec3(i + (a == 0 ? 0.5 : 0.0), j + (a == 1 ? 0.5 : 0.0), k + (a == 2 ? 0.5 : 0.0));
}

void EdgeNoise::reset(const GridGeometry& geo, bool ramped) {
  for (int a = 0; a < 3; ++a) {
    const std::size_t n = edge_shape(geo, a).size();
    n0[a].resize(n);
    n1[a].resize(n);
    ramp[a].resize(ramped ? n : 0);
  }
  valid = ramp_ready = false;
}

void CurlNoise::update_slices(const GridGeometry& geo, std::int64_t k, double length,
                              EdgeNoise& slices) const {
  // Slice `slice` of channel a at every edge of axis a: along a row only q_z changes, so the
  // corners' gradients are hashed again only where q_z enters another lattice cell.
  auto noise_slice = [&](std::array<AlignedVector<double>, 3>& out, std::int64_t slice) {
    for (int a = 0; a < 3; ++a) {
      const Shape3 s = edge_shape(geo, a);
      const uint64_t key = channel_key(p_.seed, a, slice);
      parallel_for(Index(s.n[0]), [&](Index i) {
        for (int j = 0; j < s.n[1]; ++j) {
          double* o = out[a].data() + s.index(int(i), j, 0);
          const Vec3 q0 = edge_position(geo, a, int(i), j, 0) / length;
          AxisFade f[3] = {axis_fade<false>(q0[0]), axis_fade<false>(q0[1]), {}};
          const double* g[8] = {};  // set at k = 0
          for (int k = 0; k < s.n[2]; ++k) {
            const Vec3 q = edge_position(geo, a, int(i), j, k) / length;
            const int64_t cell = f[2].i0;
            f[2] = axis_fade<false>(q[2]);
            if (k == 0 || f[2].i0 != cell) corner_gradients(key, f[0].i0, f[1].i0, f[2].i0, g);
            o[k] = corner_sum<false>(g, f, nullptr);
          }
        }
      });
    }
  };
  if (ramped() && !slices.ramp_ready) {  // alpha at every edge, once for these solids
    for (int a = 0; a < 3; ++a) {
      const Shape3 s = edge_shape(geo, a);
      double* o = slices.ramp[a].data();
      parallel_for(Index(s.n[0]), [&](Index i) {
        for (int j = 0; j < s.n[1]; ++j)
          for (int kk = 0; kk < s.n[2]; ++kk)
            o[s.index(int(i), j, kk)] = ramp(edge_position(geo, a, int(i), j, kk), nullptr);
      });
    }
    slices.ramp_ready = true;
  }
  if (slices.valid && slices.length == length && slices.slice == k) return;
  if (slices.valid && slices.length == length && slices.slice + 1 == k) {
    std::swap(slices.n0, slices.n1);  // the next slice becomes this one
  } else {
    noise_slice(slices.n0, k);
  }
  noise_slice(slices.n1, k + 1);
  slices.valid = true;
  slices.slice = k;
  slices.length = length;
}

// psi_c = alpha A L [(1 - b) n_{c,k} + b n_{c,k+1}] (see raw()), from the stored slices.
template <class T>
void CurlNoise::potential_on_edges(const GridGeometry& geo, double t, EdgeNoise& slices,
                                   std::array<AlignedVector<T>, 3>& psi) const {
  const Frame f = frame(t);
  if (!enabled_ || f.intensity == 0) {
    for (int a = 0; a < 3; ++a) std::fill(psi[a].begin(), psi[a].end(), T(0));
    return;
  }
  const double k = std::floor(f.phase), fr = f.phase - k;
  const double b = fade(fr);
  update_slices(geo, static_cast<int64_t>(k), f.length, slices);
  const double scale = f.intensity * f.length;
  for (int a = 0; a < 3; ++a) {
    const double *n0 = slices.n0[a].data(), *n1 = slices.n1[a].data();
    const double* alpha = ramped() ? slices.ramp[a].data() : nullptr;
    T* out = psi[a].data();
    parallel_for(Index(psi[a].size()), [&](Index e) {
      // b = 0: the next slice is not read (it weighs nothing; 0 * n1 could flip a zero's sign)
      const double raw = scale * ((1 - b) * n0[e] + b * (b > 0 ? n1[e] : 0.0));
      out[e] = T(alpha ? alpha[e] * raw : raw);
    });
  }
}

// Face values from the four edges around each face (Stokes on the face):
//   u(i,j,k) = [Z(i,j+1,k) - Z(i,j,k) - Y(i,j,k+1) + Y(i,j,k)] / h
//   v(i,j,k) = [X(i,j,k+1) - X(i,j,k) - Z(i+1,j,k) + Z(i,j,k)] / h
//   w(i,j,k) = [Y(i+1,j,k) - Y(i,j,k) - X(i,j+1,k) + X(i,j,k)] / h
// with X, Y, Z the differences psi1 - psi0 on the x-, y-, z-edges (periodic: indices wrap).
template <class T>
void add_discrete_curl(const std::array<AlignedVector<T>, 3>& psi1,
                       const std::array<AlignedVector<T>, 3>& psi0, MacGrid<T>& u) {
  const GridGeometry& geo = u.geo;
  const double inv_h = 1.0 / geo.h;
  const std::array<Shape3, 3> es{edge_shape(geo, 0), edge_shape(geo, 1), edge_shape(geo, 2)};
  // The row (i, j) of the edges along axis a (periodic: indices wrap), and psi1 - psi0 at its k.
  struct EdgeRow {
    const T *p1, *p0;
    double operator()(int k) const { return double(p1[k]) - double(p0[k]); }
  };
  auto row = [&](int a, int i, int j) {
    if (geo.periodic) {
      i %= geo.nx;
      j %= geo.ny;
    }
    const std::size_t e = es[a].index(i, j, 0);
    return EdgeRow{psi1[a].data() + e, psi0[a].data() + e};
  };
  // (the two edge axes p, q of face axis c, as in the formulas above: c = 0 -> Z, Y; ...)
  for (int c = 0; c < 3; ++c) {
    const Shape3 s = u.shape[c];
    T* q = u.comp[c].data();
    parallel_for(Index(s.n[0]), [&](Index ii) {
      const int i = int(ii);
      for (int j = 0; j < s.n[1]; ++j) {
        // the rows the four edges of face (i, j, k) lie on; along k, k + 1 wraps when periodic
        const EdgeRow a =
            row(c == 0 ? 2 : (c == 1 ? 0 : 1), c == 2 ? i + 1 : i, c == 0 ? j + 1 : j);
        const EdgeRow b = row(c == 0 ? 2 : (c == 1 ? 0 : 1), i, j);
        const EdgeRow e =
            row(c == 0 ? 1 : (c == 1 ? 2 : 0), c == 1 ? i + 1 : i, c == 2 ? j + 1 : j);
        const EdgeRow f = row(c == 0 ? 1 : (c == 1 ? 2 : 0), i, j);
        T* out = q + s.index(i, j, 0);
        for (int k = 0; k < s.n[2]; ++k) {
          const int k1 = geo.periodic && k + 1 == geo.nz ? 0 : k + 1;
          double curl;
          if (c == 0)  // Z(i, j+1, k) - Z(i, j, k) - Y(i, j, k+1) + Y(i, j, k)
            curl = a(k) - b(k) - f(k1) + f(k);
          else if (c == 1)  // X(i, j, k+1) - X(i, j, k) - Z(i+1, j, k) + Z(i, j, k)
            curl = a(k1) - b(k) - e(k) + f(k);
          else  // Y(i+1, j, k) - Y(i, j, k) - X(i, j+1, k) + X(i, j, k)
            curl = a(k) - b(k) - e(k) + f(k);
          out[k] = T(double(out[k]) + curl * inv_h);
        }
      }
    });
  }
}

#define FLAGSIM_INSTANTIATE_TURBULENCE(T)                                                 \
  template void CurlNoise::potential_on_edges<T>(const GridGeometry&, double, EdgeNoise&, \
                                                 std::array<AlignedVector<T>, 3>&) const; \
  template void add_discrete_curl<T>(const std::array<AlignedVector<T>, 3>&,              \
                                     const std::array<AlignedVector<T>, 3>&, MacGrid<T>&);
FLAGSIM_INSTANTIATE_TURBULENCE(float)
FLAGSIM_INSTANTIATE_TURBULENCE(double)

}  // namespace flagsim
