// StageClock: exclusive stage timing (common/stage_clock.h).
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "../test_util.h"
#include "common/stage_clock.h"

using namespace flagsim;
using flagsim::testing::busy;

TEST(StageClock, NestedStagesAreChargedExclusively) {
  StageClock clock;
  const auto t0 = std::chrono::steady_clock::now();
  {
    StageClock::Scope outer(&clock, Stage::kIntegrate);
    busy(0.002);
    {
      StageClock::Scope inner(&clock, Stage::kSprings);
      busy(0.003);
    }
    busy(0.001);
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double integrate = clock.seconds(Stage::kIntegrate),
               springs = clock.seconds(Stage::kSprings);
  EXPECT_GE(springs, 0.003);
  EXPECT_GE(integrate, 0.003);  // the outer stage's own 2 + 1 ms, not the inner 3 ms again
  EXPECT_LE(integrate + springs, wall);
  EXPECT_EQ(clock.seconds(Stage::kDrag), 0.0);  // a stage never opened
}

TEST(StageClock, ANullClockTimesNothingAndNamesCoverEveryStage) {
  { StageClock::Scope s(nullptr, Stage::kDrag); }  // kernels called outside a Simulation
  for (const char* name : EnumNames<Stage>::names) EXPECT_NE(std::string(name), "");
  EXPECT_STREQ(name_of(Stage::kSelfCollision), "self_collision");
}
