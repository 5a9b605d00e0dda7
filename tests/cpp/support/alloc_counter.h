// Counts heap allocations while a CountAllocations scope is alive. This test binary replaces the
// global allocation functions (alloc_counter.cpp): every operator new, and on glibc also the C
// allocation functions (malloc, calloc, realloc, memalign, posix_memalign, aligned_alloc), which
// Eigen's dynamic matrices and the OpenMP runtime use instead of operator new. Used to assert
// that a simulation step allocates nothing.
#pragma once

namespace flagsim::testing {

/// Allocations counted so far by every thread while counting was on.
long allocation_count();

/// False when the allocator belongs to a sanitizer (nothing is replaced, nothing is counted):
/// tests asserting zero allocations should skip then.
bool allocation_counting_available();

/// True when malloc and friends are counted too (glibc), not only operator new.
bool counts_c_allocations();

class CountAllocations {
 public:
  CountAllocations();
  ~CountAllocations();
  long count() const { return allocation_count() - start_; }

 private:
  long start_;
};

}  // namespace flagsim::testing
