"""perlin1d and eq. 5 from Python, checked against the definitions written out in
_perlin_reference.py."""

import flagsim
import numpy as np
import pytest
from _perlin_reference import reference_eq5, reference_noise


@pytest.mark.parametrize("seed", [0, 1, 2024, 2**32 - 1])
def test_perlin1d_matches_the_definition(seed):
    x = np.linspace(-40.0, 40.0, 1601) + 0.013
    np.testing.assert_allclose(
        flagsim.perlin1d(x, seed=seed), reference_noise(x, seed), rtol=0, atol=1e-14
    )


def test_perlin1d_zero_on_the_lattice_bounded_and_smooth():
    rng = np.random.default_rng(0)
    for seed in rng.integers(0, 2**32, size=5):
        seed = int(seed)
        assert np.all(flagsim.perlin1d(np.arange(-500.0, 500.0), seed=seed) == 0.0)
        x = np.linspace(0.0, 256.0, 256 * 200 + 1)
        n = flagsim.perlin1d(x, seed=seed)
        assert np.max(np.abs(n)) <= 1.0
        # Continuous first derivative: one-sided slopes agree at every lattice point.
        i = np.arange(-30.0, 30.0)
        e = 1e-6
        left = (flagsim.perlin1d(i, seed) - flagsim.perlin1d(i - e, seed)) / e
        right = (flagsim.perlin1d(i + e, seed) - flagsim.perlin1d(i, seed)) / e
        np.testing.assert_allclose(left, right, atol=1e-5)


def test_perlin1d_is_vectorised_and_seeded():
    x = np.linspace(0.0, 10.0, 24).reshape(2, 3, 4) + 0.5
    a = flagsim.perlin1d(x, seed=5)
    assert a.shape == (2, 3, 4) and a.dtype == np.float64
    np.testing.assert_array_equal(a, flagsim.perlin1d(x, seed=5))
    # Only 8 gradient values: two seeds share a cell now and then (1 in 64), most cells differ.
    assert np.count_nonzero(a != flagsim.perlin1d(x, seed=6)) >= 18
    assert isinstance(flagsim.perlin1d(0.5), float)
    np.testing.assert_array_equal(
        flagsim.perlin1d([0.25, 0.75]), flagsim.perlin1d(np.array([0.25, 0.75]))
    )


def test_perlin1d_rejects_bad_input():
    with pytest.raises(ValueError, match=r"seed should be in \[0, 4294967295\], got -1"):
        flagsim.perlin1d([0.5], seed=-1)
    with pytest.raises(ValueError, match=r"x should be finite, got nan"):
        flagsim.perlin1d([0.5, np.nan])


def params(**overrides):
    p = flagsim.FlappingParams()
    p.mode = "displace"
    p.amplitude = 0.03
    p.l_max = 0.25
    p.speed = 0.6
    p.parabola = 1.2
    p.frequency = 3.5
    p.seed = 17
    for k, v in overrides.items():
        setattr(p, k, v)
    return p


def test_displacement_is_equation_5_per_vertex():
    p = params()
    rows, cols, length = 8, 11, 0.54
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    xy = np.column_stack([(c / (cols - 1)).ravel(), (r / (rows - 1)).ravel()])
    L = xy[:, 0] * length
    for t in (0.0, 0.8, 3.1):
        z = flagsim.flapping_displacement(xy, L, 2.0, t, p)
        np.testing.assert_allclose(
            z, reference_eq5(xy[:, 0], xy[:, 1], L, 2.0, t, p), rtol=0, atol=1e-15
        )


def test_ramp_constant_beyond_l_max():
    p = params()
    values = [flagsim.flapping_ramp(L, p) for L in (0.25, 0.3, 1.0, 50.0)]
    assert values == [p.amplitude] * 4
    assert flagsim.flapping_ramp(0.0, p) == 0.0
    assert 0 < flagsim.flapping_ramp(0.1, p) < p.amplitude


def test_flapping_params_validation():
    p = flagsim.FlappingParams()
    with pytest.raises(ValueError, match=r"flapping\.l_max should be finite and > 0, got 0"):
        p.l_max = 0.0
    with pytest.raises(ValueError, match=r"flapping\.l_max should be finite and > 0, got -1"):
        p.l_max = -1.0
    with pytest.raises(
        ValueError,
        match=r'flapping\.mode should be one of "displace", "force", '
        r'"visual", "off", got "flap"',
    ):
        p.mode = "flap"
    with pytest.raises(ValueError, match=r"flapping\.frequency should be finite and > 0, got inf"):
        p.frequency = float("inf")
    with pytest.raises(ValueError, match=r"flapping\.seed should be in"):
        p.seed = 2**32
    # Rejected values leave the parameters as they were.
    assert p.l_max == 0.2 and p.mode == "off" and p.frequency == 3.0
    for mode in ("displace", "force", "visual", "off"):
        p.mode = mode
    assert "mode='off'" in repr(p) and "l_max=0.2," in repr(p)


def test_flapping_seed_validation():
    p = flagsim.FlappingParams()
    with pytest.raises(ValueError, match=r"flapping\.seed should be in \[0, 4294967295\], got -3"):
        p.seed = -3
    p.seed = 2**32 - 1
    assert p.seed == 2**32 - 1
