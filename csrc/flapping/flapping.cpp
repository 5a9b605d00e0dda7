#include "flapping/flapping.h"

#include <algorithm>

#include "common/parallel.h"

namespace flagsim {

namespace {
// C1 smoothstep S(u) = 3u^2 - 2u^3 of u clamped to [0, 1]: 0 and flat at 0, 1 and flat at 1.
inline double smoothstep(double u) {
  u = std::clamp(u, 0.0, 1.0);
  return u * u * (3.0 - 2.0 * u);
}
}  // namespace

double flapping_ramp(double L, const FlappingParams& p) {
  return p.amplitude * smoothstep(L / p.l_max);
}

double flapping_fade_in(double t, const FlappingParams& p) {
  return p.ramp > 0 ? smoothstep(t / p.ramp) : 1.0;
}

void flapping_displacement(const Perlin1D& noise, const MatX2& xy, const VecX& L, double u_p,
                           double t, const FlappingParams& p, VecX& z) {
  const Index n = xy.rows();
  if (z.size() != n) z.resize(n);
  const double shift = p.speed * t, fade = u_p * flapping_fade_in(t, p);
  parallel_for(n, [&](Index i) {
    const double x = xy(i, 0), y = xy(i, 1);
    const double phase = x - shift - p.parabola * (1.0 - y) * y;
    z[i] = fade * flapping_ramp(L[i], p) * noise(p.frequency * phase);
  });
}

}  // namespace flagsim
