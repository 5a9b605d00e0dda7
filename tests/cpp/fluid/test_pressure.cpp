#include "fluid/pressure.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "common/simd.h"

namespace flagsim {

namespace {

GridGeometry geometry(int nx, int ny, int nz, bool periodic) {
  GridGeometry g;
  g.nx = nx;
  g.ny = ny;
  g.nz = nz;
  g.h = 0.1;
  g.origin = Vec3::Zero();
  g.periodic = periodic;
  return g;
}

template <class T>
MacGrid<T> random_field(const GridGeometry& g, unsigned seed) {
  MacGrid<T> u(g);
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (auto& c : u.comp)
    for (T& x : c) x = T(normal(rng));
  return u;
}

template <class A, class B>
bool same_bits(const A& a, const B& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0;
}

// The MAC divergence written out cell by cell: the formula the kernels vectorise.
template <class T>
std::vector<T> divergence_by_cells(const MacGrid<T>& u, std::size_t stride, double scale) {
  const GridGeometry& g = u.geo;
  std::vector<T> d(std::size_t(g.nx) * g.ny * stride, T(0));
  for (int i = 0; i < g.nx; ++i)
    for (int j = 0; j < g.ny; ++j)
      for (int k = 0; k < g.nz; ++k) {
        const int ip = g.periodic && i + 1 == g.nx ? 0 : i + 1;
        const int jp = g.periodic && j + 1 == g.ny ? 0 : j + 1;
        const int kp = g.periodic && k + 1 == g.nz ? 0 : k + 1;
        const T v = T(((double(u.at(0, ip, j, k)) - u.at(0, i, j, k)) +
                       (double(u.at(1, i, jp, k)) - u.at(1, i, j, k)) +
                       (double(u.at(2, i, j, kp)) - u.at(2, i, j, k))) *
                      (1.0 / g.h));
        d[(std::size_t(i) * g.ny + j) * stride + k] = scale == 0 ? v : T(scale * v);
      }
  return d;
}

template <class T>
void expect_divergence_bits_at_every_width() {
  for (const bool periodic : {true, false})
    for (const auto& n :
         {std::array<int, 3>{5, 6, 7}, std::array<int, 3>{4, 3, 16}, std::array<int, 3>{3, 4, 2},
          std::array<int, 3>{2, 5, 12}, std::array<int, 3>{3, 2, 32}}) {
      const GridGeometry g = geometry(n[0], n[1], n[2], periodic);
      const MacGrid<T> u = random_field<T>(g, 3);
      for (const int stride : {0, n[2] + 3})
        for (const double scale : {0.0, -0.01}) {
          const std::size_t s = stride > 0 ? std::size_t(stride) : std::size_t(n[2]);
          const std::vector<T> expected = divergence_by_cells(u, s, scale);
          for (const int cap : {0, 16}) {
            vector_bytes(cap);
            std::vector<T> got(expected.size(), T(0));
            divergence(u, got.data(), stride, scale);
            vector_bytes(0);
            EXPECT_TRUE(same_bits(expected, got))
                << n[0] << "x" << n[1] << "x" << n[2] << (periodic ? " periodic" : " tunnel")
                << " stride " << stride << " scale " << scale << " vector cap " << cap;
          }
        }
    }
}

template <class T>
void expect_periodic_gradient_bits_at_every_width() {
  for (const auto& n :
       {std::array<int, 3>{5, 6, 7}, std::array<int, 3>{4, 3, 16}, std::array<int, 3>{3, 4, 2},
        std::array<int, 3>{2, 5, 9}, std::array<int, 3>{3, 2, 32}}) {
    const GridGeometry g = geometry(n[0], n[1], n[2], true);
    const MacGrid<T> u0 = random_field<T>(g, 4);
    for (const int stride : {0, n[2] + 2}) {
      const std::size_t s = stride > 0 ? std::size_t(stride) : std::size_t(n[2]);
      std::vector<T> phi(s * std::size_t(n[0] * n[1]));
      std::mt19937 rng(9);
      std::normal_distribution<double> normal(0.0, 1.0);
      for (T& x : phi) x = T(normal(rng));
      MacGrid<T> expected = u0;
      subtract_gradient(phi.data(), expected, stride);  // the general (scalar) kernel
      for (const int cap : {0, 16}) {
        vector_bytes(cap);
        MacGrid<T> got = u0;
        EXPECT_TRUE(subtract_gradient_periodic(phi.data(), stride, got));
        // A non-finite new value anywhere is seen: at the ends of the w rows (face 0, which
        // wraps, and the last face) and inside.
        for (int c = 0; c < 3; ++c)
          for (const std::size_t at : {std::size_t(0), std::size_t(n[2] - 1), std::size_t(n[2] / 2),
                                       got.comp[c].size() - 1}) {
            MacGrid<T> bad = u0;
            bad.comp[c][at] = std::numeric_limits<T>::infinity();
            EXPECT_FALSE(subtract_gradient_periodic(phi.data(), stride, bad))
                << "component " << c << " at " << at << " vector cap " << cap;
          }
        vector_bytes(0);
        for (int c = 0; c < 3; ++c)
          EXPECT_TRUE(same_bits(expected.comp[c], got.comp[c]))
              << n[0] << "x" << n[1] << "x" << n[2] << " stride " << stride << " component " << c
              << " vector cap " << cap;
      }
    }
  }
}

}  // namespace

// The divergence kernel (a plane per call, vectors of doubles with the periodic row's last cell
// by a shuffle) gives the cell-by-cell formula's bits at both vector widths, periodic and
// bounded, rows padded or not, scaled or not, rows shorter than a vector and not a multiple of
// one, and rows of 16 and 32 (the AVX code's unrolled rows).
TEST(MacDivergence, GivesTheCellFormulasBitsAtEveryWidth) {
  expect_divergence_bits_at_every_width<double>();
}

TEST(MacDivergence, GivesTheCellFormulasBitsAtEveryWidthOnAFloatGrid) {
  expect_divergence_bits_at_every_width<float>();
}

// The periodic gradient pass (a plane per call, the w row's wrapped face 0 in its first vector)
// gives the general kernel's bits, and its finiteness check sees every face.
TEST(SubtractGradientPeriodic, GivesTheGeneralKernelsBitsAtEveryWidth) {
  expect_periodic_gradient_bits_at_every_width<double>();
}

TEST(SubtractGradientPeriodic, GivesTheGeneralKernelsBitsAtEveryWidthOnAFloatGrid) {
  expect_periodic_gradient_bits_at_every_width<float>();
}

#ifdef FLAGSIM_HAVE_FFTW
// The fft projection's spectral division (factors on vectors, then the modes as pairs of reals)
// gives the same bits at both widths.
TEST(FftProjector, ProjectsWithTheSameBitsAtEveryWidth) {
  for (const auto& n : {std::array<int, 3>{6, 5, 14}, std::array<int, 3>{4, 4, 4}}) {
    const GridGeometry g = geometry(n[0], n[1], n[2], true);
    const MacGrid<double> u0 = random_field<double>(g, 6);
    std::array<MacGrid<double>, 2> out = {u0, u0};
    for (const int cap : {0, 16}) {
      vector_bytes(cap);
      FftProjector<double> fft(g);
      EXPECT_TRUE(fft.project(out[cap == 0 ? 0 : 1]));
      vector_bytes(0);
    }
    for (int c = 0; c < 3; ++c) EXPECT_TRUE(same_bits(out[0].comp[c], out[1].comp[c]));
    std::vector<double> div(g.cells().size());
    divergence(out[0], div.data());
    for (const double d : div) EXPECT_LT(std::fabs(d), 1e-10);
  }
}
#endif

}  // namespace flagsim
