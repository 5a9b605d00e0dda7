// Memory the process may still take, and the up-front check that a scene fits in it.
//
// The per-element figures are measured (peak resident set after construction and two steps,
// docs/design.md "Size limits"): a flag vertex with the implicit integrator and its multigrid
// preconditioner about 2.2 KB (explicit needs less); an air cell the grid-sized arrays its
// configuration allocates (FluidParams::memory_bytes counts them: 11.5 values of the grid's
// precision per cell for a periodic semi-Lagrangian fft grid at 128^3) plus a slack.
#pragma once
#include <cstdint>
#include <string>

namespace flagsim {

constexpr double kBytesPerVertex = 2300;  ///< upper bound, implicit integrator
/// Measured peak resident set over the air's counted arrays (FFTW's plans, allocator rounding):
/// 1.02 at 128^3 (186.6 MiB against 183 counted), more at small grids, where nothing matters.
constexpr double kMemorySlack = 1.1;

/// Bytes held right now by AlignedAllocator (fluid/grid.h: every grid-sized array of the air, its
/// FFT spectra and multigrid levels), over the whole process. Tests count the air's grid-sized
/// arrays with it (a Fluid's construction adds its arrays, destruction takes them back).
std::int64_t aligned_bytes_live();
/// AlignedAllocator's book-keeping: delta bytes allocated (> 0) or freed (< 0).
void count_aligned_bytes(std::int64_t delta);

/// Bytes this process can still allocate without swapping: MemAvailable, lowered to what the
/// cgroup (container) limit leaves and to $FLAGSIM_MEMORY_LIMIT (bytes) when set; 0 when not
/// known (then no check is made).
std::uint64_t available_memory();

/// InvalidArgument naming `what` when `bytes` exceed the available memory.
void check_memory(const std::string& what, double bytes, const std::string& advice);

}  // namespace flagsim
