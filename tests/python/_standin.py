"""A small stand-in for flagsim.Simulation used by the POV-Ray tests: a mesh whose motion the
test knows exactly, with the Simulation's array interface.

The flag is a rows x cols sheet hanging from a pole at x = 0 (r = 0 the top row, c = 0
the pole side, as the real topology) with a travelling wave z = A (x / L) sin(k x - w t): a
deterministic, flapping-looking motion with the same array interface as the Simulation.
"""

from types import SimpleNamespace

import numpy as np
from flagsim.povray import vertex_normals


def sheet(rows, cols, length=1.5, height=1.0):
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    u = (c / (cols - 1)).ravel()
    v = (1.0 - r / (rows - 1)).ravel()
    rest = np.stack([length * u, height * (v - 1.0), np.zeros_like(u)], axis=1)
    tris = []
    for i in range(rows - 1):
        for j in range(cols - 1):
            a = i * cols + j
            b, d = a + 1, a + cols
            tris += [(a, d, b), (b, d, d + 1)]  # counter-clockwise seen from +z
    return rest, np.stack([u, v], axis=1), np.array(tris, dtype=np.int32)


class StandInSim:
    def __init__(self, rows=9, cols=13, dt=0.01, amplitude=0.25):
        self.rest, self.uv, self.triangles = sheet(rows, cols)
        self.dt = dt
        self.amplitude = amplitude
        self.step_count = 0
        self.steps_taken = []
        self._update()

    @property
    def time(self):
        return self.step_count * self.dt

    def _update(self):
        x = self.rest[:, 0]
        t = self.time
        p = self.rest.copy()
        p[:, 2] = self.amplitude * (x / 1.5) * np.sin(4.0 * x - 7.0 * t)
        p[:, 1] -= 0.05 * (x / 1.5) ** 2
        self.positions = p
        self.normals = vertex_normals(p, self.triangles)

    def step(self, n=1):
        self.steps_taken.append(n)
        self.step_count += n
        self._update()


def standin_scene(dt=0.01):
    """What the exporter reads from a Scene: dt and the pole."""
    pole = SimpleNamespace(enabled=True, radius=0.055, height=2.6, base=(0.0, -2.5, 0.0))
    return SimpleNamespace(dt=dt, pole=pole)
