// No heap allocation inside a step (issue 8): per-step scratch is allocated at construction.
//
// Counting uses the test binary's replaced allocator (tests/cpp/support/alloc_counter.cpp): every
// operator new and, on glibc, malloc and friends, which is what Eigen's dynamic matrices (and so
// its temporaries) and the OpenMP runtime call; a counter of operator new alone would miss
// exactly the allocations that matter here. Under AddressSanitizer nothing is counted and the
// tests skip.
#include <gtest/gtest.h>

#include <vector>

#include "../support/alloc_counter.h"
#include "common/parallel.h"
#include "scene/simulation.h"

#if __has_include("fluid/fluid.h")
#include "fluid/fluid.h"
#define FLAGSIM_TEST_HAVE_FLUID 1
#endif

namespace flagsim {
namespace {

using testing::CountAllocations;

#define SKIP_WITHOUT_COUNTING()                  \
  if (!testing::allocation_counting_available()) \
  GTEST_SKIP() << "the allocator belongs to the sanitizer"

// The counter must see what it is meant to see, or a zero below would prove nothing.
TEST(NoAlloc, CounterSeesOperatorNewAndEigenTemporaries) {
  SKIP_WITHOUT_COUNTING();
  MatX3 a = MatX3::Random(50, 3), b = MatX3::Random(50, 3);
  long n_new, n_eigen;
  {
    CountAllocations count;
    auto* p = new std::vector<double>(100);
    delete p;
    n_new = count.count();
  }
  {
    CountAllocations count;
    MatX3 c = a + b;  // a new dynamic matrix: one Eigen heap allocation (std::malloc)
    n_eigen = count.count();
    EXPECT_NEAR(c(0, 0), a(0, 0) + b(0, 0), 1e-15);
  }
  EXPECT_GE(n_new, 2);
  if (testing::counts_c_allocations()) {
    EXPECT_GE(n_eigen, 1);
  }
}

long allocations_in_steps(Simulation& sim, long steps) {
  sim.step(3);  // first steps may size lazily grown buffers (thread pools, CG workspaces)
  CountAllocations count;
  sim.step(steps);
  return count.count();
}

Scene paper_full() {
  Scene s = Scene::paper();
  s.self_collision.enabled = true;
  s.flapping.mode = FlapMode::kDisplace;
  return s;
}

// The paper scene as built in (grid air with its fan, since the air solver landed).
TEST(NoAlloc, PaperSceneStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  for (const char* method : {"implicit", "explicit"}) {
    Scene s = Scene::paper();
    s.integrator.method = parse_enum<Method>("method", method);
    Simulation sim(s);
    EXPECT_EQ(allocations_in_steps(sim, 100), 0) << method;
    EXPECT_EQ(sim.step_count(), 103);
  }
}

// The air's step beside the cloth's (air.pipeline, issue 28) and one after the other, on one
// thread and on two (the side-by-side sections: a cached two-thread team, each side's loops on
// its own thread, no nested team); one-way, and two-way with the reaction a step late.
TEST(NoAlloc, PipelinedAndSerialStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  const int before = num_threads();
  for (Coupling coupling : {Coupling::kOneWay, Coupling::kTwoWayLagged})
    for (int threads : {1, 2})
      for (bool pipeline : {true, false}) {
        set_num_threads(threads);
        Scene s = paper_full();
        s.air.pipeline = pipeline;
        s.air.coupling = coupling;
        Simulation sim(s);
        EXPECT_EQ(sim.pipelined(), pipeline);
        EXPECT_EQ(allocations_in_steps(sim, 100), 0)
            << name_of(coupling) << ", " << threads << " threads, pipeline " << pipeline;
      }
  set_num_threads(before);
}

// The same flag in the analytic wind (no grid): the cloth stages alone.
TEST(NoAlloc, PaperFlagInUniformWindStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  for (const char* method : {"implicit", "explicit"}) {
    Scene s = Scene::paper();
    s.air.model = AirModel::kUniform;
    s.integrator.method = parse_enum<Method>("method", method);
    Simulation sim(s);
    EXPECT_EQ(allocations_in_steps(sim, 100), 0) << method;
  }
}

// Self-collision and flapping on (they are stages only once their areas are merged: until then
// the flags are accepted and the stages are simply not built, and this repeats the test above).
TEST(NoAlloc, PaperSceneWithCollisionAndFlappingStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  Simulation sim(paper_full());
  EXPECT_EQ(allocations_in_steps(sim, 100), 0);
}

// A flag big enough that every vertex loop wants the OpenMP team (>= kParallelGrain), both
// integrators, on one thread (no region: libgomp allocates one-thread teams) and on two (a
// cached team). Heavy cloth keeps the implicit system well conditioned (few CG iterations, a
// fast test); the loops run the same code whatever the mass.
TEST(NoAlloc, LargeFlagOnOneAndTwoThreadsStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  const int before = num_threads();
  for (int threads : {1, 2}) {
    set_num_threads(threads);
    for (const char* method : {"implicit", "explicit"}) {
      Scene s = Scene::paper();
      s.air.model = AirModel::kUniform;
      s.flag.rows = s.flag.cols = 66;  // 4356 vertices
      s.flag.areal_density = 50.0;
      s.integrator.method = parse_enum<Method>("method", method);
      Simulation sim(s);
      EXPECT_EQ(allocations_in_steps(sim, 2), 0) << method << ", " << threads << " threads";
    }
  }
  set_num_threads(before);
}

#ifdef FLAGSIM_TEST_HAVE_FLUID
// 64^3 air alone, on one thread and on two (every grid loop on the OpenMP team).
TEST(NoAlloc, AirOnly64CubedStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  const int before = num_threads();
  for (int threads : {1, 2}) {
    set_num_threads(threads);
    FluidParams p;
    p.resolution = {64, 64, 64};
    p.cell_size = 2.0 / 64;
    p.boundary = Boundary::kPeriodic;
    p.pressure = Pressure::kFft;
    Fluid air(p);
    air.step(0.01);
    air.step(0.01);
    CountAllocations count;
    for (int k = 0, steps = threads == 1 ? 100 : 20; k < steps; ++k) air.step(0.01);
    EXPECT_EQ(count.count(), 0) << threads << " threads";
  }
  set_num_threads(before);
}
#endif

}  // namespace
}  // namespace flagsim
