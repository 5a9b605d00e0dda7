// Thread-count control for OpenMP loops. Results are deterministic for a given thread count.
#pragma once

#include "common/types.h"

namespace flagsim {

/// Loops over fewer items than this run on one thread: below it, waking a thread team costs
/// more than the loop (and a loaded machine makes spinning threads far worse).
constexpr Index kParallelGrain = 4096;
/// Grid loops over cells (advection rows, Poisson sweeps, projections) enter a team from this many
/// cells: a cell costs a few loads and flops, less than a cloth vertex's forces.
constexpr Index kGridParallelGrain = 4 * kParallelGrain;
/// Loops that only copy or compare each item (ghost fills, max reductions) enter a team from this
/// many items: memory-bound, they gain least from more threads.
constexpr Index kCopyParallelGrain = 8 * kParallelGrain;

/// Number of threads flagsim's loops use (default: OpenMP's default, usually all cores).
int num_threads();

/// True when a loop the caller wants parallel should enter an OpenMP region: `wanted` and more
/// than one thread. libgomp builds a team for every region it enters, even one whose if clause is
/// false or that has a single thread, and such a one-thread team is heap-allocated and freed on
/// every call; teams of two or more threads are cached. No allocation may happen inside a step.
inline bool use_team(bool wanted) { return wanted && num_threads() > 1; }

/// body(i) for every i in [0, n): split over the OpenMP team when use_team(parallel), else a
/// plain loop on the calling thread. Use this instead of `#pragma omp parallel for if (cond)`.
template <class Body>
inline void parallel_for_if(bool parallel, Index n, const Body& body) {
#ifdef _OPENMP
  if (use_team(parallel)) {
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

/// parallel_for_if(n > kGridParallelGrain, n, body): an elementwise loop over n grid cells.
template <class Body>
inline void parallel_for_cells(Index n, const Body& body) {
  parallel_for_if(n > kGridParallelGrain, n, body);
}

/// Set the thread count for flagsim's loops; n >= 1. Throws InvalidArgument otherwise. Inside a
/// parallel region it sets the count for the calling thread's loops until the region ends.
void set_num_threads(int n);

/// Runs first() and second() at the same time, each on a thread of its own, when use_team(true)
/// (two threads or more); otherwise first() then second() on the calling thread. Each runs its
/// own calls in order, and inside each num_threads() is 1: their loops run on their own thread
/// (no nested team, never more than two threads busy), and since every flagsim loop gives the same
/// bits on any thread count, each gives the bits it would give alone. The two must not touch the
/// same data, and must not throw (catch inside, rethrow after). With OpenMP sections a thread that
/// finishes its part takes the other if it has not been started yet (a sleeping worker).
template <class First, class Second>
inline void run_side_by_side(const First& first, const Second& second) {
#ifdef _OPENMP
  if (use_team(true)) {
#pragma omp parallel sections num_threads(2)
    {
#pragma omp section
      {
        set_num_threads(1);
        first();
      }
#pragma omp section
      {
        set_num_threads(1);
        second();
      }
    }
    return;
  }
#endif
  first();
  second();
}
/// True when compiled with OpenMP.
bool has_openmp();

}  // namespace flagsim
