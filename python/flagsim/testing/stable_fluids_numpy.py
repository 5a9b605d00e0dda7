"""Plain numpy Stable Fluids on a periodic MAC grid: the correctness oracle and speed baseline.

The textbook algorithm (Stam 1999, with the FFT projection of Stam 2001), written independently
of flagsim's C++ kernels: semi-Lagrangian self-advection with a linear backtrace and trilinear
interpolation, implicit diffusion and projection both done on full complex FFTs (``np.fft.fftn``)
of the three velocity components. The grid and the discrete operators are the ones
``flagsim.Fluid(boundary="periodic", pressure="fft")`` uses, so one step of each on the same field
agrees to round-off:

* u on x-faces at ``origin + h * (i, j + 1/2, k + 1/2)``, v and w likewise, all (nx, ny, nz);
* divergence at cells ``(u[i+1] - u[i] + v[j+1] - v[j] + w[k+1] - w[k]) / h``, gradient at faces
  ``(phi[i] - phi[i-1]) / h``; in Fourier space their symbols are ``(e^{i t} - 1) / h`` and
  ``(1 - e^{-i t}) / h`` with ``t = 2 pi m / n``, and the Laplacian's is ``(2 cos t - 2) / h^2``.

Viscosity follows flagsim's rule (docs/design.md, "Explicit viscosity on periodic fft grids"):
where ``beta = nu dt / h^2 <= EXPLICIT_VISCOSITY_BETA`` the step adds ``nu dt lap u^n`` (the
7-point Laplacian of the field before advection, in real space) to the advected field and projects
it; above, implicit diffusion in Fourier space, ``(1 - nu dt lambda)^-1``, before the projection.

No mean-flow driving and no fans: the k = 0 mode is left as it is.
"""

from __future__ import annotations

import numpy as np

__all__ = ["EXPLICIT_VISCOSITY_BETA", "StableFluidsNumpy"]

#: Largest nu dt / h^2 diffused explicitly (flagsim's kExplicitViscosityBeta, csrc/fluid/fluid.cpp).
EXPLICIT_VISCOSITY_BETA = 0.01


def _offset(component: int) -> np.ndarray:
    """Staggering offset (cells) of a component's nodes: 0 along its own axis, 1/2 across."""
    off = np.full(3, 0.5)
    off[component] = 0.0
    return off


class StableFluidsNumpy:
    """Periodic Stable Fluids on an (nx, ny, nz) MAC grid of cell size ``cell_size`` (m).

    ``u``, ``v``, ``w`` are (nx, ny, nz) float64 arrays (m/s), assigned freely between steps.
    """

    def __init__(
        self, resolution=(16, 16, 16), cell_size=0.125, origin=(0.0, 0.0, 0.0), viscosity=0.0
    ):
        self.n = tuple(int(x) for x in resolution)
        if len(self.n) != 3 or min(self.n) < 1:
            raise ValueError(f"resolution should be 3 cell counts >= 1, got {resolution}")
        if not cell_size > 0:
            raise ValueError(f"cell_size should be > 0, got {cell_size}")
        if not viscosity >= 0:
            raise ValueError(f"viscosity should be >= 0, got {viscosity}")
        self.h = float(cell_size)
        self.origin = np.asarray(origin, dtype=float)
        self.viscosity = float(viscosity)
        self.time = 0.0
        self.u = np.zeros(self.n)
        self.v = np.zeros(self.n)
        self.w = np.zeros(self.n)
        # node indices (cells) of a (nx, ny, nz) array, stacked on the last axis
        self._index = np.stack(
            np.meshgrid(*[np.arange(k, dtype=float) for k in self.n], indexing="ij"), axis=-1
        )
        theta = [2.0 * np.pi * np.arange(k) / k for k in self.n]
        t = np.meshgrid(*theta, indexing="ij")
        self._div_symbol = [(np.exp(1j * td) - 1.0) / self.h for td in t]
        self._grad_symbol = [(1.0 - np.exp(-1j * td)) / self.h for td in t]
        self._lap_symbol = sum((2.0 * np.cos(td) - 2.0) for td in t) / self.h**2

    # -- geometry ------------------------------------------------------------------------------
    def face_positions(self, component: int) -> np.ndarray:
        """World positions (nx*ny*nz, 3) of a component's nodes, C order."""
        return (self.origin + self.h * (self._index + _offset(component))).reshape(-1, 3)

    def set_velocity(self, fn) -> None:
        """Set u, v, w from fn(points (M, 3)) -> (M, 3), evaluated at each component's faces."""
        for c, name in enumerate("uvw"):
            values = np.asarray(fn(self.face_positions(c)), dtype=float)[:, c]
            setattr(self, name, values.reshape(self.n).copy())

    # -- kernels -------------------------------------------------------------------------------
    def _interpolate(self, q: np.ndarray, component: int, p: np.ndarray) -> np.ndarray:
        """Trilinear, periodic value of component array q at points p (..., 3) in cell units."""
        g = p - _offset(component)
        base = np.floor(g)
        f = g - base
        i0 = base.astype(np.int64)
        idx0 = [np.mod(i0[..., d], self.n[d]) for d in range(3)]
        idx1 = [np.mod(i0[..., d] + 1, self.n[d]) for d in range(3)]
        fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]

        def at(a, b, c):
            return q[
                (idx1[0] if a else idx0[0], idx1[1] if b else idx0[1], idx1[2] if c else idx0[2])
            ]

        def lerp(a, b, t):
            return a + t * (b - a)

        c00 = lerp(at(0, 0, 0), at(0, 0, 1), fz)
        c01 = lerp(at(0, 1, 0), at(0, 1, 1), fz)
        c10 = lerp(at(1, 0, 0), at(1, 0, 1), fz)
        c11 = lerp(at(1, 1, 0), at(1, 1, 1), fz)
        return lerp(lerp(c00, c01, fy), lerp(c10, c11, fy), fx)

    def advect(self, dt: float) -> None:
        """Semi-Lagrangian self-advection (Stam 1999 §2.2): q(x) <- q(x - dt u(x))."""
        fields = (self.u, self.v, self.w)
        out = []
        for c in range(3):
            x = self._index + _offset(c)  # node positions in cell units
            vel = np.stack(
                [fields[e] if e == c else self._interpolate(fields[e], e, x) for e in range(3)],
                axis=-1,
            )
            out.append(self._interpolate(fields[c], c, x - (dt / self.h) * vel))
        self.u, self.v, self.w = out

    def explicit_viscosity(self, dt: float) -> bool:
        """Whether a step of dt diffuses explicitly (see the module docstring)."""
        beta = self.viscosity * dt / self.h**2
        return 0 < beta <= EXPLICIT_VISCOSITY_BETA

    def laplacian(self, q: np.ndarray) -> np.ndarray:
        """Periodic 7-point Laplacian of a component array (1/m^2 times its unit)."""
        out = -6.0 * q
        for axis in range(3):
            out += np.roll(q, 1, axis) + np.roll(q, -1, axis)
        return out / self.h**2

    def diffuse_and_project(self, dt: float) -> None:
        """Implicit diffusion and projection in Fourier space (Stam 2001)."""
        hats = [np.fft.fftn(q) for q in (self.u, self.v, self.w)]
        lam = self._lap_symbol
        if self.viscosity > 0 and not self.explicit_viscosity(dt):
            hats = [q / (1.0 - self.viscosity * dt * lam) for q in hats]
        div = sum(a * q for a, q in zip(self._div_symbol, hats))
        with np.errstate(divide="ignore", invalid="ignore"):
            phi = np.where(lam == 0, 0.0, div / np.where(lam == 0, 1.0, lam))
        hats = [q - g * phi for g, q in zip(self._grad_symbol, hats)]
        self.u, self.v, self.w = (np.fft.ifftn(q).real for q in hats)

    def divergence(self) -> np.ndarray:
        """Cell divergence (nx, ny, nz), 1/s."""
        return (
            np.roll(self.u, -1, 0)
            - self.u
            + np.roll(self.v, -1, 1)
            - self.v
            + np.roll(self.w, -1, 2)
            - self.w
        ) / self.h

    def step(self, dt: float) -> None:
        """One Stable Fluids step: advect, diffuse, project."""
        before = (self.u, self.v, self.w)
        self.advect(dt)
        if self.explicit_viscosity(dt):
            nu_dt = self.viscosity * dt
            self.u, self.v, self.w = (
                q + nu_dt * self.laplacian(q0) for q, q0 in zip((self.u, self.v, self.w), before)
            )
        self.diffuse_and_project(dt)
        self.time += dt
