"""Helpers the air tests share: random fields, field differences, the faces beside solids."""

import numpy as np


def random_field(fluid, seed):
    rng = np.random.default_rng(seed)
    for name in "uvw":
        setattr(fluid, name, rng.standard_normal(getattr(fluid, name).shape))


def max_abs_diff(a, b):
    return max(float(np.abs(getattr(a, n) - getattr(b, n)).max()) for n in "uvw")


def plate(shape):
    """A solid plate across the middle of the cross-section, a quarter of the way along x."""
    nx, ny, nz = shape
    m = np.zeros(shape, bool)
    m[nx // 4 : nx // 4 + 2, ny // 4 : 3 * ny // 4, nz // 4 : 3 * nz // 4] = True
    return m


def solid_face_masks(fluid):
    """Per component, True on faces with a solid cell on either side (they must carry 0)."""
    solid = fluid.solid_cells() > 0
    periodic = fluid.boundary == "periodic"
    masks = []
    for axis in range(3):
        if periodic:  # face i lies between cells i - 1 and i
            masks.append(solid | np.roll(solid, 1, axis=axis))
        else:  # faces 0 .. n, air beyond the ends
            pad = [(0, 0)] * 3
            pad[axis] = (1, 1)
            s = np.pad(solid, pad)
            lo = [slice(None)] * 3
            hi = [slice(None)] * 3
            lo[axis] = slice(0, -1)
            hi[axis] = slice(1, None)
            masks.append(s[tuple(lo)] | s[tuple(hi)])
    return masks


def close_solid_faces(fluid):
    """Zero the faces beside solid cells, as the obstacles do in a real scene."""
    for name, closed in zip("uvw", solid_face_masks(fluid)):
        getattr(fluid, name)[closed] = 0.0
