// No heap allocation inside a step (issue 8): per-step scratch is allocated at construction.
//
// The counting allocator is tests/cpp/support/alloc_counter.cpp (shared by the test binary).
#include <gtest/gtest.h>

#include <atomic>
#include <cstddef>
#include <cstdlib>
#include <new>

#include "../support/alloc_counter.h"
#include "common/parallel.h"
#include "scene/simulation.h"

#if __has_include("fluid/fluid.h")
#include "fluid/fluid.h"
#define FLAGSIM_TEST_HAVE_FLUID 1
#endif



namespace flagsim {
namespace {

// Counts allocations from construction to count().
class AllocationProbe {
 public:
  long count() const { return scope_.count(); }

 private:
  testing::CountAllocations scope_;
};

#define SKIP_WITHOUT_COUNTING()                                                         \
  if (!testing::allocation_counting_available()) GTEST_SKIP() << "allocator owned by the sanitizer"

// The probe itself must see what it is meant to see, or a zero below would prove nothing.
TEST(NoAlloc, ProbeCountsOperatorNewAndEigenTemporaries) {
  SKIP_WITHOUT_COUNTING();
  MatX3 a = MatX3::Random(50, 3), b = MatX3::Random(50, 3);
  long n_new, n_eigen;
  {
    AllocationProbe probe;
    auto* p = new std::vector<double>(100);
    delete p;
    n_new = probe.count();
  }
  {
    AllocationProbe probe;
    MatX3 c = a + b;  // a new dynamic matrix: one Eigen heap allocation
    n_eigen = probe.count();
    EXPECT_NEAR(c(0, 0), a(0, 0) + b(0, 0), 1e-15);
  }
  EXPECT_GE(n_new, 2);
#if defined(__GLIBC__)
  EXPECT_GE(n_eigen, 1);
#endif
}

long allocations_in_steps(Simulation& sim, long steps) {
  sim.step(3);  // first steps may size lazily grown buffers (thread pools, CG workspaces)
  AllocationProbe probe;
  sim.step(steps);
  return probe.count();
}

Scene paper_full() {
  Scene s = Scene::paper();
  s.self_collision.enabled = true;
  s.flapping.mode = "displace";
  return s;
}

TEST(NoAlloc, PaperSceneStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  for (const char* method : {"implicit", "explicit"}) {
    Scene s = Scene::paper();
    s.integrator.method = method;
    Simulation sim(s);
    EXPECT_EQ(allocations_in_steps(sim, 100), 0) << method;
    EXPECT_EQ(sim.step_count(), 103);
  }
}

// Self-collision and flapping on (they are stages only once their areas are merged: until then
// the flags are accepted and the stages are simply not built, and this repeats the test above).
TEST(NoAlloc, PaperSceneWithCollisionAndFlappingStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  Simulation sim(paper_full());
  EXPECT_EQ(allocations_in_steps(sim, 100), 0);
}

// A flag big enough that every vertex loop runs on the OpenMP team (>= kParallelGrain), both
// integrators. Heavy cloth keeps the implicit system well conditioned (few CG iterations, a fast
// test); the loops run the same code whatever the mass.
TEST(NoAlloc, LargeFlagOnTwoThreadsStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  const int before = num_threads();
  set_num_threads(2);
  for (const char* method : {"implicit", "explicit"}) {
    Scene s = Scene::paper();
    s.flag.rows = s.flag.cols = 66;  // 4356 vertices
    s.flag.areal_density = 50.0;
    s.integrator.method = method;
    Simulation sim(s);
    EXPECT_EQ(allocations_in_steps(sim, 5), 0) << method;
  }
  set_num_threads(before);
}

#ifdef FLAGSIM_TEST_HAVE_FLUID
TEST(NoAlloc, AirOnly64CubedStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  FluidParams p;
  p.resolution = {64, 64, 64};
  p.cell_size = 1.0 / 64;
  Fluid air(p);
  air.step(0.01);
  air.step(0.01);
  AllocationProbe probe;
  for (int k = 0; k < 100; ++k) air.step(0.01);
  EXPECT_EQ(probe.count(), 0);
}

TEST(NoAlloc, PaperSceneWithGridAirStepsWithoutHeapAllocation) {
  SKIP_WITHOUT_COUNTING();
  Scene s = paper_full();
  s.air.model = "grid";
  Simulation sim(s);
  EXPECT_EQ(allocations_in_steps(sim, 100), 0);
}
#endif

}  // namespace
}  // namespace flagsim
