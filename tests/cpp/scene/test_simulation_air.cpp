// The air grid as the Simulation's air stage (issue 4).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>

#include "../support/alloc_counter.h"
#include "common/errors.h"
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

TEST(SimulationAir, FlagOutsideTheGridIsRejectedAtBuild) {
  Scene s = Scene::paper();
  s.air.origin = Vec3(-0.5, 0.2, -1.0);  // grid above the flag
  EXPECT_THROW(Simulation sim(s), InvalidArgument);
}

}  // namespace flagsim
