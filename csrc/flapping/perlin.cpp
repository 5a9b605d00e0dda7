#include "flapping/perlin.h"

#include <cmath>
#include <numeric>
#include <utility>

namespace flagsim {

namespace {
// splitmix64 (Steele, Lea, Flood, OOPSLA 2014), the generator named in perlin_permutation().
uint64_t splitmix64(uint64_t& state) {
  uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
}  // namespace

std::array<uint8_t, 256> perlin_permutation(uint32_t seed) {
  std::array<uint8_t, 256> p{};
  std::iota(p.begin(), p.end(), uint8_t{0});
  uint64_t state = seed;
  for (int k = 255; k >= 1; --k) {
    const auto j = static_cast<int>(splitmix64(state) % static_cast<uint64_t>(k + 1));
    std::swap(p[k], p[j]);
  }
  return p;
}

Perlin1D::Perlin1D(uint32_t seed) : seed_(seed), perm_(perlin_permutation(seed)) {}

double Perlin1D::gradient(int64_t i) const {
  const unsigned h = perm_[static_cast<size_t>(i & 255)];
  const double magnitude = 1.0 - 0.25 * static_cast<double>((h >> 1) & 3u);
  return (h & 1u) ? -magnitude : magnitude;
}

double Perlin1D::operator()(double x) const {
  const double xi = std::floor(x);
  const double f = x - xi;
  // fmod keeps the lattice index exact for any finite x (no int64 overflow); & 255 maps
  // negative remainders to i mod 256.
  const auto i = static_cast<int64_t>(std::fmod(xi, 256.0));
  const double s = perlin_fade(f);
  return 2.0 * ((1.0 - s) * gradient(i) * f + s * gradient(i + 1) * (f - 1.0));
}

}  // namespace flagsim
