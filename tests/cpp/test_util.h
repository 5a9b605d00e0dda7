// Shared helpers for the C++ tests.
#pragma once
#include <chrono>
#include <cmath>
#include <vector>

#include "scene/scene.h"

namespace flagsim::testing {

/// One free mass on a vertical spring: a 2 x 2 flag with vertices 0, 1, 2 pinned, shear and bend
/// springs off, no air, no gravity. Vertex 3 (bottom right) hangs from vertex 1 by a structural
/// spring of stiffness k; the horizontal spring to vertex 2 acts only at second order in the
/// vertical displacement. Period 2 pi sqrt(m_3 / k).
inline Scene spring_pair_scene(const std::string& method, double k, double dt) {
  Scene s;
  s.flag.rows = 2;
  s.flag.cols = 2;
  s.flag.width = 0.1;
  s.flag.height = 0.1;
  s.flag.stretch_stiffness = k;
  s.flag.shear_stiffness = 0;
  s.flag.bend_stiffness = 0;
  s.flag.damping = 0;
  s.flag.pinned_vertices = {0, 1, 2};
  s.air.model = AirModel::kNone;
  s.gravity = Vec3::Zero();
  s.pole.enabled = false;
  s.integrator.method = parse_enum<Method>("method", method);
  s.integrator.adaptive = false;
  s.integrator.cg_tolerance = 1e-12;
  s.dt = dt;
  return s;
}

/// Spins for `seconds` of wall time: a wait the scheduler cannot shorten (timer tests).
inline void busy(double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
  }
}

/// log2 ratios of successive errors: the observed orders when h halves each time.
inline std::vector<double> observed_orders(const std::vector<double>& err) {
  std::vector<double> p;
  for (size_t i = 1; i < err.size(); ++i) p.push_back(std::log2(err[i - 1] / err[i]));
  return p;
}

}  // namespace flagsim::testing
