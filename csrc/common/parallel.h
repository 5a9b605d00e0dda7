// Thread-count control for OpenMP loops. Results are deterministic for a given thread count.
#pragma once

#include "common/types.h"

namespace flagsim {

/// Loops over fewer items than this run on one thread: below it, waking a thread team costs
/// more than the loop (and a loaded machine makes spinning threads far worse).
constexpr Index kParallelGrain = 4096;

/// body(i) for every i in [0, n): split over the OpenMP team when `parallel`, else a plain loop
/// on the calling thread. Use this instead of `#pragma omp parallel for if (small)`: libgomp
/// builds a one-thread team for a region whose if clause is false, and that team is
/// heap-allocated and freed on every call (no allocation may happen inside a step).
template <class Body>
inline void parallel_for_if(bool parallel, Index n, const Body& body) {
#ifdef _OPENMP
  if (parallel) {
#pragma omp parallel for schedule(static)
    for (Index i = 0; i < n; ++i) body(i);
    return;
  }
#else
  (void)parallel;
#endif
  for (Index i = 0; i < n; ++i) body(i);
}

/// parallel_for_if(n >= kParallelGrain, n, body).
template <class Body>
inline void parallel_for(Index n, const Body& body) {
  parallel_for_if(n >= kParallelGrain, n, body);
}

/// Number of threads flagsim's loops use (default: OpenMP's default, usually all cores).
int num_threads();
/// Set the thread count for flagsim's loops; n >= 1. Throws InvalidArgument otherwise.
void set_num_threads(int n);
/// True when compiled with OpenMP.
bool has_openmp();

}  // namespace flagsim
