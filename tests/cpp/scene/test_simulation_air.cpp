// The air grid as the Simulation's air stage (issue 4).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <string>

#include "../support/alloc_counter.h"
#include "../support/same_bits.h"
#include "common/errors.h"
#include "common/parallel.h"
#include "scene/simulation.h"

namespace flagsim {

TEST(SimulationAir, PaperSceneUsesTheGridAndItsStepAllocatesNothing) {
  Simulation sim(Scene::paper());
  ASSERT_NE(sim.fluid(), nullptr);
  const auto& st = sim.stages();
  EXPECT_NE(std::find(st.begin(), st.end(), "fluid"), st.end());
  sim.step(5);
  testing::CountAllocations count;
  sim.step(100);
  EXPECT_EQ(count.count(), 0);
  EXPECT_NEAR(sim.fluid()->time(), sim.time(), 1e-12);
}

TEST(SimulationAir, UniformWindThroughTheGridMatchesTheAnalyticAir) {
  Scene s = Scene::paper();
  s.air.fans.clear();
  s.air.wind.keys = {{0.0, Vec3(1, 0, 0.5)}, {1.0, Vec3(3, 0, -1)}};
  s.air.model = AirModel::kUniform;
  Simulation analytic(s);
  s.air.model = AirModel::kGrid;
  Simulation grid(s);
  EXPECT_EQ(analytic.fluid(), nullptr);
  analytic.step(120);
  grid.step(120);
  EXPECT_LT((analytic.positions() - grid.positions()).cwiseAbs().maxCoeff(), 1e-11);
  EXPECT_GT((analytic.positions() - grid.topology().rest_positions).cwiseAbs().maxCoeff(), 0.03);
}

namespace {
Scene paper_full(bool pipeline) {
  Scene s = Scene::paper();
  s.self_collision.enabled = true;
  s.flapping.mode = FlapMode::kDisplace;
  s.air.pipeline = pipeline;
  return s;
}

using testing::same_air;
using testing::same_bytes;
using testing::Threads;
}  // namespace

// Issue 28: the air's step beside the cloth's gives the serial order's bits. 400 steps of the
// full paper scene (grid air with its fan, self-collision, eq. 5), the serial order on one thread
// as the reference, the pipeline on one thread (one side after the other) and on two (side by
// side), and the serial order on two threads.
TEST(SimulationAir, PipelinedStepGivesTheSerialBitsOnOneAndTwoThreads) {
  constexpr long kSteps = 400;
  auto run = [&](int threads, bool pipeline) {
    Threads t(threads);
    auto sim = std::make_unique<Simulation>(paper_full(pipeline));
    EXPECT_EQ(sim->pipelined(), pipeline);
    sim->step(kSteps);
    return sim;
  };
  const auto serial = run(1, false);
  EXPECT_GT((serial->positions() - serial->topology().rest_positions).cwiseAbs().maxCoeff(), 0.05)
      << "the flag should have moved";
  for (int threads : {1, 2})
    for (bool pipeline : {true, false}) {
      if (threads == 1 && !pipeline) continue;
      const auto sim = run(threads, pipeline);
      const std::string what =
          std::to_string(threads) + " threads, pipeline " + (pipeline ? "on" : "off");
      EXPECT_TRUE(same_bytes(sim->positions(), serial->positions())) << what;
      EXPECT_TRUE(same_bytes(sim->velocities(), serial->velocities())) << what;
      EXPECT_TRUE(same_air(*sim->fluid(), *serial->fluid())) << what;
      EXPECT_EQ(sim->air_outside_total(), serial->air_outside_total()) << what;
      EXPECT_EQ(sim->pole_air_speed(), serial->pole_air_speed()) << what;
    }
}

// The air's thread helps the cloth's once its step is done (for_each_chunk: the self-collision
// broad phase's tree queries and its pair loops, in chunks merged in a fixed order): the bits are
// the serial order's whichever thread ran which chunk. A 32 x 32 flag in the paper's air with
// self-collision (the thickness at the paper's ratio to the spacing, as Scene::large) and eq. 5,
// whose thousands of candidate pairs are shared; 100 steps on one and two threads.
TEST(SimulationAir, HelpedClothStepGivesTheSerialBitsOnOneAndTwoThreads) {
  constexpr long kSteps = 100;
  auto run = [&](int threads, bool pipeline) {
    Threads t(threads);
    Scene s = paper_full(pipeline);
    auto spacing = [&] {
      return std::min(s.flag.width / (s.flag.cols - 1), s.flag.height / (s.flag.rows - 1));
    };
    const double paper_spacing = spacing();
    s.flag.rows = s.flag.cols = 32;
    s.self_collision.thickness *= spacing() / paper_spacing;
    auto sim = std::make_unique<Simulation>(s);
    sim->step(kSteps);
    return sim;
  };
  const auto serial = run(1, false);
  ASSERT_NE(serial->self_collision_stats(), nullptr);
  EXPECT_GT(serial->self_collision_stats()->candidates, 2048) << "too few pairs to share";
  for (int threads : {1, 2}) {
    const auto sim = run(threads, true);
    EXPECT_TRUE(same_bytes(sim->positions(), serial->positions())) << threads << " threads";
    EXPECT_TRUE(same_bytes(sim->velocities(), serial->velocities())) << threads << " threads";
    EXPECT_TRUE(same_air(*sim->fluid(), *serial->fluid())) << threads << " threads";
  }
}

// A cloth step that fails beside the air leaves the air as it was before the step: the air's
// step is taken back, as the serial order never takes it.
TEST(SimulationAir, FailedClothStepBesideTheAirTakesTheAirStepBack) {
  for (int threads : {1, 2}) {
    Threads t(threads);
    Scene s = paper_full(true);
    s.integrator.strain_limit = 0;   // nothing holds the stretch...
    s.integrator.max_strain = 1e-6;  // ...that the first step's sag makes a divergence
    Simulation sim(s), reference(s);
    const MatX3 x0 = sim.positions();
    EXPECT_THROW(sim.step(1), DivergenceError);
    EXPECT_TRUE(same_bytes(sim.positions(), x0));
    EXPECT_EQ(sim.step_count(), 0);
    EXPECT_TRUE(same_air(*sim.fluid(), *reference.fluid())) << threads << " threads";
  }
}

// The step the pipeline takes back (Fluid::undo_step), taken again, gives the bits of the step
// taken once: the periodic fft air of the scenes, and a tunnel on multigrid, whose warm start
// keep_warm_start keeps.
TEST(SimulationAir, AirStepTakenBackAndTakenAgainGivesTheSameBits) {
  for (Pressure pressure : {Pressure::kFft, Pressure::kMultigrid}) {
#ifndef FLAGSIM_HAVE_FFTW
    if (pressure == Pressure::kFft) continue;  // not in this build
#endif
    FluidParams p = Scene::paper().air;
    if (pressure == Pressure::kMultigrid) {
      p.boundary = Boundary::kTunnel;
      p.advection = Advection::kMacCormack;
    }
    p.pressure = pressure;
    Fluid once(p), twice(p);
    twice.keep_warm_start();
    for (int k = 0; k < 5; ++k) {
      once.step(0.01);
      twice.step(0.01);
    }
    twice.step(0.01);
    twice.undo_step();
    EXPECT_EQ(twice.time(), once.time());
    EXPECT_TRUE(same_air(once, twice));
    for (int k = 0; k < 3; ++k) {
      once.step(0.01);
      twice.step(0.01);
    }
    EXPECT_TRUE(same_air(once, twice)) << name_of(pressure);
    if (pressure != Pressure::kFft) {
      EXPECT_GT(once.stats().pressure_iterations, 0);
    }
  }
}

TEST(SimulationAir, FlagOutsideTheGridIsRejectedAtBuild) {
  Scene s = Scene::paper();
  s.air.origin = Vec3(-0.5, 0.2, -1.0);  // grid above the flag
  EXPECT_THROW(Simulation sim(s), InvalidArgument);
}

}  // namespace flagsim
