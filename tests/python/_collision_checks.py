"""Independent geometric checks for collision tests (numpy only, no flagsim collision code).

crossings(): vertex-triangle crossings while every point moves linearly from x0 to x1, found by
sampling the signed plane distance of each (vertex, non-incident triangle) pair, bisecting sign
changes, and testing whether the vertex is inside the triangle at that time.
min_distance(): smallest distance from a vertex to a triangle it does not belong to.
"""

import numpy as np


def _candidates(lo_v, hi_v, lo_t, hi_t, tris):
    overlap = np.all((lo_v[:, None, :] <= hi_t[None]) & (hi_v[:, None, :] >= lo_t[None]), axis=2)
    cols = np.arange(len(tris))
    for k in range(3):
        overlap[tris[:, k], cols] = False  # never against its own triangles
    return np.nonzero(overlap)


def _plane_distance(p, a, b, c):
    n = np.cross(b - a, c - a)
    return np.einsum("...i,...i->...", n, p - a) / np.linalg.norm(n, axis=-1)


def _inside(p, a, b, c, tol=1e-9):
    n = np.cross(b - a, c - a)
    nn = np.einsum("...i,...i->...", n, n)
    wa = np.einsum("...i,...i->...", np.cross(b - p, c - p), n) / nn
    wb = np.einsum("...i,...i->...", np.cross(c - p, a - p), n) / nn
    wc = 1 - wa - wb
    return (wa >= -tol) & (wb >= -tol) & (wc >= -tol)


def crossings(x0, x1, tris, samples=16):
    """Number of (vertex, triangle) pairs where the vertex passes through the triangle."""
    tris = np.asarray(tris, dtype=np.int64)
    pts = np.concatenate([x0[tris], x1[tris]], axis=1)
    v, t = _candidates(np.minimum(x0, x1), np.maximum(x0, x1), pts.min(1), pts.max(1), tris)
    idx = [v, tris[t, 0], tris[t, 1], tris[t, 2]]
    moving = np.zeros(len(v), dtype=bool)
    for i in idx:
        moving |= np.any(x0[i] != x1[i], axis=1)
    idx = [i[moving] for i in idx]  # four points at rest cannot start crossing
    if len(idx[0]) == 0:
        return 0

    def at(sel, s):  # (p, a, b, c) of the selected pairs at times s
        s = np.asarray(s)[:, None]
        return [x0[i[sel]] + s * (x1[i[sel]] - x0[i[sel]]) for i in idx]

    every = np.arange(len(idx[0]))
    s_grid = np.linspace(0.0, 1.0, samples + 1)
    d = np.stack([_plane_distance(*at(every, np.full(len(every), s))) for s in s_grid])
    # Intervals where the plane distance changes sign: bisect them all at once.
    k, pair = np.nonzero((d[:-1] < 0) != (d[1:] < 0))
    lo, hi, dlo = s_grid[k], s_grid[k + 1], d[k, pair]
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        dm = _plane_distance(*at(pair, mid))
        same = (dm < 0) == (dlo < 0)
        lo, dlo, hi = np.where(same, mid, lo), np.where(same, dm, dlo), np.where(same, hi, mid)
    crossed = np.zeros(len(every), dtype=bool)
    crossed[pair[_inside(*at(pair, 0.5 * (lo + hi)))]] = True
    # Samples exactly on the plane (a touch without a sign change) count when inside.
    k0, pair0 = np.nonzero(d[1:] == 0)
    crossed[pair0[_inside(*at(pair0, s_grid[k0 + 1]))]] = True
    return int(crossed.sum())


def _segment_distance(p, a, b):
    ab = b - a
    s = np.clip(np.einsum("...i,...i->...", p - a, ab) / np.einsum("...i,...i->...", ab, ab), 0, 1)
    return np.linalg.norm(p - (a + s[..., None] * ab), axis=-1)


def min_distance(x, tris, reach):
    """Smallest vertex-to-non-incident-triangle distance, considering pairs within `reach`
    (box test); +inf when no pair is that close."""
    tris = np.asarray(tris, dtype=np.int64)
    pts = x[tris]
    v, t = _candidates(x - reach, x + reach, pts.min(1), pts.max(1), tris)
    if len(v) == 0:
        return np.inf
    p, a, b, c = x[v], pts[t, 0], pts[t, 1], pts[t, 2]
    inside = _inside(p, a, b, c, tol=0.0)
    edge = np.minimum.reduce(
        [_segment_distance(p, a, b), _segment_distance(p, b, c), _segment_distance(p, c, a)]
    )
    d = np.where(inside, np.abs(_plane_distance(p, a, b, c)), edge)
    return float(d.min())


def inside_cylinder(x, radius, base, height):
    """Mask of points strictly inside a vertical (+y) cylinder."""
    r2 = (x[:, 0] - base[0]) ** 2 + (x[:, 2] - base[2]) ** 2
    return (r2 < radius**2) & (x[:, 1] > base[1]) & (x[:, 1] < base[1] + height)
