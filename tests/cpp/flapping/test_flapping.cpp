#include "flapping/flapping.h"

#include <gtest/gtest.h>

#include <cmath>

#include "common/errors.h"

namespace flagsim {
namespace {

FlappingParams demo_params() {
  FlappingParams p;
  p.mode = FlapMode::kDisplace;
  p.amplitude = 0.02;
  p.l_max = 0.3;
  p.speed = 0.8;
  p.parabola = 1.5;
  p.frequency = 4.0;
  p.seed = 9;
  return p;
}

TEST(FlappingRamp, RisesFromZeroAndIsConstantBeyondLMax) {
  const FlappingParams p = demo_params();
  EXPECT_EQ(flapping_ramp(0.0, p), 0.0);
  EXPECT_DOUBLE_EQ(flapping_ramp(p.l_max, p), p.amplitude);
  for (double L : {0.3, 0.31, 0.5, 1.0, 7.0, 1e6}) EXPECT_EQ(flapping_ramp(L, p), p.amplitude);
  double previous = 0;
  for (int k = 1; k <= 300; ++k) {
    const double a = flapping_ramp(p.l_max * k / 300.0, p);
    EXPECT_GT(a, previous);
    previous = a;
  }
  // Smoothstep: A(l_max / 2) = amplitude / 2, and no kink at l_max.
  EXPECT_DOUBLE_EQ(flapping_ramp(0.5 * p.l_max, p), 0.5 * p.amplitude);
  const double e = 1e-7;
  EXPECT_NEAR((flapping_ramp(p.l_max, p) - flapping_ramp(p.l_max - e, p)) / e, 0.0, 1e-5);
}

// Vertices of a cols x rows flag, rest coordinates normalised as in flapping.h, L from a pinned
// pole edge (x = 0) of a flag of the given length.
struct Grid {
  MatX2 xy;
  VecX L;
};
Grid grid(int cols, int rows, double length) {
  Grid g{MatX2(cols * rows, 2), VecX(cols * rows)};
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const int i = r * cols + c;
      g.xy(i, 0) = c / double(cols - 1);
      g.xy(i, 1) = r / double(rows - 1);
      g.L[i] = g.xy(i, 0) * length;
    }
  return g;
}

TEST(FlappingDisplacement, EqualsEquation5AtEveryVertex) {
  const FlappingParams p = demo_params();
  const Grid g = grid(11, 8, 0.54);
  const Perlin1D noise(p.seed);
  VecX z;
  for (double t : {0.0, 0.37, 2.5}) {
    const double u_p = 2.3;
    flapping_displacement(noise, g.xy, g.L, u_p, t, p, z);
    ASSERT_EQ(z.size(), g.L.size());
    for (Index i = 0; i < z.size(); ++i) {
      const double x = g.xy(i, 0), y = g.xy(i, 1);
      const double u = std::min(g.L[i] / p.l_max, 1.0);
      const double A = p.amplitude * (3 * u * u - 2 * u * u * u);
      const double s = std::min(t / p.ramp, 1.0), fade = s * s * (3 - 2 * s);  // the fade-in
      const double expected =
          fade * u_p * A * noise(p.frequency * (x - p.speed * t - p.parabola * (1 - y) * y));
      EXPECT_NEAR(z[i], expected, 1e-15) << "vertex " << i << " t " << t;
    }
  }
}

TEST(FlappingDisplacement, PinnedEdgeStillAndLinearInAirSpeed) {
  const FlappingParams p = demo_params();
  const Grid g = grid(9, 6, 1.0);
  const Perlin1D noise(p.seed);
  VecX z1, z3;
  flapping_displacement(noise, g.xy, g.L, 1.0, 0.9, p, z1);
  flapping_displacement(noise, g.xy, g.L, 3.0, 0.9, p, z3);
  for (Index i = 0; i < z1.size(); ++i) {
    if (g.L[i] == 0) {
      EXPECT_EQ(z1[i], 0.0);
    }
    EXPECT_NEAR(z3[i], 3 * z1[i], 1e-15);
  }
  EXPECT_GT(z1.cwiseAbs().maxCoeff(), 0.0);
}

TEST(FlappingDisplacement, WaveTravelsAtSpeedVOnParabolicFronts) {
  FlappingParams p = demo_params();
  p.l_max = 1e-9;  // A constant everywhere on this test's points: only the wave is left
  p.ramp = 0.0;    // and no fade-in
  const Perlin1D noise(p.seed);
  MatX2 xy(1, 2), xy2(1, 2);
  const VecX L = VecX::Constant(1, 1.0);
  VecX z, z2;
  for (int k = 0; k < 50; ++k) {
    const double x = 0.02 * k, y = 0.1 + 0.016 * k, t = 0.1 * k, dt = 0.25;
    // Travelling: the value at (x, t) is found at (x + v dt, t + dt).
    xy << x, y;
    xy2 << x + p.speed * dt, y;
    flapping_displacement(noise, xy, L, 1.5, t, p, z);
    flapping_displacement(noise, xy2, L, 1.5, t + dt, p, z2);
    EXPECT_NEAR(z[0], z2[0], 1e-12);
    // Parabolic front: the edge's value (y = 0) is found a (1 - y) y further out at height y.
    xy << x, 0.0;
    xy2 << x + p.parabola * (1 - y) * y, y;
    flapping_displacement(noise, xy, L, 1.5, t, p, z);
    flapping_displacement(noise, xy2, L, 1.5, t, p, z2);
    EXPECT_NEAR(z[0], z2[0], 1e-12);
  }
}

TEST(FlappingDisplacement, FadesInAsASmoothstepOverTheRamp) {
  FlappingParams p = demo_params();
  p.ramp = 0.4;
  FlappingParams full = p;
  full.ramp = 0.0;
  const Grid g = grid(11, 8, 0.54);
  const Perlin1D noise(p.seed);
  VecX z, z_full;
  // S(u) = 3u^2 - 2u^3: 0 at the start, 1/2 half way, 1 from the end of the ramp on
  for (auto [t, S] : {std::pair{0.0, 0.0}, {0.1, 0.15625}, {0.2, 0.5}, {0.4, 1.0}, {3.0, 1.0}}) {
    flapping_displacement(noise, g.xy, g.L, 2.0, t, p, z);
    flapping_displacement(noise, g.xy, g.L, 2.0, t, full, z_full);
    ASSERT_GT(z_full.cwiseAbs().maxCoeff(), 1e-3);
    for (Index i = 0; i < z.size(); ++i) EXPECT_NEAR(z[i], S * z_full[i], 1e-16) << t;
  }
}

TEST(FlappingParams, ValidateNamesTheParameter) {
  FlappingParams p;
  EXPECT_NO_THROW(p.validate("flapping"));
  auto message = [](const FlappingParams& q) {
    try {
      q.validate("flapping");
    } catch (const InvalidArgument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  p.l_max = 0;
  EXPECT_EQ(message(p), "flapping.l_max should be finite and > 0, got 0");
  // a mode is an enum: an unknown name is refused where text becomes one (TOML, Python)
  try {
    parse_enum<FlapMode>("flapping.mode", "wobble");
    ADD_FAILURE() << "no error";
  } catch (const InvalidArgument& e) {
    EXPECT_STREQ(e.what(),
                 "flapping.mode should be one of \"displace\", \"force\", \"visual\", "
                 "\"off\", got \"wobble\"");
  }
  p = FlappingParams{};
  p.amplitude = -1;
  EXPECT_EQ(message(p), "flapping.amplitude should be finite and >= 0, got -1");
  p = FlappingParams{};
  p.ramp = -0.5;
  EXPECT_EQ(message(p), "flapping.ramp should be finite and >= 0, got -0.5");
  p = FlappingParams{};
  p.speed = NAN;
  EXPECT_EQ(message(p), "flapping.speed should be a finite number, got nan");
  p = FlappingParams{};
  p.frequency = 0;
  EXPECT_EQ(message(p), "flapping.frequency should be finite and > 0, got 0");
  p = FlappingParams{};
  p.parabola = INFINITY;
  EXPECT_EQ(message(p), "flapping.parabola should be a finite number, got inf");
  for (const char* mode : {"displace", "force", "visual", "off"}) {
    p = FlappingParams{};
    p.mode = parse_enum<FlapMode>("flapping.mode", mode);
    EXPECT_NO_THROW(p.validate("flapping"));
  }
}

}  // namespace
}  // namespace flagsim
