// Thread-count control for OpenMP loops. Results are deterministic for a given thread count.
#pragma once

#include "common/types.h"

namespace flagsim {

/// Loops over fewer items than this run on one thread: below it, waking a thread team costs
/// more than the loop (and a loaded machine makes spinning threads far worse).
constexpr Index kParallelGrain = 4096;

/// Number of threads flagsim's loops use (default: OpenMP's default, usually all cores).
int num_threads();
/// Set the thread count for flagsim's loops; n >= 1. Throws InvalidArgument otherwise.
void set_num_threads(int n);
/// True when compiled with OpenMP.
bool has_openmp();

}  // namespace flagsim
