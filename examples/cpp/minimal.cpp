// Embed flagsim in a C++ program: simulate the paper's flag for 5 s and report its extent.
#include <chrono>
#include <cstdio>

#include <flagsim/flagsim.h>

int main() {
  flagsim::Scene scene = flagsim::Scene::paper();
  flagsim::Simulation sim(scene);
  const long steps = static_cast<long>(5.0 / scene.dt);
  const auto t0 = std::chrono::steady_clock::now();
  sim.step(steps);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const flagsim::MatX3& x = sim.positions();
  const flagsim::Vec3 lo = x.colwise().minCoeff(), hi = x.colwise().maxCoeff();
  std::printf("simulated %.2f s in %ld steps: %.0f steps per second\n", sim.time(), steps,
              steps / secs);
  std::printf("flag extent: x [%.3f, %.3f] y [%.3f, %.3f] z [%.3f, %.3f] m\n", lo.x(), hi.x(),
              lo.y(), hi.y(), lo.z(), hi.z());
  return 0;
}
