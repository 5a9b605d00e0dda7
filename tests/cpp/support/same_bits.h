// Byte-for-byte comparisons of simulation state, and flagsim's thread count for a scope: the
// determinism tests (the pipeline against the serial order, one thread against two).
#pragma once
#include <cstring>

#include "common/parallel.h"
#include "common/types.h"
#include "fluid/fluid.h"

namespace flagsim::testing {

inline bool same_bytes(const MatX3& a, const MatX3& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
}

// Every component of the two grids, byte for byte, and their time.
inline bool same_air(const Fluid& a, const Fluid& b) {
  for (int c = 0; c < 3; ++c) {
    const std::size_t bytes = a.component_shape(c).size() * (a.is_double() ? 8 : 4);
    if (std::memcmp(a.component_data(c), b.component_data(c), bytes) != 0) return false;
  }
  return a.time() == b.time();
}

struct Threads {  // flagsim's thread count for a scope
  int before = num_threads();
  explicit Threads(int n) { set_num_threads(n); }
  ~Threads() { set_num_threads(before); }
  Threads(const Threads&) = delete;
  Threads& operator=(const Threads&) = delete;
};

}  // namespace flagsim::testing
