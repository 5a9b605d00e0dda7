// Integrators against analytic solutions: a spring-mass pair, energy, stiff springs.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "../test_util.h"
#include "common/errors.h"
#include "scene/simulation.h"

namespace flagsim {
namespace {

using testing::observed_orders;
using testing::spring_pair_scene;

constexpr double kPi = 3.14159265358979323846;

// Free-mass oscillation from an initial stretch delta: the largest deviation from the analytic
// -delta cos(w t) over [0, T], relative to delta; optionally the measured period (between the
// first two upward zero crossings, linearly interpolated).
double pair_max_error(const std::string& method, double k, double dt, double delta, double T,
                      double* period_out = nullptr) {
  Simulation sim(spring_pair_scene(method, k, dt));
  const double y0 = sim.positions()(3, 1);
  const double w = std::sqrt(k / sim.topology().mass[3]);
  sim.positions()(3, 1) -= delta;
  const long n = std::lround(T / dt);
  double prev = -delta, worst = 0, first = -1;
  for (long i = 0; i < n; ++i) {
    sim.step();
    const double y = sim.positions()(3, 1) - y0;
    worst = std::max(worst, std::abs(y + delta * std::cos(w * sim.time())) / delta);
    if (period_out && prev < 0 && y >= 0) {
      const double tc = (i + (-prev) / (y - prev)) * dt;
      if (first < 0)
        first = tc;
      else if (*period_out == 0)
        *period_out = tc - first;
    }
    prev = y;
  }
  return worst;
}

class SpringPair : public ::testing::TestWithParam<const char*> {};

TEST_P(SpringPair, PeriodMatchesAnalyticAndErrorFallsAtFirstOrder) {
  const std::string method = GetParam();
  const double k = 100.0, delta = 1e-4;
  Simulation probe(spring_pair_scene(method, k, 1e-3));
  const double m = probe.topology().mass[3];
  const double T = 2 * kPi * std::sqrt(m / k);
  // Largest error over one period; dt = T/100, T/200, T/400, T/800: both methods first order.
  std::vector<double> err;
  for (double div : {100.0, 200.0, 400.0, 800.0})
    err.push_back(pair_max_error(method, k, T / div, delta, T));
  const auto p = observed_orders(err);
  for (double q : p) {
    EXPECT_GT(q, 0.85) << method;
    EXPECT_LT(q, 1.2) << method;
  }
  EXPECT_LT(err.back(), 0.03);
  // The measured period converges to the analytic one (its error is second order in dt).
  double period = 0;
  pair_max_error(method, k, T / 2000, delta, 2.5 * T, &period);
  EXPECT_NEAR(period, T, 1e-4 * T) << method;
}

INSTANTIATE_TEST_SUITE_P(Integrators, SpringPair, ::testing::Values("explicit", "implicit"));

TEST(Explicit, UndampedClothEnergyStaysBoundedOver1e4Steps) {
  Scene s;
  s.flag.rows = 6;
  s.flag.cols = 6;
  s.flag.damping = 0;
  s.air.model = AirModel::kNone;
  s.gravity = Vec3::Zero();
  s.integrator.method = Method::kExplicit;
  s.integrator.adaptive = false;
  s.integrator.strain_limit =
      0;               // the bare integrator: strain limiting is a dissipative projection
  Scene adaptive = s;  // the default dt is above the stable step: only the topology is wanted
  adaptive.integrator.adaptive = true;
  Simulation probe(adaptive);
  MatX3 zero = MatX3::Zero(probe.topology().num_vertices(), 3);
  const double h_stable =
      stable_step_estimate(probe.topology(), s.drag, 1.2, false, probe.positions(), zero, zero);
  s.dt = 0.1 * h_stable;
  Simulation sim(s);
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> d(-0.01, 0.01);
  for (Index i = 0; i < sim.positions().rows(); ++i)
    if (!sim.topology().pinned(i))
      for (int c = 0; c < 3; ++c) sim.positions()(i, c) += d(rng);
  const ClothEnergy e0 = sim.energy();
  const double E0 = e0.kinetic + e0.spring;
  ASSERT_GT(E0, 0);
  // Symplectic Euler conserves a modified energy: the true one oscillates within O(h), no drift.
  double early = 0, late = 0;
  for (int i = 0; i < 10000; ++i) {
    sim.step();
    const ClothEnergy e = sim.energy();
    const double dev = std::abs(e.kinetic + e.spring - E0) / E0;
    (i < 1000 ? early : late) = std::max(i < 1000 ? early : late, dev);
  }
  EXPECT_LT(std::max(early, late), 0.05);
  EXPECT_LT(late, 1.5 * early + 1e-3);
}

Scene stiff_paper(const std::string& method, bool adaptive) {
  Scene s = Scene::paper();
  s.flag.stretch_stiffness = 1e6;  // k_s for every spring: strain is then bounded everywhere
  s.flag.shear_stiffness = 1e6;
  s.flag.bend_stiffness = 1e6;
  s.integrator.method = parse_enum<Method>("method", method);
  s.integrator.adaptive = adaptive;
  s.flapping.mode =
      FlapMode::kOff;  // eq. 5 displaces positions directly: the integrator is under test
  s.dt = 0.01;
  return s;
}

TEST(Stiff, ImplicitIsStableWithKs1e6AtDt001) {
  Simulation sim(stiff_paper("implicit", false));
  sim.step(200);
  EXPECT_TRUE(sim.positions().allFinite());
  EXPECT_LT(sim.max_strain(), 0.01);
}

TEST(Stiff, ExplicitAdaptiveSubstepsAndStaysStable) {
  Simulation sim(stiff_paper("explicit", true));
  sim.step(10);
  EXPECT_GT(sim.last_step_stats().substeps, 10);
  EXPECT_TRUE(sim.positions().allFinite());
  EXPECT_LT(sim.max_strain(), 0.01);
}

// Strain limiting would keep an unstable explicit run bounded (but meaningless), so a step
// above the stable-step estimate is refused. When the scene is unstable at rest, no step could
// run: the Simulation refuses to be built, naming the parameter and the count it needs.
TEST(Stiff, ExplicitWithoutSubstepsUnstableAtRestIsRejectedUpFront) {
  try {
    Simulation sim(stiff_paper("explicit", false));
    FAIL() << "an explicit scene far above its stable step was built";
  } catch (const InvalidArgument& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind("integrator.substeps should be >= ", 0), 0u) << what;
    EXPECT_NE(what.find("integrator.adaptive = true"), std::string::npos) << what;
    EXPECT_NE(what.find("got 1"), std::string::npos) << what;
  }
  // with the substeps it names, the scene is built and runs
  Scene s = stiff_paper("explicit", false);
  try {
    Simulation probe(s);
  } catch (const InvalidArgument& e) {
    const std::string what = e.what();
    s.integrator.substeps = std::stoi(what.substr(what.find(">= ") + 3));
  }
  Simulation sim(s);
  sim.step(5);
  EXPECT_TRUE(sim.positions().allFinite());
}

// Stable at rest, unstable once a gust raises the drag slope (the estimate's |u| + |v| term,
// ~4 |u| per second here, passes the springs' bound near 360 m/s):
// the step where it happens raises DivergenceError("unstable_step") and restores its start.
TEST(Stiff, ExplicitStepThatBecomesUnstableRaisesDivergenceAndRestoresTheState) {
  Scene s = Scene::paper();
  s.air.model = AirModel::kUniform;
  s.air.wind = WindSchedule{};
  s.air.wind.keys = {{0.0, Vec3(2, 0, 0)}, {0.02, Vec3(2, 0, 0)}, {0.1, Vec3(1000, 0, 0)}};
  s.flapping.mode = FlapMode::kOff;
  s.integrator.method = Method::kExplicit;
  s.integrator.adaptive = false;
  s.integrator.energy_tolerance = 0;  // the mechanism under test is the stable-step refusal
  s.dt = 5e-4;                        // the stable step at rest is 0.95 ms
  Simulation sim(s);                  // stable at rest
  MatX3 x, v;
  for (int i = 0; i < 200; ++i) {
    x = sim.positions();
    v = sim.velocities();
    try {
      sim.step();
    } catch (const DivergenceError& e) {
      EXPECT_EQ(e.cause, "unstable_step");
      EXPECT_GT(e.step, 40);  // after the gust began
      EXPECT_EQ(sim.step_count(), e.step);
      EXPECT_EQ(sim.positions(), x);
      EXPECT_EQ(sim.velocities(), v);
      return;
    }
  }
  FAIL() << "a gust to 1000 m/s never made the explicit step unstable";
}

TEST(Divergence, StrainBeyondTheBoundRaisesAndRestores) {
  Scene s = Scene::paper();
  s.integrator.strain_limit = 0;  // nothing may pull the spring back within the step
  Simulation sim(s);
  sim.positions()(10, 0) += 1000.0;  // the free corner 1 km out: strain far above max_strain
  const MatX3 x = sim.positions();
  try {
    sim.step();
    FAIL() << "no DivergenceError";
  } catch (const DivergenceError& e) {
    EXPECT_EQ(e.cause, "strain");
    EXPECT_EQ(e.vertex, 10);  // the end of the worst spring that moved most
  }
  EXPECT_EQ(sim.positions(), x);
}

}  // namespace
}  // namespace flagsim

namespace flagsim {
namespace {

// A 4 x 4 flag lying flat (normal +y after a turn of its rest positions), falling at 1 m/s onto
// a floor 1 mm below it: one step of 10 ms would carry it 9 mm through. Every vertex has the
// floor as its contact plane (ForceSet::contacts). Both integrators end the step on the plane,
// not through it, with no velocity into it (the implicit one: a speculative contact, velocity
// -gap / h along the normal).
TEST(ContactPlanes, AFallingFlagEndsOnItsPlaneNotThroughIt) {
  FlagParams p;
  p.rows = 4;
  p.cols = 4;
  p.width = p.height = 0.3;
  p.pin = Pin::kNone;
  const ClothTopology topo = build_flag_topology(p);
  const Index N = topo.num_vertices();
  const double h = 0.01, gap = 0.001, floor_y = -gap;
  for (const Method method : {Method::kImplicit, Method::kExplicit}) {
    SCOPED_TRACE(method == Method::kImplicit ? "implicit" : "explicit");
    ForceSet fs;
    fs.gravity = fs.springs = true;
    IntegratorParams ip;
    ip.method = method;
    ip.cg_tolerance = 1e-10;
    const MatX3 u = MatX3::Zero(N, 3);
    MatX3 normal = MatX3::Zero(N, 3);
    VecX offset = VecX::Constant(N, floor_y);
    normal.col(1).setOnes();
    const auto start = [&](MatX3& x, MatX3& v) {
      x.resize(N, 3);
      for (Index i = 0; i < N; ++i)  // the flag's plane turned flat: (x, z) from (x, y)
        x.row(i) << topo.rest_positions(i, 0), 0.0, topo.rest_positions(i, 1);
      v = MatX3::Zero(N, 3);
      v.col(1).setConstant(-1.0);
    };
    MatX3 x, v;
    start(x, v);
    IntegratorScratch s(topo);
    IntegratorStats stats;
    ASSERT_EQ(integrate(topo, fs, ip, h, u, x, v, s, stats), IntegrateStatus::kOk);
    EXPECT_LT(x.col(1).maxCoeff(), floor_y - 0.005);  // without the planes: far through

    start(x, v);
    fs.contacts = &normal;
    fs.contact_offset = &offset;
    IntegratorScratch s2(topo);
    ASSERT_EQ(integrate(topo, fs, ip, h, u, x, v, s2, stats), IntegrateStatus::kOk);
    for (Index i = 0; i < N; ++i) {
      EXPECT_NEAR(x(i, 1), floor_y, 1e-9) << i;  // on the plane
      EXPECT_GE(x(i, 1), floor_y - 1e-12) << i;
      EXPECT_GE(v(i, 1), method == Method::kImplicit ? -gap / h - 1e-9 : 0.0) << i;
    }
  }
}

}  // namespace
}  // namespace flagsim
