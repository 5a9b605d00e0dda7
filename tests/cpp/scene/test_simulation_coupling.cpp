// Two-way coupling and the force on the pole (issue 24 items 2 and 3; docs/coupling.md).
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "../support/alloc_counter.h"
#include "common/parallel.h"
#include "fluid/advect.h"
#include "scene/simulation.h"

namespace flagsim {
namespace {

// rho h^3 times the sum of the face velocities: the air's momentum on a periodic grid (each
// face stored once), N s.
Vec3 air_momentum(const Fluid& f) {
  const double h = f.geometry().h, cell_mass = f.params().density * h * h * h;
  Vec3 p = Vec3::Zero();
  for (int c = 0; c < 3; ++c) {
    const double* u = static_cast<const double*>(f.component_data(c));
    double s = 0;
    for (std::size_t i = 0; i < f.component_shape(c).size(); ++i) s += u[i];
    p[c] = cell_mass * s;
  }
  return p;
}

Vec3 flag_momentum(const Simulation& sim) {
  Vec3 p = Vec3::Zero();
  for (Index i = 0; i < sim.velocities().rows(); ++i)
    p += sim.topology().mass[i] * Vec3(sim.velocities().row(i));
  return p;
}

// The paper's flag free (no pins, no pole, no gravity) and thrown at 3 m/s across still air in
// the paper's periodic box; the wind has no keys, so no mean pressure gradient holds the mean
// flow: nothing outside air and flag exchanges momentum with them.
Scene free_flag(Method method, Pressure pressure) {
  Scene s = Scene::paper();
  s.air.fans.clear();
  s.air.wind = WindSchedule();
  s.air.coupling = Coupling::kTwoWay;
  s.air.pressure = pressure;
  s.gravity = Vec3::Zero();
  s.flag.pin = Pin::kNone;
  s.pole.enabled = false;
  s.flapping.mode = FlapMode::kOff;
  s.integrator.method = method;
  s.integrator.cg_tolerance = 1e-12;  // the CG residual is a force no one exerts
  return s;
}

}  // namespace

// The spread is the transpose of the sampling: <g, spread(J)> = <sample(g), J> for any field g,
// with the same clamping outside the box; each component's nodes gain the sum of J.
TEST(Coupling, SpreadIsTheTransposeOfSampling) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  for (bool periodic : {true, false}) {
    GridGeometry geo;
    geo.nx = 6, geo.ny = 5, geo.nz = 7;
    geo.h = 0.2;
    geo.origin = Vec3(-0.3, 0.1, -0.5);
    geo.periodic = periodic;
    MacGrid<double> g(geo), spread(geo);
    for (int c = 0; c < 3; ++c)
      for (double& x : g.comp[c]) x = uni(rng);
    const long m = 40;
    MatX3 points(m, 3), J(m, 3), at(m, 3);
    for (long r = 0; r < m; ++r)
      for (int d = 0; d < 3; ++d) {
        // a few points outside the box: the sampling clamps them, and so does the spread
        points(r, d) = geo.origin[d] + geo.h * geo.n(d) * (0.5 + 0.6 * uni(rng));
        J(r, d) = uni(rng);
      }
    sample_velocity(g, points.data(), m, at.data());
    spread_velocity(points.data(), m, J.data(), 2.5, spread);
    double lhs = 0;
    for (int c = 0; c < 3; ++c) {
      double nodes = 0;
      for (std::size_t i = 0; i < g.comp[c].size(); ++i) {
        lhs += g.comp[c][i] * spread.comp[c][i];
        nodes += spread.comp[c][i];
      }
      EXPECT_NEAR(nodes, 2.5 * J.col(c).sum(), 1e-13) << c;
    }
    EXPECT_NEAR(lhs, 2.5 * (at.array() * J.array()).sum(), 1e-12) << periodic;
  }
}

// Air plus flag keep their momentum to round-off in a periodic box without gravity, step by
// step. Semi-Lagrangian advection is not conservative itself (it moves momentum by an amount of
// the order of the flow's curvature), so each step is compared with a twin of the air stepped
// from the same field without the flag: their difference is what the flag gave the air.
TEST(Coupling, AirPlusFlagMomentumIsConservedToRoundOff) {
  for (Method method : {Method::kExplicit, Method::kImplicit})
    for (Pressure pressure : {Pressure::kFft, Pressure::kMultigrid}) {
      if (pressure == Pressure::kFft && !kBuiltWithFftw) continue;
      Simulation sim(free_flag(method, pressure));
      for (Index i = 0; i < sim.velocities().rows(); ++i)
        sim.velocities().row(i) = Vec3(0.5, -0.3, 3.0).transpose();
      Fluid twin(sim.fluid()->params());
      const double dt = sim.scene().dt;
      double worst = 0, exchanged = 0;
      for (int k = 0; k < 40; ++k) {
        for (int c = 0; c < 3; ++c)
          twin.set_component(c, static_cast<const double*>(sim.fluid()->component_data(c)));
        const Vec3 flag0 = flag_momentum(sim);
        sim.step(1);
        twin.step(dt);
        const Vec3 given = air_momentum(*sim.fluid()) - air_momentum(twin);
        const Vec3 taken = flag_momentum(sim) - flag0;
        worst = std::max(worst, (given + taken).norm());
        exchanged += taken.norm();
      }
      const double scale = flag_momentum(sim).norm();
      EXPECT_GT(exchanged, 0.05 * scale);  // the air really slowed the flag
      EXPECT_LT(worst, 1e-13 * scale + 1e-15) << name_of(method) << " " << name_of(pressure);
      // and the air, on its own grid, got what the flag lost: the projection keeps the mean
      EXPECT_GT(air_momentum(*sim.fluid()).z(), 0.5 * exchanged / 40);
    }
}

// The same run bit for bit on one thread and on two, and no heap allocation in a two-way step.
TEST(Coupling, TwoWayIsDeterministicAndAllocatesNothing) {
  const int before = num_threads();
  std::vector<MatX3> x;
  std::vector<std::vector<double>> air;
  for (int threads : {1, 2}) {
    set_num_threads(threads);
    Scene s = Scene::emergent();
    s.air.resolution = {24, 16, 16};  // the emergent scene on a coarser grid, pole included
    s.air.cell_size = 1.0 / 16;
    Simulation sim(s);
    sim.step(3);
    {
      testing::CountAllocations count;
      sim.step(20);
      if (testing::allocation_counting_available()) EXPECT_EQ(count.count(), 0) << threads;
    }
    x.push_back(sim.positions());
    const auto* u = static_cast<const double*>(sim.fluid()->component_data(0));
    air.emplace_back(u, u + sim.fluid()->component_shape(0).size());
  }
  set_num_threads(before);
  EXPECT_EQ(std::memcmp(x[0].data(), x[1].data(), sizeof(double) * x[0].size()), 0);
  EXPECT_EQ(air[0], air[1]);
}

// The pins' reaction: a banner hanging still in still air carries its weight on its top row.
TEST(Coupling, PoleForceOfAHangingFlagIsItsWeight) {
  Scene s = Scene::banner();
  s.air.model = AirModel::kNone;
  Simulation sim(s);
  sim.step(300);
  sim.reset_pole_force_mean();
  sim.step(100);
  const Vec3 weight = sim.topology().mass.sum() * s.gravity;
  EXPECT_LT((sim.pole_force() - weight).norm(), 1e-3 * weight.norm());
  EXPECT_LT((sim.pole_force_mean() - weight).norm(), 1e-4 * weight.norm());
}

}  // namespace flagsim
