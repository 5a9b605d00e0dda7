"""Taichi's Stable Fluids on the CPU: the second air peer (``--peers``), if taichi installs.

What a Taichi user would write after the Stable Fluids example that ships with Taichi
(python/taichi/examples/simulation/stable_fluid.py), in 3-D on the bench's periodic box:
collocated velocity, semi-Lagrangian advection with periodic trilinear interpolation, the
divergence by central differences, ``JACOBI`` Jacobi sweeps for the pressure (warm-started from
the last step's, as the example does) and the gradient subtracted; no viscosity (the bench's air
viscosity changes nothing at these sizes in a step). One CPU thread (``cpu_max_num_threads=1``),
double precision. The Jacobi sweeps are a fixed count, as in the example, not a converged solve:
at 64^3 and up the pressure is far from converged, so this peer does less work per step than
flagsim's exact FFT projection.
"""

# no `from __future__ import annotations`: Taichi reads the kernels' annotations as objects

from typing import Any

import numpy as np

#: Jacobi sweeps per step (the example's count is per resolution; 50 here at every size).
JACOBI = 50


def taichi_available() -> tuple[bool, str]:
    import importlib.util

    if importlib.util.find_spec("taichi") is None:
        return False, "Taichi is not installed (pip install taichi; make bench-deps installs it)"
    return True, ""


class TaichiFluid:
    def __init__(self, n: int, box: float, field_fn, dt: float):
        import taichi as ti

        ti.init(arch=ti.cpu, cpu_max_num_threads=1, default_fp=ti.f64, log_level=ti.WARN)
        self.ti = ti
        self.n, self.h, self.dt = n, box / n, dt
        v = ti.Vector.field(3, ti.f64, shape=(n, n, n))
        v_new = ti.Vector.field(3, ti.f64, shape=(n, n, n))
        div = ti.field(ti.f64, shape=(n, n, n))
        p = ti.field(ti.f64, shape=(n, n, n))
        p_new = ti.field(ti.f64, shape=(n, n, n))
        self.v, self.p = v, p
        h = self.h

        @ti.func
        def wrap(i):
            return (i % n + n) % n

        @ti.func
        def sample(q, x):  # x in cell units (node index space)
            b = ti.floor(x)
            f = x - b
            i = ti.cast(b, ti.i32)
            r = ti.Vector([0.0, 0.0, 0.0])
            for a, bb, c in ti.static(ti.ndrange(2, 2, 2)):
                w = (
                    (f[0] if a else 1 - f[0])
                    * (f[1] if bb else 1 - f[1])
                    * (f[2] if c else 1 - f[2])
                )
                r += w * q[wrap(i[0] + a), wrap(i[1] + bb), wrap(i[2] + c)]
            return r

        @ti.kernel
        def advect(s: ti.f64):
            for node in ti.grouped(v):
                v_new[node] = sample(v, ti.cast(node, ti.f64) - s * v[node])

        @ti.kernel
        def divergence():
            for i, j, k in div:
                div[i, j, k] = (
                    v_new[wrap(i + 1), j, k][0]
                    - v_new[wrap(i - 1), j, k][0]
                    + v_new[i, wrap(j + 1), k][1]
                    - v_new[i, wrap(j - 1), k][1]
                    + v_new[i, j, wrap(k + 1)][2]
                    - v_new[i, j, wrap(k - 1)][2]
                ) / (2 * h)

        @ti.kernel
        def jacobi(src: ti.template(), dst: ti.template()):
            for i, j, k in src:
                dst[i, j, k] = (
                    src[wrap(i + 1), j, k]
                    + src[wrap(i - 1), j, k]
                    + src[i, wrap(j + 1), k]
                    + src[i, wrap(j - 1), k]
                    + src[i, j, wrap(k + 1)]
                    + src[i, j, wrap(k - 1)]
                    - h * h * div[i, j, k]
                ) / 6.0

        @ti.kernel
        def subtract_gradient():
            for i, j, k in v:
                g = ti.Vector(
                    [
                        p[wrap(i + 1), j, k] - p[wrap(i - 1), j, k],
                        p[i, wrap(j + 1), k] - p[i, wrap(j - 1), k],
                        p[i, j, wrap(k + 1)] - p[i, j, wrap(k - 1)],
                    ]
                )
                v[i, j, k] = v_new[i, j, k] - g / (2 * h)

        self._advect, self._div, self._jacobi, self._grad = (
            advect,
            divergence,
            jacobi,
            subtract_gradient,
        )
        self._p_new = p_new
        idx = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
        v.from_numpy(np.asarray(field_fn((idx + 0.5) * self.h), float).reshape(n, n, n, 3))
        self.step(1)  # compile the kernels outside the timing
        ti.sync()

    def step(self, count: int) -> None:
        s = self.dt / self.h
        for _ in range(count):
            self._advect(s)
            self._div()
            for _ in range(JACOBI // 2):
                self._jacobi(self.p, self._p_new)
                self._jacobi(self._p_new, self.p)
            self._grad()
        self.ti.sync()

    def info(self) -> dict[str, Any]:
        return {
            "notes": f"collocated, {JACOBI} Jacobi sweeps per step (not converged), no viscosity, "
            "CPU, 1 thread"
        }

    def ok(self) -> bool:
        return bool(np.isfinite(self.v.to_numpy()).all())
