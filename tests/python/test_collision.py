"""Self-collision and pole parameters from Python."""

import flagsim
import pytest


def test_self_collision_params_validation():
    p = flagsim.SelfCollisionParams()
    assert not p.enabled and p.thickness == 0.005 and p.friction == 0.0
    with pytest.raises(
        ValueError, match=r"self_collision\.thickness should be finite and > 0, got -0\.001"
    ):
        p.thickness = -0.001
    with pytest.raises(
        ValueError, match=r"self_collision\.friction should be finite and >= 0, got -0\.5"
    ):
        p.friction = -0.5
    with pytest.raises(ValueError, match=r"self_collision\.iterations should be in \[1, 1000\]"):
        p.iterations = 0
    assert p.thickness == 0.005 and p.friction == 0.0 and p.iterations == 32
    p.enabled = True
    p.thickness = 0.002
    assert repr(p) == (
        "SelfCollisionParams(enabled=True, thickness=0.002, friction=0.0, " "iterations=32)"
    )


def test_pole_params_validation():
    p = flagsim.PoleParams()
    assert p.radius == 0.055
    with pytest.raises(ValueError, match=r"pole\.radius should be in \(0, 1e\+06\] m, got 0"):
        p.radius = 0.0
    with pytest.raises(ValueError, match=r"pole\.height should be in \(0, 1e\+06\] m, got nan"):
        p.height = float("nan")
    with pytest.raises(ValueError, match=r"pole\.base should be finite"):
        p.base = [0.0, float("inf"), 0.0]
    # accepted extremes used to pass here and fail in POV-Ray after the export
    with pytest.raises(ValueError, match=r"pole\.base should be within 1e\+06 m of the origin"):
        p.base = [1e308, 0.0, 0.0]
    with pytest.raises(ValueError, match=r"pole\.height should be in \(0, 1e\+06\] m, got 1e\+300"):
        p.height = 1e300
    assert p.radius == 0.055 and list(p.base) == [0.0, -2.5, 0.0]
    p.base = [1.0, -2.0, 0.5]
    assert list(p.base) == [1.0, -2.0, 0.5]
