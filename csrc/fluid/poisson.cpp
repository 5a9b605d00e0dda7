#include "fluid/poisson.h"
#include "common/parallel.h"
#include "fluid/multigrid.h"

#include <algorithm>
#include <cmath>

namespace flagsim {

namespace {

constexpr double kMicTau = 0.97;    // Bridson §5.4: modified incomplete Cholesky weight
constexpr double kMicSigma = 0.25;  // safety: fall back to the plain diagonal below this

/// Neighbour of node i along an axis of n nodes, -1 when there is none (beyond a non-periodic end).
inline int neighbour(int i, int step, int n, Side lo, Side hi) {
  const int m = i + step;
  if (m < 0) return lo == Side::kPeriodic ? m + n : -1;
  if (m >= n) return hi == Side::kPeriodic ? m - n : -1;
  return m;
}

/// Diagonal of K at node (i, j, k): one per existing neighbour that is not the node itself, one
/// per GhostZero side it touches.
inline double diag_k(const Laplace7& op, const int ijk[3]) {
  double d = 0;
  for (int a = 0; a < 3; ++a) {
    const int n = op.shape.n[a];
    for (int s = -1; s <= 1; s += 2) {
      const int m = neighbour(ijk[a], s, n, op.lo[a], op.hi[a]);
      if (m >= 0)
        d += (m != ijk[a]) ? 1.0 : 0.0;
      else
        d += ((s < 0 ? op.lo[a] : op.hi[a]) == Side::kGhostZero) ? 1.0 : 0.0;
    }
  }
  return d;
}

template <class T>
double max_abs(const T* x, std::size_t n) {
  return parallel_max(n, [&](std::size_t i) { return std::fabs(double(x[i])); });
}

template <class T>
double dot(const T* a, const T* b, std::size_t n) {
  return deterministic_sum(n, [&](std::size_t i) { return double(a[i]) * double(b[i]); });
}

/// Zeroes fixed nodes of x.
template <class T>
void zero_fixed(const Laplace7& op, T* x) {
  const Shape3& sh = op.shape;
  for (int d = 0; d < 3; ++d) {
    for (int end = 0; end < 2; ++end) {
      if ((end == 0 ? op.lo[d] : op.hi[d]) != Side::kFixed) continue;
      const int fixed_index = end == 0 ? 0 : sh.n[d] - 1;
      for (int a = 0; a < sh.n[0]; ++a)
        for (int b = 0; b < sh.n[1]; ++b)
          for (int c = 0; c < sh.n[2]; ++c) {
            const int ijk[3] = {a, b, c};
            if (ijk[d] == fixed_index) x[sh.index(a, b, c)] = T(0);
          }
    }
  }
}

/// diag_k with solids: only fluid neighbours couple (ghosts lie outside the grid, never solid).
inline double diag_k_masked(const Laplace7& op, const int ijk[3]) {
  double d = 0;
  for (int a = 0; a < 3; ++a) {
    const int n = op.shape.n[a];
    for (int s = -1; s <= 1; s += 2) {
      const int m = neighbour(ijk[a], s, n, op.lo[a], op.hi[a]);
      if (m >= 0) {
        int q[3] = {ijk[0], ijk[1], ijk[2]};
        q[a] = m;
        d += (m != ijk[a] && !op.solid[op.shape.index(q[0], q[1], q[2])]) ? 1.0 : 0.0;
      } else {
        d += ((s < 0 ? op.lo[a] : op.hi[a]) == Side::kGhostZero) ? 1.0 : 0.0;
      }
    }
  }
  return d;
}

/// Zeroes solid nodes of x (nothing without a mask).
template <class T>
void zero_solid(const Laplace7& op, T* x) {
  if (!op.solid) return;
  const uint8_t* s = op.solid;
  parallel_for_cells(long(op.shape.size()), [&](Index i) {
    if (s[i]) x[i] = T(0);
  });
}

/// Mean of x over the fluid nodes (all nodes without a mask), in a fixed order.
template <class T>
double fluid_mean(const Laplace7& op, const T* x, std::size_t n_fluid) {
  const std::size_t n = op.shape.size();
  if (!op.solid)
    return deterministic_sum(n, [&](std::size_t i) { return double(x[i]); }) / double(n);
  const uint8_t* s = op.solid;
  return deterministic_sum(n, [&](std::size_t i) { return s[i] ? 0.0 : double(x[i]); }) /
         double(n_fluid);
}

/// x <- x - m on the fluid nodes (solid nodes stay 0).
template <class T>
void subtract_on_fluid(const Laplace7& op, T* x, double m) {
  const long n = long(op.shape.size());
  if (!op.solid) {
    parallel_for_cells(n, [&](Index i) { x[i] = T(x[i] - m); });
    return;
  }
  const uint8_t* s = op.solid;
  parallel_for_cells(n, [&](Index i) { x[i] = s[i] ? T(0) : T(x[i] - m); });
}

/// y on one (i, j) row of apply_laplace7 with solids: a solid node gives 0, a face to a solid
/// neighbour no term (zero flux), a missing neighbour beyond a GhostZero side x_c.
template <class T>
void apply_row_masked(const Laplace7& op, double alpha, double beta, const T* x, T* y, int i,
                      int j) {
  const Shape3& sh = op.shape;
  const int n0 = sh.n[0], n1 = sh.n[1], n2 = sh.n[2];
  const std::size_t row = sh.index(i, j, 0);
  const uint8_t* sr = op.solid + row;
  const T* xr = x + row;
  T* yr = y + row;
  const int im = neighbour(i, -1, n0, op.lo[0], op.hi[0]);
  const int ip = neighbour(i, +1, n0, op.lo[0], op.hi[0]);
  const int jm = neighbour(j, -1, n1, op.lo[1], op.hi[1]);
  const int jp = neighbour(j, +1, n1, op.lo[1], op.hi[1]);
  const int nbr[4] = {im, ip, jm, jp};
  const std::size_t nbrow[4] = {im >= 0 ? sh.index(im, j, 0) : 0, ip >= 0 ? sh.index(ip, j, 0) : 0,
                                jm >= 0 ? sh.index(i, jm, 0) : 0, jp >= 0 ? sh.index(i, jp, 0) : 0};
  const bool self[4] = {im == i, ip == i, jm == j, jp == j};
  double ghost = 0;
  if (im < 0 && op.lo[0] == Side::kGhostZero) ghost += 1;
  if (ip < 0 && op.hi[0] == Side::kGhostZero) ghost += 1;
  if (jm < 0 && op.lo[1] == Side::kGhostZero) ghost += 1;
  if (jp < 0 && op.hi[1] == Side::kGhostZero) ghost += 1;
  for (int k = 0; k < n2; ++k) {
    if (sr[k] || op.fixed(2, k)) {
      yr[k] = T(0);
      continue;
    }
    const double xc = xr[k];
    double acc = 0, g = ghost;
    for (int q = 0; q < 4; ++q)
      if (nbr[q] >= 0 && !self[q] && !op.solid[nbrow[q] + k]) acc += xc - x[nbrow[q] + k];
    const int km = neighbour(k, -1, n2, op.lo[2], op.hi[2]);
    const int kp = neighbour(k, +1, n2, op.lo[2], op.hi[2]);
    if (km >= 0) {
      if (km != k && !sr[km]) acc += xc - xr[km];
    } else if (op.lo[2] == Side::kGhostZero) {
      g += 1;
    }
    if (kp >= 0) {
      if (kp != k && !sr[kp]) acc += xc - xr[kp];
    } else if (op.hi[2] == Side::kGhostZero) {
      g += 1;
    }
    acc += g * xc;
    yr[k] = T(alpha * xc + beta * acc);
  }
}

}  // namespace

bool Laplace7::singular() const {
  for (int d = 0; d < 3; ++d)
    for (Side s : {lo[d], hi[d]})
      if (s == Side::kGhostZero || s == Side::kFixed) return false;
  return true;
}

template <class T>
void apply_laplace7(const Laplace7& op, double alpha, double beta, const T* x, T* y) {
  const Shape3& sh = op.shape;
  const int n0 = sh.n[0], n1 = sh.n[1], n2 = sh.n[2];
  const long rows = long(n0) * n1;
  const double ghost_lo2 = op.lo[2] == Side::kGhostZero ? 1.0 : 0.0;
  const double ghost_hi2 = op.hi[2] == Side::kGhostZero ? 1.0 : 0.0;
  parallel_for_if(Index(sh.size()) > kGridParallelGrain, rows, [&](Index r) {
    const int i = int(r / n1), j = int(r % n1);
    T* yr = y + std::size_t(r) * n2;
    if (op.fixed(0, i) || op.fixed(1, j)) {
      std::fill(yr, yr + n2, T(0));
      return;
    }
    if (op.solid) {
      apply_row_masked(op, alpha, beta, x, y, i, j);
      return;
    }
    const T* xr = x + std::size_t(r) * n2;
    const int im = neighbour(i, -1, n0, op.lo[0], op.hi[0]);
    const int ip = neighbour(i, +1, n0, op.lo[0], op.hi[0]);
    const int jm = neighbour(j, -1, n1, op.lo[1], op.hi[1]);
    const int jp = neighbour(j, +1, n1, op.lo[1], op.hi[1]);
    const T* nb[4] = {
        im >= 0 ? x + sh.index(im, j, 0) : nullptr, ip >= 0 ? x + sh.index(ip, j, 0) : nullptr,
        jm >= 0 ? x + sh.index(i, jm, 0) : nullptr, jp >= 0 ? x + sh.index(i, jp, 0) : nullptr};
    // Missing neighbours contribute x_c (GhostZero) or nothing (Neumann): a constant count.
    double ghost = 0;
    if (im < 0 && op.lo[0] == Side::kGhostZero) ghost += 1;
    if (ip < 0 && op.hi[0] == Side::kGhostZero) ghost += 1;
    if (jm < 0 && op.lo[1] == Side::kGhostZero) ghost += 1;
    if (jp < 0 && op.hi[1] == Side::kGhostZero) ghost += 1;
    for (int k = 0; k < n2; ++k) {
      if (op.fixed(2, k)) {
        yr[k] = T(0);
        continue;
      }
      const double xc = xr[k];
      double acc = 0;
      for (int q = 0; q < 4; ++q)
        if (nb[q]) acc += xc - nb[q][k];
      const int km = neighbour(k, -1, n2, op.lo[2], op.hi[2]);
      const int kp = neighbour(k, +1, n2, op.lo[2], op.hi[2]);
      double g = ghost;
      if (km >= 0)
        acc += xc - xr[km];
      else
        g += ghost_lo2;
      if (kp >= 0)
        acc += xc - xr[kp];
      else
        g += ghost_hi2;
      acc += g * xc;
      yr[k] = T(alpha * xc + beta * acc);
    }
  });
}

template <class T>
void MicPreconditioner<T>::build(const Laplace7& k) {
  op = k;
  const Shape3& sh = op.shape;
  inv_diag.assign(sh.size(), T(0));
  plus.assign(sh.size(), 0);
  const std::size_t stride[3] = {std::size_t(sh.n[1]) * sh.n[2], std::size_t(sh.n[2]), 1};
  // Fluid node along axis a at index m (wrapped) from node n: without solids, every node.
  auto fluid_at = [&](std::size_t n, int a, int from, int m) {
    return !op.solid || !op.solid[n + (std::ptrdiff_t(m) - from) * std::ptrdiff_t(stride[a])];
  };
  // The factored matrix: K with wrap couplings moved to the diagonal (diag = 2 per periodic axis
  // without solids, one per fluid neighbour with them).
  auto adiag = [&](const int ijk[3], std::size_t n) {
    double d = 0;
    for (int a = 0; a < 3; ++a) {
      const int na = sh.n[a];
      if (op.lo[a] == Side::kPeriodic) {
        if (!op.solid) {
          d += 2;
          continue;
        }
        d += fluid_at(n, a, ijk[a], ijk[a] > 0 ? ijk[a] - 1 : na - 1) ? 1.0 : 0.0;
        d += fluid_at(n, a, ijk[a], ijk[a] < na - 1 ? ijk[a] + 1 : 0) ? 1.0 : 0.0;
        continue;
      }
      d += ijk[a] > 0 ? (fluid_at(n, a, ijk[a], ijk[a] - 1) ? 1.0 : 0.0)
                      : (op.lo[a] == Side::kGhostZero ? 1.0 : 0.0);
      d += ijk[a] < na - 1 ? (fluid_at(n, a, ijk[a], ijk[a] + 1) ? 1.0 : 0.0)
                           : (op.hi[a] == Side::kGhostZero ? 1.0 : 0.0);
    }
    return d;
  };
  for (int i = 0; i < sh.n[0]; ++i)
    for (int j = 0; j < sh.n[1]; ++j)
      for (int kk = 0; kk < sh.n[2]; ++kk) {
        const int ijk[3] = {i, j, kk};
        const std::size_t n = sh.index(i, j, kk);
        if (op.is_solid(n)) continue;  // plus 0, inv_diag 0: z = 0 there, no coupling to it
        uint8_t bits = 0;
        for (int a = 0; a < 3; ++a)
          if (ijk[a] < sh.n[a] - 1 && fluid_at(n, a, ijk[a], ijk[a] + 1)) bits |= uint8_t(1u << a);
        plus[n] = bits;
        const double a_diag = adiag(ijk, n);
        double e = a_diag;
        for (int a = 0; a < 3; ++a) {
          if (ijk[a] == 0) continue;
          const std::size_t m = n - stride[a];
          if (!(plus[m] & (1u << a))) continue;
          const double pm = inv_diag[m];
          e -= pm * pm;       // (A_plus,a(m) precon(m))^2 with A_plus = -1
          double others = 0;  // sum of the other A_plus of m, each -1 when coupled
          for (int b = 0; b < 3; ++b)
            if (b != a && (plus[m] & (1u << b))) others -= 1.0;
          e -= kMicTau * (-1.0) * others * pm * pm;
        }
        if (e < kMicSigma * a_diag) e = a_diag;
        inv_diag[n] = T(e > 0 ? 1.0 / std::sqrt(e) : 0.0);
      }
}

template <class T>
void MicPreconditioner<T>::apply(const T* r, T* z) const {
  const Shape3& sh = op.shape;
  const std::size_t stride[3] = {std::size_t(sh.n[1]) * sh.n[2], std::size_t(sh.n[2]), 1};
  const int n0 = sh.n[0], n1 = sh.n[1], n2 = sh.n[2];
  // Solve L q = r (q stored in z), L lower: L(n, m) = A_plus(m) precon(m) for m = n - stride.
  std::size_t n = 0;
  for (int i = 0; i < n0; ++i)
    for (int j = 0; j < n1; ++j)
      for (int k = 0; k < n2; ++k, ++n) {
        double t = r[n];
        if (i > 0 && (plus[n - stride[0]] & 1u))
          t += double(inv_diag[n - stride[0]]) * z[n - stride[0]];
        if (j > 0 && (plus[n - stride[1]] & 2u))
          t += double(inv_diag[n - stride[1]]) * z[n - stride[1]];
        if (k > 0 && (plus[n - 1] & 4u)) t += double(inv_diag[n - 1]) * z[n - 1];
        z[n] = T(t * inv_diag[n]);
      }
  // Solve L^T z = q in reverse order.
  for (int i = n0 - 1; i >= 0; --i)
    for (int j = n1 - 1; j >= 0; --j)
      for (int k = n2 - 1; k >= 0; --k) {
        n = sh.index(i, j, k);
        double t = z[n];
        const double pn = inv_diag[n];
        if (plus[n] & 1u) t += pn * z[n + stride[0]];
        if (plus[n] & 2u) t += pn * z[n + stride[1]];
        if (plus[n] & 4u) t += pn * z[n + 1];
        z[n] = T(t * pn);
      }
}

namespace {

/// Conjugate gradient on the unknown nodes of A = (alpha I + beta K) (alpha = 0: A may be
/// singular, see Laplace7::singular): product(x, y) is y = A x
/// (called with x = 0 on solid nodes), precondition(r, z) is z = M^-1 r (fixed and solid nodes
/// of z are zeroed after it, and for a singular K its mean over the fluid nodes is removed).
template <class T, class Product, class Precondition>
CgResult conjugate_gradient(const Laplace7& op, double alpha, const T* b, T* x, double tol,
                            int max_iter, const Product& product,
                            const Precondition& precondition_raw, CgScratch<T>& w) {
  const Shape3& sh = op.shape;
  const std::size_t n = sh.size();
  T* r = w.r.data();
  T* z = w.z.data();
  T* s = w.s.data();
  T* q = w.q.data();
  const bool singular = alpha == 0 && op.singular();
  CgResult res;
  std::size_t n_fluid = n;
  if (op.solid) {
    n_fluid =
        std::size_t(deterministic_sum(n, [&](std::size_t i) { return op.solid[i] ? 0.0 : 1.0; }));
    zero_solid(op, x);  // not unknowns: phi = 0 there
  }

  // r = b - A x on unknown nodes (fixed nodes of x couple in through A x), 0 on fixed ones.
  product(x, q);
  parallel_for_cells(long(n), [&](Index i) { r[i] = T(double(b[i]) - double(q[i])); });
  zero_fixed(op, r);
  zero_solid(op, r);
  double b_max = 0;
  if (singular) {
    // Constants are K's null space: solve for the zero-mean part (b - A x sums to 0 exactly in
    // exact arithmetic; remove what round-off left). max|b| is measured on b - mean(b).
    const double mr = fluid_mean(op, r, n_fluid);
    const double mb = fluid_mean(op, b, n_fluid);
    subtract_on_fluid(op, r, mr);
    if (op.solid)
      b_max = parallel_max(
          n, [&](std::size_t i) { return op.solid[i] ? 0.0 : std::fabs(double(b[i]) - mb); });
    else
      b_max = parallel_max(n, [&](std::size_t i) { return std::fabs(double(b[i]) - mb); });
  } else {
    // b on fixed and solid nodes is not part of the system.
    std::copy(b, b + n, z);
    zero_fixed(op, z);
    zero_solid(op, z);
    b_max = max_abs(z, n);
  }
  double r_max = max_abs(r, n);
  if (b_max == 0 || r_max <= tol * b_max) {
    res.residual = b_max == 0 ? 0.0 : r_max / b_max;
    return res;
  }

  auto precondition = [&](const T* in, T* out) {
    precondition_raw(in, out);
    zero_fixed(op, out);
    if (singular) {
      subtract_on_fluid(op, out, fluid_mean(op, out, n_fluid));
    } else {
      zero_solid(op, out);
    }
  };

  precondition(r, z);
  std::copy(z, z + n, s);
  double sigma = dot(r, z, n);
  for (int it = 1; it <= max_iter; ++it) {
    product(s, q);
    const double sq = dot(s, q, n);
    if (!(sq > 0)) {  // breakdown (converged to round-off, or not SPD): stop here
      res.iterations = it;
      break;
    }
    const double a = sigma / sq;
    parallel_for_cells(long(n), [&](Index i) {
      x[i] = T(x[i] + a * s[i]);
      r[i] = T(r[i] - a * q[i]);
    });
    res.iterations = it;
    r_max = max_abs(r, n);
    if (r_max <= tol * b_max) break;
    precondition(r, z);
    const double sigma_new = dot(r, z, n);
    const double beta_cg = sigma_new / sigma;
    sigma = sigma_new;
    parallel_for_cells(long(n), [&](Index i) { s[i] = T(z[i] + beta_cg * s[i]); });
  }
  res.residual = r_max / b_max;
  res.converged = r_max <= tol * b_max;
  return res;
}

}  // namespace

template <class T>
CgResult solve_cg(const Laplace7& op, double alpha, double beta, const T* b, T* x, double tol,
                  int max_iter, const MicPreconditioner<T>* mic, CgScratch<T>& w) {
  const Shape3& sh = op.shape;
  const std::size_t n = sh.size();
  auto precondition = [&](const T* in, T* out) {
    if (mic) {
      mic->apply(in, out);
    } else {
      const int n1 = sh.n[1], n2 = sh.n[2];
      parallel_for_cells(long(n), [&](Index idx) {
        const int ijk[3] = {int(idx / (long(n1) * n2)), int((idx / n2) % n1), int(idx % n2)};
        if (!op.solid) {
          out[idx] = T(double(in[idx]) / (alpha + beta * diag_k(op, ijk)));
          return;
        }
        const double d = op.solid[idx] ? 0.0 : alpha + beta * diag_k_masked(op, ijk);
        out[idx] = d > 0 ? T(double(in[idx]) / d) : T(0);
      });
    }
  };
  auto product = [&](const T* in, T* out) { apply_laplace7(op, alpha, beta, in, out); };
  return conjugate_gradient(op, alpha, b, x, tol, max_iter, product, precondition, w);
}

template <class T>
CgResult solve_cg(const Laplace7& op, const T* b, T* x, double tol, int max_iter,
                  PoissonMultigrid<T>& mg, CgScratch<T>& w) {
  (void)op;  // mg was built for it
  return mg.solve(b, x, tol, max_iter, w);
}

#define FLAGSIM_INSTANTIATE_POISSON(T)                                                            \
  template void apply_laplace7<T>(const Laplace7&, double, double, const T*, T*);                 \
  template struct MicPreconditioner<T>;                                                           \
  template CgResult solve_cg<T>(const Laplace7&, double, double, const T*, T*, double, int,       \
                                const MicPreconditioner<T>*, CgScratch<T>&);                      \
  template CgResult solve_cg<T>(const Laplace7&, const T*, T*, double, int, PoissonMultigrid<T>&, \
                                CgScratch<T>&);
FLAGSIM_INSTANTIATE_POISSON(float)
FLAGSIM_INSTANTIATE_POISSON(double)

}  // namespace flagsim
