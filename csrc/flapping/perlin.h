// Improved Perlin noise in 1-D (K. Perlin, "Improving Noise", SIGGRAPH 2002): the quintic fade
// and a seeded permutation table; the gradient noise f_n of paper eq. 5.
#pragma once
#include <array>
#include <cstdint>

namespace flagsim {

/// Quintic fade of Perlin 2002: 6t^5 - 15t^4 + 10t^3 (zero first and second derivative at 0, 1).
inline double perlin_fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }

/// The permutation of 0..255 for `seed`: Fisher-Yates, k = 255 down to 1, j = r mod (k + 1),
/// swap P[k] and P[j], where r is the next output of splitmix64 (Steele, Lea, Flood 2014) whose
/// 64-bit state starts at `seed`.
std::array<uint8_t, 256> perlin_permutation(uint32_t seed);

/// 1-D improved Perlin noise:
///   n(x) = 2 [ (1 - s) g_i f + s g_{i+1} (f - 1) ],  i = floor(x), f = x - i, s = perlin_fade(f),
///   g_i = sign * (1 - ((h >> 1) & 3) / 4),  h = P[i mod 256],  sign = -1 when h is odd, else +1.
/// Gradients take the 8 values +-1, +-3/4, +-1/2, +-1/4 (random amplitude, paper §4.2); the factor
/// 2 makes the bound tight: |n| <= 1, reached at f = 1/2 when g_i = -g_{i+1} = +-1.
/// n(i) = 0 at every integer; n is C2. Period 256. Immutable after construction: thread-safe.
class Perlin1D {
 public:
  explicit Perlin1D(uint32_t seed = 0);
  double operator()(double x) const;
  uint32_t seed() const { return seed_; }

 private:
  double gradient(int64_t i) const;
  uint32_t seed_;
  std::array<uint8_t, 256> perm_;
};

}  // namespace flagsim
