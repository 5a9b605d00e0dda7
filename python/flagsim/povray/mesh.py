"""Per-frame flag meshes as POV-Ray mesh2 include files (the C++ writer does the work)."""

from __future__ import annotations

import os

import numpy as np

from .. import _core


def flags_of(sim):
    """The flags to draw for ``sim``: ``sim.flags`` of a Simulation (flag 0 first), or ``(sim,)``
    for anything without them."""
    flags = getattr(sim, "flags", None)
    return tuple(flags) if flags else (sim,)


def mesh_arrays(sim):
    """(positions, normals, uv, triangles) of what should be drawn for ``sim``: every flag of a
    scene with several as one mesh (flag i's vertices after those of flags 0 .. i-1, each with
    its own uv in [0, 1]), so one mesh2 per frame draws them all.
    """
    flags = flags_of(sim)
    if len(flags) == 1:
        return _flag_arrays(flags[0])
    parts = [_flag_arrays(f) for f in flags]
    offsets = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
    return (
        np.concatenate([p[0] for p in parts]),
        np.concatenate([p[1] for p in parts]),
        np.concatenate([p[2] for p in parts]),
        np.concatenate([np.asarray(p[3]) + o for p, o in zip(parts, offsets)]).astype(np.int32),
    )


def _flag_arrays(sim):
    """(positions, normals, uv, triangles) of what should be drawn for one flag ``sim``.

    ``sim`` is any object with ``positions`` and ``normals`` (N, 3), ``uv`` (N, 2) and
    ``triangles`` (T, 3). When it also has ``render_positions`` that are not None (flapping in
    "visual" mode displaces the drawn flag, not the simulated one), those are drawn, with
    ``render_normals`` if present, else normals recomputed from them.
    """
    positions = getattr(sim, "render_positions", None)
    triangles = np.asarray(sim.triangles)
    if positions is None:
        positions, normals = sim.positions, sim.normals
    else:
        normals = getattr(sim, "render_normals", None)
        if normals is None:
            normals = vertex_normals(positions, triangles)
    return positions, normals, sim.uv, triangles


def vertex_normals(positions, triangles):
    """Area-weighted unit vertex normals (N, 3) of a triangle mesh, oriented by the winding."""
    x = np.asarray(positions, dtype=float)
    t = np.asarray(triangles, dtype=np.int64)
    face = np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]])  # |face| = 2 * area
    n = np.zeros_like(x)
    for k in range(3):
        np.add.at(n, t[:, k], face)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def format_mesh2(sim, *, name="FlagMesh", decimals=7, comment=""):
    """The mesh2 text ``write_mesh2`` would write for ``sim``."""
    positions, normals, uv, triangles = mesh_arrays(sim)
    return _core.format_mesh2(
        positions, normals, uv, triangles, name=name, decimals=decimals, comment=comment
    )


def write_mesh2(sim, path, *, name="FlagMesh", decimals=7, comment=""):
    """Write ``sim``'s flag as a POV-Ray include file declaring ``name`` as a mesh2.

    Converted to POV-Ray's left-handed frame (z negated, winding flipped), positions and uv with
    ``decimals`` digits after the point. The file is written whole or not at all (temporary file,
    then rename). ``sim`` is a ``flagsim.Simulation`` or any object with the same ``positions``,
    ``normals``, ``uv``, ``triangles`` (see ``mesh_arrays``).
    """
    positions, normals, uv, triangles = mesh_arrays(sim)
    _core.write_mesh2_arrays(
        os.fspath(path),
        positions,
        normals,
        uv,
        triangles,
        name=name,
        decimals=decimals,
        comment=comment,
    )
