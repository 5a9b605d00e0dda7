"""The bench's air baseline: textbook Stable Fluids (Stam 1999, with the FFT solver of Stam 2001)
in plain numpy, written to be as fast as numpy allows rather than to match flagsim's grid.

What a numpy user would write for a periodic box:

* a collocated grid: all three components at the cell centres, one (3, n, n, n) array;
* semi-Lagrangian advection with a linear backtrace, q(x) <- q(x - dt u(x)), and periodic
  trilinear interpolation by a vectorised gather. One set of indices and weights serves the three
  components (collocated), and the grid is walked in chunks of ``CHUNK`` points so that the
  gather's temporaries stay in cache (at 128^3 the unchunked gather was ~6x slower: each of its
  ~60 whole-grid temporaries streamed 48 MB from memory);
* implicit diffusion and projection in one pass over the real-to-complex FFT of the three
  components with the continuous symbols ``i k`` (Stam 2001): u_hat <- P(k) u_hat / (1 + nu dt
  |k|^2), P = I - k k^T / |k|^2, the Nyquist wavenumbers of even sizes taken as 0 in the
  projection (the usual convention for an odd derivative).

The FFT is scipy.fft (``workers=1``) when scipy is installed (``pip install .[bench]`` brings it;
~25 % faster than numpy.fft here), else numpy.fft: same transforms to round-off, so the check in
tests/python/test_bench_stam_numpy.py holds for both. ``fft_backend()`` says which one ran.
Measured choices (one thread, this 2-core machine, CPU time per step, loaded): the gather against
scipy.ndimage.map_coordinates(order=1, mode='grid-wrap') per component: 16^3 0.42 vs 0.91 ms,
64^3 22 vs 55 ms, 128^3 200 vs 470 ms (map_coordinates finds the weights three times and wraps
every point in C, ~75 ns a point at every size); chunks of 8192 points against 32768: 128^3 200
vs 250 ms.

It differs from flagsim's discretisation on purpose (collocated, spectral derivatives), so the two
agree only as the grid is refined: their difference after one step falls at second order (the
trilinear interpolation's and the MAC operators' error), which the test checks.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CHUNK", "StamFftNumpy", "fft_backend"]

#: Points per chunk of the advection's gather: (3, CHUNK) doubles, ~200 KB per temporary.
CHUNK = 8192


def _fft():
    """(rfftn, irfftn, name) over the last three axes, one thread."""
    try:
        import scipy.fft as sfft
    except ImportError:
        return (
            lambda a: np.fft.rfftn(a, axes=(1, 2, 3)),
            lambda a, s: np.fft.irfftn(a, s=s, axes=(1, 2, 3)),
            "numpy.fft",
        )
    return (
        lambda a: sfft.rfftn(a, axes=(1, 2, 3), workers=1),
        lambda a, s: sfft.irfftn(a, s=s, axes=(1, 2, 3), workers=1),
        "scipy.fft",
    )


def _z_lerp(v, row, z0, z1, wz):
    """v (3, N) gathered at row + z0 and row + z1 and interpolated along z (in place)."""
    lo = v.take(row + z0, axis=1)
    hi = v.take(row + z1, axis=1)
    hi -= lo
    hi *= wz
    lo += hi
    return lo


def fft_backend() -> str:
    """'scipy.fft' or 'numpy.fft': what StamFftNumpy transforms with here."""
    return _fft()[2]


class StamFftNumpy:
    """Periodic Stable Fluids on n^3 collocated cells of a cubic box of side ``box`` (m).

    ``vel`` is the (3, n, n, n) float64 velocity (m/s) at the cell centres
    ``origin + (i + 1/2, j + 1/2, k + 1/2) h``; assign it freely between steps.
    """

    def __init__(self, n: int, box: float, viscosity: float = 0.0, origin=(0.0, 0.0, 0.0)):
        if int(n) != n or n < 2:
            raise ValueError(f"n should be an integer >= 2 (cells per side), got {n!r}")
        if not box > 0:
            raise ValueError(f"box should be > 0 (m), got {box!r}")
        if not viscosity >= 0:
            raise ValueError(f"viscosity should be >= 0 (m^2/s), got {viscosity!r}")
        self.n = n = int(n)
        self.h = box / n
        self.origin = np.asarray(origin, dtype=float)
        self.viscosity = float(viscosity)
        self.vel = np.zeros((3, n, n, n))
        i = np.arange(n, dtype=float)
        # node coordinates in cells, (3, n^3): the gather's departure points are these less s u
        self._nodes = np.stack(np.meshgrid(i, i, i, indexing="ij")).reshape(3, -1)
        k = 2.0 * np.pi * np.fft.fftfreq(n, d=self.h)
        kz = 2.0 * np.pi * np.fft.rfftfreq(n, d=self.h)
        self._k2 = k[:, None, None] ** 2 + k[None, :, None] ** 2 + kz[None, None, :] ** 2
        kd = [k.copy(), k.copy(), kz.copy()]
        if n % 2 == 0:  # the Nyquist wavenumber has no sign: no derivative there
            kd[0][n // 2] = kd[1][n // 2] = kd[2][-1] = 0.0
        self._k = (kd[0][:, None, None], kd[1][None, :, None], kd[2][None, None, :])
        kk = sum(a**2 for a in self._k)
        self._inv_kk = np.where(kk > 0, 1.0 / np.where(kk > 0, kk, 1.0), 0.0)
        self._rfftn, self._irfftn, self.fft = _fft()

    def positions(self) -> np.ndarray:
        """World positions (n^3, 3) of the cell centres, C order (m)."""
        return self.origin + self.h * (self._nodes.T + 0.5)

    def set_velocity(self, fn) -> None:
        """vel from fn(points (M, 3)) -> (M, 3) m/s at the cell centres."""
        v = np.asarray(fn(self.positions()), dtype=float)
        self.vel = np.ascontiguousarray(v.T).reshape(3, self.n, self.n, self.n)

    def advect(self, dt: float) -> None:
        """Semi-Lagrangian self-advection, chunk by chunk (see the module docstring)."""
        n, nn = self.n, self.n * self.n
        s = dt / self.h
        v = self.vel.reshape(3, -1)
        out = np.empty_like(v)
        for a in range(0, v.shape[1], CHUNK):
            b = min(v.shape[1], a + CHUNK)
            p = v[:, a:b] * -s
            p += self._nodes[:, a:b]  # departure points, cells
            f = np.floor(p)
            p -= f  # p: the weights along each axis
            i0 = f.astype(np.intp)
            np.remainder(i0, n, out=i0)
            i1 = i0 + 1
            i1[i1 == n] = 0
            x0, x1, y0, y1, z0, z1 = i0[0] * nn, i1[0] * nn, i0[1] * n, i1[1] * n, i0[2], i1[2]
            wx, wy, wz = p
            c0, c1 = _z_lerp(v, x0 + y0, z0, z1, wz), _z_lerp(v, x0 + y1, z0, z1, wz)
            c1 -= c0
            c1 *= wy
            c0 += c1
            d0, d1 = _z_lerp(v, x1 + y0, z0, z1, wz), _z_lerp(v, x1 + y1, z0, z1, wz)
            d1 -= d0
            d1 *= wy
            d0 += d1
            d0 -= c0
            d0 *= wx
            c0 += d0
            out[:, a:b] = c0
        self.vel = out.reshape(self.vel.shape)

    def diffuse_and_project(self, dt: float) -> None:
        """Implicit diffusion and projection in one pass over the spectra (Stam 2001)."""
        hat = self._rfftn(self.vel)
        if self.viscosity > 0:
            hat /= 1.0 + (self.viscosity * dt) * self._k2
        kx, ky, kz = self._k
        div = kx * hat[0]
        div += ky * hat[1]
        div += kz * hat[2]
        div *= self._inv_kk
        hat[0] -= kx * div
        hat[1] -= ky * div
        hat[2] -= kz * div
        self.vel = self._irfftn(hat, (self.n,) * 3)

    def step(self, dt: float) -> None:
        """One Stable Fluids step: advect, then diffuse and project."""
        self.advect(dt)
        self.diffuse_and_project(dt)

    def divergence(self) -> np.ndarray:
        """Spectral divergence at the cell centres, (n, n, n), 1/s."""
        hat = self._rfftn(self.vel)
        kx, ky, kz = self._k
        return self._irfftn((1j * (kx * hat[0] + ky * hat[1] + kz * hat[2]))[None], (self.n,) * 3)[
            0
        ]
