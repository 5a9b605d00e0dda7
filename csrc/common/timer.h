// Wall-clock stage timer: accumulates seconds per named stage (Simulation.timings).
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
