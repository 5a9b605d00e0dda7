// Counts heap allocations (operator new and the malloc family) while a CountAllocations scope is
// alive (this test binary replaces the global allocation functions in alloc_counter.cpp). Used to assert that a
// simulation step allocates nothing.
#pragma once

namespace flagsim::testing {

/// Allocations counted so far by every thread while counting was on.
long allocation_count();
/// False under AddressSanitizer, which owns the allocator (nothing is counted).
bool allocation_counting_available();

class CountAllocations {
 public:
  CountAllocations();
  ~CountAllocations();
  long count() const { return allocation_count() - start_; }

 private:
  long start_;
};

}  // namespace flagsim::testing
