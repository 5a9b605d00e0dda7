// The stages of a Simulation step, and the clock that times them (Simulation.timings).
//
// Each stage is timed by one scoped timer into an array indexed by Stage, as MuJoCo times its
// mjtTimer stages with TM_START/TM_END. Timing is exclusive: a stage opened inside another (the
// force kernels inside the integrator, strain limiting inside the pole loop) stops the outer
// stage's clock while it runs, so every second is charged to exactly one stage and the total is
// the step's wall time. Adding a stage: an enumerator and its name here, one Scope where it runs.
#pragma once
#include <array>
#include <chrono>
#include <cstddef>

#include "common/enums.h"

namespace flagsim {

enum class Stage {
  kWind,           // analytic wind at the masses
  kFluid,          // the air grid: sampled at the masses, then advanced
  kCoupling,       // two-way: the flag's drag reaction handed to the air grid
  kFlap,           // eq. 5 "displace" / "force": a drift or force the integrator carries
  kPins,           // moving pins: their velocity for the piece, their positions placed after
  kGravity,        // force kernels, called by the integrator
  kDrag,           //   eq. 3
  kSprings,        //   eq. 4
  kIntegrate,      // explicit or implicit step, less the kernels and projections it calls
  kStrainLimit,    // Provot projection
  kPole,           // collision with the pole
  kSolids,         // collision with the scene's solids (boxes, spheres, capsules, meshes)
  kSelfCollision,  // vertex-triangle and edge-edge
  kCheck,          // finiteness, strain, energy bookkeeping and the plausibility test
  kFlapVisual,     // eq. 5 "visual": after the step, on the exported geometry only
  kCount
};

/// Names (name_of) as Simulation.timings and Simulation.stages report them: "flap" for both
/// eq. 5 stages, as a scene builds one or the other.
template <>
struct EnumNames<Stage> {
  static constexpr std::array<const char*, std::size_t(Stage::kCount)> names{
      "wind",    "fluid",  "coupling",       "flap",      "pins",
      "gravity", "drag",   "springs",        "integrate", "strain_limit",
      "pole",    "solids", "self_collision", "check",     "flap"};
};

class StageClock {
 public:
  using Clock = std::chrono::steady_clock;

  /// Charges the time until it ends to `stage`, pausing the stage it was opened in. A null
  /// clock times nothing (kernels called outside a Simulation).
  class Scope {
   public:
    Scope(StageClock* clock, Stage stage) : c_(clock) {
      if (!c_) return;
      const Clock::time_point now = Clock::now();
      c_->charge(now);
      outer_ = c_->current_;
      c_->current_ = stage;
    }
    ~Scope() {
      if (!c_) return;
      c_->charge(Clock::now());
      c_->current_ = outer_;
    }
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;

   private:
    StageClock* c_;
    Stage outer_ = Stage::kCount;
  };

  double seconds(Stage s) const { return seconds_[std::size_t(s)]; }

 private:
  // Adds the time since the last mark to the running stage, and marks now.
  void charge(Clock::time_point now) {
    if (current_ != Stage::kCount)
      seconds_[std::size_t(current_)] += std::chrono::duration<double>(now - mark_).count();
    mark_ = now;
  }
  std::array<double, std::size_t(Stage::kCount)> seconds_{};
  Stage current_ = Stage::kCount;
  Clock::time_point mark_{};
};

}  // namespace flagsim
