"""Starting shapes for tests and benchmarks."""

import numpy as np


def folded_onto_itself(sim, cols: int, rows: int, width: float, height: float = 0.05) -> np.ndarray:
    """Positions (N x 3) of sim's flag laid flat in the x-z plane and folded over along its middle
    column: columns >= cols/2 lie back over the first half, `height` above, shifted by half a
    cell (width / (cols - 1) / 2) so no vertex sits exactly over another."""
    rest = np.array(sim.rest_positions)
    x = np.empty_like(rest)
    half, dx = cols // 2, width / (cols - 1)
    for r in range(rows):
        for c in range(cols):
            i = r * cols + c
            if c < half:
                x[i] = (rest[i, 0], 0.0, -rest[i, 1])
            else:
                x[i] = (rest[r * cols + (cols - 1 - c), 0] + 0.5 * dx, height, -rest[i, 1])
    return x
