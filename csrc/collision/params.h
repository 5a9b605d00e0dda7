// Parameters of self-collision (vertex vs triangle, paper §1) and of the pole.
#pragma once
#include <string>

#include "common/types.h"

namespace flagsim {

struct SelfCollisionParams {
  bool enabled = false;
  double thickness = 0.005;  ///< m, minimum vertex-triangle distance
  double friction = 0.0;     ///< Coulomb coefficient, >= 0
  int iterations = 32;       ///< response sweeps per step at most before the freeze fallback
  void validate(const std::string& prefix) const;
};

/// Vertical cylinder along +y the flag is pinned to; vertices collide with it.
struct PoleParams {
  bool enabled = true;
  double radius = 0.055;      ///< m (paper §4.1: 11 cm diameter)
  double height = 2.6;        ///< m
  Vec3 base{0.0, -2.5, 0.0};  ///< m, centre of the bottom cap
  void validate(const std::string& prefix) const;
};

}  // namespace flagsim
