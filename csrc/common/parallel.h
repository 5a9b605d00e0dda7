// Thread-count control for OpenMP loops. Results are deterministic for a given thread count.
#pragma once

#include <atomic>
#include <memory>

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

namespace detail {
using ChunkFn = void (*)(const void* body, Index chunk);
// Runs fn(body, c) for every c in [0, chunks) with the SideBySide helper taking chunks too, when
// called inside a SideBySide::run's first job; false (nothing run) anywhere else.
bool share_chunks(Index chunks, ChunkFn fn, const void* body);
}  // namespace detail

/// body(c) for every chunk c in [0, chunks), each chunk writing only outputs of its own (results
/// merged in chunk order afterwards), so that which thread runs which chunk cannot change a bit.
/// Inside a SideBySide::run's first job (the cloth's side of a pipelined step) the helper thread,
/// once its own job is done, takes chunks too (balance: the air's thread helps the cloth's), if it
/// has picked its own job up by then (else it is not running: no wake-up is paid for);
/// elsewhere a plain loop in chunk order, as is a for_each_chunk inside a chunk (no nesting).
/// Chunks must not throw and must not enter OpenMP teams (num_threads() is 1 on both sides
/// there). No heap allocation.
template <class Body>
inline void for_each_chunk(Index chunks, const Body& body) {
  const detail::ChunkFn fn = [](const void* b, Index c) { (*static_cast<const Body*>(b))(c); };
  if (detail::share_chunks(chunks, fn, &body)) return;
  for (Index c = 0; c < chunks; ++c) body(c);
}

/// body(c) for every chunk c in [0, chunks): over the OpenMP team in static blocks when
/// use_team(parallel), else for_each_chunk (with the SideBySide helper when there is one).
template <class Body>
inline void run_chunks(bool parallel, Index chunks, const Body& body) {
  if (use_team(parallel)) {
    parallel_for_if(true, chunks, body);
    return;
  }
  for_each_chunk(chunks, body);
}

/// Set the thread count for flagsim's loops; n >= 1. Throws InvalidArgument otherwise. Inside a
/// parallel region it sets the count for the calling thread's loops until the region ends.
void set_num_threads(int n);

/// A helper thread that runs one job beside the calling thread (the Simulation's air step beside
/// its cloth step). run(first, second) runs first() on the calling thread and second() on the
/// helper, at the same time, when num_threads() >= 2; when the helper has not picked second()
/// up by the time first() returns (asleep, or without a core on a loaded machine), the calling
/// thread runs it itself, so it never waits for a thread that has not started. On one thread:
/// first() then second() on the calling thread. Inside both, num_threads() is 1: their loops run
/// on their own thread (no OpenMP team inside, never more than two busy threads), and since every
/// flagsim loop gives the same bits on any thread count, each gives the bits it would give alone.
/// The two must not touch the same data and must not throw (catch inside, rethrow after).
/// Once second() is done, the helper takes chunks of the work first() shares (for_each_chunk)
/// until first() returns. Waiting threads spin for up to kSpinMicroseconds, then sleep. No heap
/// allocation in run().
class SideBySide {
 public:
  static constexpr int kSpinMicroseconds = 50;
  SideBySide();   // starts the helper thread
  ~SideBySide();  // stops and joins it
  SideBySide(const SideBySide&) = delete;
  SideBySide& operator=(const SideBySide&) = delete;

  template <class First, class Second>
  void run(const First& first, const Second& second) {
    if (!use_team(true)) {
      first();
      second();
      return;
    }
    run_jobs([](const void* f) { (*static_cast<const First*>(f))(); }, &first,
             [](const void* f) { (*static_cast<const Second*>(f))(); }, &second);
  }

  struct State;  // the helper's thread, its job slot and how the two threads wait

 private:
  using Job = void (*)(const void*);
  void run_jobs(Job first, const void* first_arg, Job second, const void* second_arg);
  std::unique_ptr<State> s_;
};

/// Returns once `flag` is true (acquire): spins for up to SideBySide::kSpinMicroseconds, then
/// yields the core between looks. For waits on another thread's next few hundred microseconds
/// (the air's step held until the cloth has sampled u^n: Fluid::WriteGate).
void wait_until_set(const std::atomic<bool>& flag);

/// True when compiled with OpenMP.
bool has_openmp();

}  // namespace flagsim
