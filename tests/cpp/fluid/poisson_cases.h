// Poisson problems shared by the pressure-solve tests (test_poisson.cpp, test_multigrid.cpp):
// pressure-like operators, solid masks, consistent right-hand sides and an independent residual.
#pragma once
#include <algorithm>
#include <cmath>
#include <random>

#include "fluid/poisson.h"

namespace flagsim::poisson_cases {

inline Laplace7 pressure_like(int nx, int ny, int nz, bool tunnel) {
  Laplace7 op;
  op.shape = Shape3{{nx, ny, nz}};
  if (tunnel) {  // as pressure_operator: Neumann walls and inflow, p = 0 beyond the outflow
    for (int d = 0; d < 3; ++d) op.lo[d] = op.hi[d] = Side::kNeumann;
    op.hi[0] = Side::kGhostZero;
  }
  return op;
}

/// A box of solid cells (the bench's: a plate across the middle half, an eighth of the length
/// thick, a quarter of the way down the x axis).
inline AlignedVector<uint8_t> box_mask(const Shape3& sh) {
  AlignedVector<uint8_t> m(sh.size(), 0);
  const int nx = sh.n[0], ny = sh.n[1], nz = sh.n[2];
  for (int i = nx / 4; i < nx / 4 + std::max(1, nx / 8); ++i)
    for (int j = ny / 4; j < 3 * ny / 4; ++j)
      for (int k = nz / 4; k < 3 * nz / 4; ++k) m[sh.index(i, j, k)] = 1;
  return m;
}

/// About `fraction` of the cells solid, scattered (a hard case: many thin walls and pockets).
inline AlignedVector<uint8_t> random_mask(const Shape3& sh, double fraction, unsigned seed) {
  std::mt19937 rng(seed);
  std::bernoulli_distribution solid(fraction);
  AlignedVector<uint8_t> m(sh.size());
  for (auto& v : m) v = solid(rng) ? 1 : 0;
  return m;
}

template <class T>
AlignedVector<T> random_vector(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  AlignedVector<T> v(n);
  for (auto& x : v) x = T(u(rng));
  return v;
}

/// A right-hand side the solve can meet: 0 on solid cells and, for a singular K, with zero sum
/// over each pocket of fluid that no Dirichlet side reaches (here: over all fluid cells, the
/// masks below leave one pocket).
template <class T>
AlignedVector<T> consistent_rhs(const Laplace7& op, unsigned seed) {
  AlignedVector<T> b = random_vector<T>(op.shape.size(), seed);
  double sum = 0, count = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (op.is_solid(i)) b[i] = T(0);
    sum += double(b[i]);
    count += op.is_solid(i) ? 0 : 1;
  }
  if (op.singular())
    for (std::size_t i = 0; i < b.size(); ++i)
      if (!op.is_solid(i)) b[i] = T(double(b[i]) - sum / count);
  return b;
}

inline double dot(const AlignedVector<double>& a, const AlignedVector<double>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
  return s;
}

/// max |K x - b| over the fluid cells, K applied by apply_laplace7 (the reference operator).
template <class T>
double residual(const Laplace7& op, const AlignedVector<T>& x, const AlignedVector<T>& b) {
  AlignedVector<double> xd(x.begin(), x.end()), y(x.size());
  apply_laplace7(op, 0.0, 1.0, xd.data(), y.data());
  double m = 0;
  for (std::size_t i = 0; i < y.size(); ++i)
    if (!op.is_solid(i)) m = std::max(m, std::fabs(y[i] - double(b[i])));
  return m;
}

template <class T>
double max_abs(const AlignedVector<T>& v) {
  double m = 0;
  for (T x : v) m = std::max(m, std::fabs(double(x)));
  return m;
}

/// Solution minus its mean over the fluid cells (a singular K fixes x up to that constant).
template <class T>
AlignedVector<double> without_mean(const Laplace7& op, const AlignedVector<T>& x) {
  double s = 0, n = 0;
  for (std::size_t i = 0; i < x.size(); ++i)
    if (!op.is_solid(i)) {
      s += double(x[i]);
      n += 1;
    }
  AlignedVector<double> out(x.size(), 0.0);
  for (std::size_t i = 0; i < x.size(); ++i)
    if (!op.is_solid(i)) out[i] = double(x[i]) - (op.singular() ? s / n : 0.0);
  return out;
}

}  // namespace flagsim::poisson_cases
