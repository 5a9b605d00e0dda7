// The self-collision fallback's response: inelastic impact zones in the sense of Provot 1997 and
// Bridson et al. 2002, with zero motion over the step. A frozen vertex goes back to its start
// position x0, which is collision-free, so a loop that freezes every violating pair until none is
// left terminates (self_collision.h, "fallback"). Which pairs violate is the narrow phase's call;
// this holds which vertices are frozen and how a group is frozen.
#pragma once
#include <cstdint>
#include <vector>

#include "collision/params.h"
#include "common/keyframes.h"
#include "common/types.h"

namespace flagsim {

class ImpactZones {
 public:
  explicit ImpactZones(Index num_vertices);

  /// Nothing frozen (the start of a step's fallback).
  void clear();

  /// Frozen by this fallback, or pinned (inv_mass 0, 1/kg): a vertex the fallback cannot move.
  bool still(int32_t i, const VecX& inv_mass) const { return frozen_[i] || inv_mass[i] == 0; }

  /// The free vertices of `group` (4 indices into x0, x, v: N x 3, m and m/s) back to x0, moving
  /// as one with the group's momentum-weighted mean velocity (the velocity of its first pinned
  /// vertex when it holds one: a zone touching a pin moves with it, and stays still with a pin at
  /// rest). Returns how many were not frozen before.
  Index freeze(const int32_t group[4], const MatX3& x0, MatX3& x, MatX3& v, const VecX& inv_mass);

  /// True when a vertex that is not still lies inside the pole at x. motion: a moving pole, at
  /// motion->to at both x0 and x (the sweep's frame: collide_pole_carried), or nullptr (at rest).
  bool any_in_pole(const PoleParams& pole, const MatX3& x, const VecX& inv_mass,
                   const RigidMotion* motion = nullptr) const;

  /// Every vertex that is not still and lies inside the pole at x back to x0 (outside the pole),
  /// its velocity towards the pole's axis removed (relative to the surface's velocity there when
  /// the pole moves; motion as any_in_pole's). Returns how many.
  Index freeze_in_pole(const PoleParams& pole, const MatX3& x0, MatX3& x, MatX3& v,
                       const VecX& inv_mass, const RigidMotion* motion = nullptr);

  const std::vector<uint8_t>& frozen() const { return frozen_; }

 private:
  std::vector<uint8_t> frozen_;  // per vertex
};

}  // namespace flagsim
