"""Forces the air exerts on its solids, as time series: drag and lift coefficients, shedding
frequency and Strouhal number.

    >>> import flagsim, flagsim.forces
    >>> cyl = flagsim.ObstacleParams(shape="cylinder", center=(0, 0, 0.05), radius=0.5, length=9)
    >>> air = flagsim.Fluid(resolution=(48, 32, 2), cell_size=0.125, origin=(-2, -2, 0),
    ...                     boundary="tunnel", pressure="pcg", viscosity=0.01, wind=(1, 0, 0),
    ...                     obstacles=[cyl])
    >>> h = flagsim.forces.force_history(air, dt=0.05, steps=20)
    >>> h.force.shape
    (20, 3)
    >>> bool(h.coefficients(density=1.2, speed=1.0, area=1.0 * 0.25)[-1, 0] > 0)  # drag
    True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ForceHistory:
    """time (n,) s after each step, force (n, 3) N on one obstacle."""

    time: np.ndarray
    force: np.ndarray

    def window(self, after: float = 0.0) -> np.ndarray:
        """Mask of the samples at time > after (s): drop the start-up transient."""
        return self.time > after

    def coefficients(self, density: float, speed: float, area: float) -> np.ndarray:
        """force / (0.5 density speed^2 area): drag (along the flow) and lift coefficients."""
        if not (density > 0 and speed > 0 and area > 0):
            raise ValueError(
                f"density, speed and area should be > 0, got {density}, {speed}, {area}"
            )
        return self.force / (0.5 * density * speed * speed * area)

    def mean(self, after: float = 0.0) -> np.ndarray:
        """Time-averaged force (3,) over the samples after `after` s."""
        w = self.window(after)
        if not w.any():
            raise ValueError(f"after should be below the last time {self.time[-1]:g} s")
        return self.force[w].mean(axis=0)

    def shedding_frequency(self, axis: int = 1, after: float = 0.0) -> float:
        """Frequency (Hz) of the force component `axis` (lift: across the flow) from its upward
        crossings of its mean, each located by linear interpolation between samples: whole
        periods between the first and last crossing. NaN when it crosses fewer than twice."""
        w = self.window(after)
        t, f = self.time[w], self.force[w, axis]
        f = f - f.mean()
        up = np.nonzero((f[:-1] < 0) & (f[1:] >= 0))[0]
        if len(up) < 2:
            return float("nan")
        tc = t[up] - f[up] * (t[up + 1] - t[up]) / (f[up + 1] - f[up])
        return float((len(tc) - 1) / (tc[-1] - tc[0]))


def force_history(fluid, dt: float, steps: int, index: int = 0, progress: bool = False):
    """Step `fluid` `steps` times by dt (s), recording fluid.obstacle_force(index) after each
    step. progress: a tqdm bar."""
    if steps < 1:
        raise ValueError(f"steps should be >= 1, got {steps}")
    fluid.obstacle_force(index)  # a bad index fails before any step
    times = np.empty(steps)
    forces = np.empty((steps, 3))
    it = range(steps)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="air", unit="step")
    for s in it:
        fluid.step(dt)
        times[s] = fluid.time
        forces[s] = fluid.obstacle_force(index)
    return ForceHistory(times, forces)
