#include "fluid/turbulence.h"

#include <gtest/gtest.h>

#include <vector>

#include "../support/alloc_counter.h"
#include "fluid/fluid.h"

namespace flagsim {

namespace {

TurbulenceParams noise_params(double evolution) {
  TurbulenceParams t;
  t.intensity.keys = {{0.0, 1.5}};
  t.length_scale.keys = {{0.0, 0.3}};
  t.evolution.keys = {{0.0, evolution}};
  t.ramp_distance = 0.15;
  t.seed = 7;
  return t;
}

ObstacleParams cylinder() {
  ObstacleParams o;
  o.shape = ObstacleShape::kCylinder;
  o.center = Vec3(0.5, 0.45, 0.4);
  o.radius = 0.08;
  o.axis = Vec3(0, 1, 0);
  o.length = 2.0;
  return o;
}

GridGeometry grid(bool periodic) {
  GridGeometry g;
  g.nx = 12;
  g.ny = 10;
  g.nz = 8;
  g.h = 0.1;
  g.periodic = periodic;
  return g;
}

// Edges whose psi from the kept slices differs from CurlNoise::potential at their midpoints.
template <class T>
int mismatches(const CurlNoise& noise, const GridGeometry& geo, double t, EdgeNoise& slices) {
  std::array<AlignedVector<T>, 3> psi;
  for (int a = 0; a < 3; ++a) psi[a].resize(edge_shape(geo, a).size());
  noise.potential_on_edges(geo, t, slices, psi);
  int bad = 0;
  for (int a = 0; a < 3; ++a) {
    const Shape3 s = edge_shape(geo, a);
    for (int i = 0; i < s.n[0]; ++i)
      for (int j = 0; j < s.n[1]; ++j)
        for (int k = 0; k < s.n[2]; ++k) {
          const T direct = T(noise.potential(a, edge_position(geo, a, i, j, k), t));
          bad += psi[a][s.index(i, j, k)] != direct;
        }
  }
  return bad;
}

}  // namespace

// The grid's psi comes from noise slices kept between steps (EdgeNoise): at every time, forward
// within a slice, into the next, several slices ahead, back (an undone step), with a length
// scale that changes every step, it is the potential evaluated afresh at each edge, bit for bit.
TEST(EdgeNoise, KeptSlicesGiveTheDirectPotentialBitForBit) {
  std::vector<double> times;
  for (int s = 0; s <= 30; ++s) times.push_back(0.01 * s);   // 1.2 slices at 4 per second
  times.insert(times.end(), {0.29, 0.13, 0.131, 1.7, 0.0});  // back, ahead, back to the start
  for (const bool periodic : {true, false})
    for (const bool solid : {false, true}) {
      std::vector<ObstacleParams> solids;
      if (solid) solids.push_back(cylinder());
      const GridGeometry geo = grid(periodic);
      const CurlNoise noise(noise_params(4.0), solids);
      EXPECT_EQ(noise.ramped(), solid);
      EdgeNoise slices, slices_f;
      slices.reset(geo, noise.ramped());
      slices_f.reset(geo, noise.ramped());
      for (const double t : times) {
        EXPECT_EQ(mismatches<double>(noise, geo, t, slices), 0) << t;
        EXPECT_EQ(mismatches<float>(noise, geo, t, slices_f), 0) << t;
        EXPECT_EQ(slices.slice, static_cast<std::int64_t>(std::floor(4.0 * t))) << t;
      }
      // the lattice spacing keyframed: a new L every step re-evaluates both slices
      TurbulenceParams moving = noise_params(4.0);
      moving.length_scale.keys = {{0.0, 0.3}, {0.3, 0.5}};
      const CurlNoise growing(moving, solids);
      slices.reset(geo, growing.ramped());
      for (int s = 0; s <= 12; ++s)
        EXPECT_EQ(mismatches<double>(growing, geo, 0.025 * s, slices), 0) << s;
      // evolution 0: phase 0 for ever, the next slice weighs nothing
      const CurlNoise frozen(noise_params(0.0), solids);
      slices.reset(geo, frozen.ramped());
      EXPECT_EQ(mismatches<double>(frozen, geo, 0.5, slices), 0);
    }
}

// Steps that cross noise slices evaluate them into the arrays kept from construction: nothing is
// allocated inside a step, with or without a solid to ramp psi to.
TEST(EdgeNoise, TurbulentStepsAllocateNothing) {
  for (const bool solid : {false, true}) {
    FluidParams p;
    p.resolution = {12, 10, 8};
    p.cell_size = 0.1;
    p.origin = Vec3::Zero();
    p.pressure = solid ? Pressure::kMultigrid : Pressure::kFft;
    p.wind = WindSchedule(Vec3(2, 0, 0));
    p.turbulence = noise_params(20.0);  // a new slice every 5 steps
    if (solid) p.obstacles.push_back(cylinder());
#ifndef FLAGSIM_HAVE_FFTW
    if (!solid) continue;
#endif
    Fluid f(p);
    f.step(0.01);  // first step: thread pools and lazy runtime state
    testing::CountAllocations count;
    for (int i = 0; i < 30; ++i) f.step(0.01);
    EXPECT_EQ(count.count(), 0) << (solid ? "with a solid" : "without");
  }
}

}  // namespace flagsim
