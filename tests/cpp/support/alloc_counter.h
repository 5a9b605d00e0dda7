// Counts global operator new calls while a CountAllocations scope is alive (this test binary
// replaces the global allocation functions in alloc_counter.cpp). Used to assert that a
// simulation step allocates nothing.
#pragma once

namespace flagsim::testing {

/// Allocations counted so far by every thread while counting was on.
long allocation_count();

class CountAllocations {
 public:
  CountAllocations();
  ~CountAllocations();
  long count() const { return allocation_count() - start_; }

 private:
  long start_;
};

}  // namespace flagsim::testing
