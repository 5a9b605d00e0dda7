// The 9-point stencil of a rows x cols grid of vertices (vertex (r, c) at index r cols + c): the
// coarse multigrid levels store one 3x3 block per stencil slot.
#pragma once

#include "common/simd.h"

namespace flagsim {

/// Slot of neighbour (r + dr, c + dc) in a vertex's stencil, dr and dc in -1..1: 3 (dr + 1) + dc +
/// 1, row-major, so the centre is slot 4 and slot 8 - k mirrors slot k.
constexpr int kStencilCentre = 4;
constexpr int stencil_slot(int dr, int dc) { return 3 * (dr + 1) + (dc + 1); }

/// f(dr, dc) for every neighbour (r + dr, c + dc) of vertex (r, c) inside the rows x cols grid,
/// the centre included, in increasing slot order. interior = true: the caller knows all 8
/// neighbours are inside, so the bounds tests compile out and the loop unrolls (same calls, same
/// order). f should be a FLAGSIM_INLINE_LAMBDA where it sits in a vector kernel.
template <bool interior = false, class F>
FLAGSIM_INLINE void for_each_stencil_neighbour(int rows, int cols, int r, int c, F&& f) {
  for (int dr = -1; dr <= 1; ++dr) {
    if (!interior && (r + dr < 0 || r + dr >= rows)) continue;
    for (int dc = -1; dc <= 1; ++dc) {
      if (!interior && (c + dc < 0 || c + dc >= cols)) continue;
      f(dr, dc);
    }
  }
}

}  // namespace flagsim
