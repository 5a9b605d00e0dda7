// Memory the process may still take, and the up-front check that a scene fits in it.
//
// The per-element figures are measured (peak resident set after construction and two steps,
// docs/design.md "Size limits"): a flag vertex with the implicit integrator and its multigrid
// preconditioner about 2.2 KB (explicit needs less); an air cell about 26 values of the grid's
// precision (periodic: u, the MacCormack scratch, ghost-padded copies, FFT buffers; tunnel less).
#pragma once
#include <cstdint>
#include <string>

namespace flagsim {

constexpr double kBytesPerVertex = 2300;  ///< upper bound, implicit integrator
constexpr double kValuesPerCell = 26;     ///< times sizeof(double) or sizeof(float)

/// Bytes this process can still allocate without swapping: MemAvailable, lowered to what the
/// cgroup (container) limit leaves and to $FLAGSIM_MEMORY_LIMIT (bytes) when set; 0 when not
/// known (then no check is made).
std::uint64_t available_memory();

/// InvalidArgument naming `what` when `bytes` exceed the available memory.
void check_memory(const std::string& what, double bytes, const std::string& advice);

}  // namespace flagsim
