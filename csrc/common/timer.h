// Wall-clock scope timer: adds the seconds a scope took to a running sum (Fluid.stats seconds_*;
// the Simulation's stages use StageClock, common/stage_clock.h).
#pragma once
#include <chrono>

namespace flagsim {

class ScopedTimer {
 public:
  explicit ScopedTimer(double& accumulator)
      : acc_(accumulator), t0_(std::chrono::steady_clock::now()) {}
  ~ScopedTimer() {
    acc_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  }
  ScopedTimer(const ScopedTimer&) = delete;
  ScopedTimer& operator=(const ScopedTimer&) = delete;

 private:
  double& acc_;
  std::chrono::steady_clock::time_point t0_;
};

}  // namespace flagsim
