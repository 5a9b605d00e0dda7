"""The bench's numpy air baseline (benchmarks/stam_numpy.py): textbook Stable Fluids on a
collocated grid with spectral derivatives, so it matches flagsim's fft backend (staggered MAC
grid, discrete operators) only as the grid is refined. What holds:

* it solves the same problem: after one step from the same smooth periodic field, its difference
  from flagsim.Fluid(pressure="fft") falls at second order in h (16^3 -> 32^3 -> 64^3, at a fixed
  dt), the order of trilinear interpolation and of the MAC operators;
* its own invariants: a uniform field moves unchanged, the projection leaves no divergence and
  keeps the mean flow (the k = 0 mode).
"""

import math

import flagsim
import numpy as np
import pytest

from benchmarks.stam_numpy import StamFftNumpy

BOX = 2.0
NU = 1e-3


def field(points):
    """A smooth periodic field with a mean flow, not divergence-free (the projection has work)."""
    k = 2 * np.pi / BOX
    x, y, z = points.T
    u = np.empty_like(points)
    u[:, 0] = 1.5 + np.sin(k * y) * np.cos(k * z) + 0.3 * np.sin(k * x)
    u[:, 1] = 0.5 * np.cos(k * x) + 0.4 * np.sin(k * (y + z))
    u[:, 2] = -0.3 + 0.6 * np.sin(k * x) * np.cos(k * y)
    return u


def at_faces(stam: StamFftNumpy) -> list[np.ndarray]:
    """Stam's cell-centre components moved to flagsim's faces (half a cell down their own axis)
    by a Fourier shift: exact for a band-limited field, so it adds no error of its own order."""
    n = stam.n
    out = []
    for c in range(3):
        hat = np.fft.fftn(stam.vel[c])
        k = 2 * np.pi * np.fft.fftfreq(n, d=stam.h)
        if n % 2 == 0:
            k[n // 2] = 0.0
        shape = [1, 1, 1]
        shape[c] = n
        hat *= np.exp(-0.5j * stam.h * k).reshape(shape)
        out.append(np.fft.ifftn(hat).real)
    return out


def one_step_difference(n: int) -> float:
    h = BOX / n
    dt = 0.01  # fixed: Courant number 0.16 (16^3) to 0.64 (64^3) at 2 m/s
    fluid = flagsim.Fluid(
        resolution=(n, n, n),
        cell_size=h,
        origin=(0.0, 0.0, 0.0),
        boundary="periodic",
        pressure="fft",
        viscosity=NU,
    )
    fluid.set_velocity(field)
    stam = StamFftNumpy(n, BOX, viscosity=NU)
    stam.set_velocity(field)
    fluid.step(dt)
    stam.step(dt)
    moved = at_faces(stam)
    return max(float(np.abs(np.asarray(getattr(fluid, c)) - m).max()) for c, m in zip("uvw", moved))


def test_agrees_with_flagsim_fft_at_second_order_in_h():
    if not flagsim.has_fftw():
        pytest.fail("flagsim was built without FFTW: the fft backend to compare with is missing")
    errors = [one_step_difference(n) for n in (16, 32, 64)]
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    # Measured: 3.6e-4, 8.6e-5, 2.2e-5 m/s on a ~2 m/s field (orders 2.07, 1.97). At a fixed
    # Courant number instead (dt ~ h) the two schemes' leading interpolation errors coincide and
    # the difference falls at third order: not the check for the discretisations' own error.
    assert errors[0] < 2e-3, errors
    for order in orders:
        assert 1.8 < order < 2.3, (errors, orders)


def test_uniform_field_moves_unchanged_and_projection_leaves_no_divergence():
    stam = StamFftNumpy(12, BOX, viscosity=NU)
    stam.vel[:] = np.array([1.25, -0.5, 0.75])[:, None, None, None]
    stam.step(0.05)  # Courant 0.375: a fractional departure on every axis
    for c, value in enumerate((1.25, -0.5, 0.75)):
        np.testing.assert_allclose(stam.vel[c], value, rtol=0, atol=1e-14)

    stam.set_velocity(field)
    assert np.abs(stam.divergence()).max() > 1.0  # the field has divergence to take out
    mean = stam.vel.mean(axis=(1, 2, 3))
    stam.diffuse_and_project(0.05)
    assert np.abs(stam.divergence()).max() < 1e-10
    np.testing.assert_allclose(stam.vel.mean(axis=(1, 2, 3)), mean, rtol=0, atol=1e-14)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"n": 1}, "n should be an integer >= 2"),
        ({"n": 8.5}, "n should be an integer >= 2"),
        ({"box": 0.0}, "box should be > 0"),
        ({"viscosity": -1.0}, "viscosity should be >= 0"),
    ],
)
def test_bad_arguments_are_named(kwargs, match):
    args = {"n": 8, "box": BOX, "viscosity": 0.0} | kwargs
    with pytest.raises(ValueError, match=match):
        StamFftNumpy(**args)
