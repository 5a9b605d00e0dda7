"""Self-collision and the pole inside the Simulation, checked after every step by independent
geometry (_collision_checks.py): no vertex passes through a triangle, no vertex ends closer than
half the thickness to a triangle it does not belong to, no vertex inside the pole."""

import flagsim
import numpy as np
import pytest
from _collision_checks import crossings, inside_cylinder, min_distance
from flagsim.testing.shapes import folded_onto_itself


def run_checked(sim, steps, scene, pole=None):
    """Step `steps` times; after each step count crossings over the step, the smallest vertex to
    non-incident triangle distance and the vertices inside the pole. Returns totals and extremes."""
    tris = np.asarray(sim.triangles)
    h = scene.self_collision.thickness
    out = dict(
        crossings=0, min_distance=np.inf, inside_pole=0, max_strain=0.0, contacts=0, frozen=0
    )
    for _ in range(steps):
        x0 = sim.positions.copy()
        sim.step()
        x = sim.positions
        out["crossings"] += crossings(x0, x, tris)
        out["min_distance"] = min(out["min_distance"], min_distance(x, tris, h))
        out["max_strain"] = max(out["max_strain"], sim.max_strain())
        if pole is not None:
            out["inside_pole"] += int(inside_cylinder(x, pole.radius, pole.base, pole.height).sum())
        st = sim.self_collision_stats
        if st is not None:
            out["contacts"] += st["contacts"] + st["crossings"]
            out["frozen"] += st["frozen"]
    return out


def small_flag(scene):
    scene.air.model = "none"
    scene.pole.enabled = False
    scene.flag.rows, scene.flag.cols = 10, 16
    scene.flag.width, scene.flag.height = 0.8, 0.5
    scene.self_collision.enabled = True


def test_folded_flag_dropped_onto_itself():
    s = flagsim.Scene.paper()
    small_flag(s)
    rows, cols = s.flag.rows, s.flag.cols
    s.flag.pinned_vertices = [r * cols + c for r in range(rows) for c in range(cols // 2)]
    s.flag.bend_stiffness, s.flag.areal_density = 0.2, 0.5  # a limp, heavy cloth: the fold closes
    sim = flagsim.Simulation(s)
    sim.positions = folded_onto_itself(sim, cols, rows, s.flag.width)
    top = np.arange(rows * cols).reshape(rows, cols)[:, cols // 2 + 1 :].ravel()
    start = sim.positions[top, 1].mean()
    out = run_checked(sim, 150, s)
    assert out["crossings"] == 0
    assert out["min_distance"] >= 0.5 * s.self_collision.thickness
    assert out["contacts"] > 0 and out["frozen"] == 0
    # it fell 5 cm and rests on the lower half, the thickness above it
    h = s.self_collision.thickness
    y = sim.positions[top, 1]
    assert start == pytest.approx(0.05) and 0.5 * h <= y.min() and y.mean() < 2 * h


def test_folded_flag_slammed_shut():
    # Hanging from its top edge, the front half folded over the back one and both thrown at each
    # other at 3 m/s (6 m/s closing speed): free against free.
    s = flagsim.Scene.paper()
    small_flag(s)
    s.flag.pin = "top"
    rows, cols = s.flag.rows, s.flag.cols
    sim = flagsim.Simulation(s)
    rest = np.array(sim.rest_positions)
    x, v = rest.copy(), np.zeros_like(rest)
    dx = s.flag.width / (cols - 1)
    for r in range(1, rows):
        for c in range(cols):
            i = r * cols + c
            if c >= cols // 2:
                x[i] = (rest[r * cols + (cols - 1 - c), 0] + 0.5 * dx, rest[i, 1], 0.04)
                v[i, 2] = -3.0
            else:
                v[i, 2] = 3.0
    for c in range(cols // 2, cols):  # the pinned top row stays put: fold it there too
        x[c] = (rest[cols - 1 - c, 0] + 0.5 * dx, 0.0, 0.04)
    sim.positions, sim.velocities = x, v
    out = run_checked(sim, 100, s)
    assert out["crossings"] == 0
    assert out["min_distance"] >= 0.5 * s.self_collision.thickness
    assert out["contacts"] > 0


def reversal_scene(self_collision=True, speed=8.0):
    """A 12 x 16 flag on its pole in a wind that turns against the pole and back."""
    s = flagsim.Scene.paper()
    s.air.model = "uniform"
    s.flag.rows, s.flag.cols = 12, 16
    s.self_collision.enabled = self_collision
    s.flapping.mode = "off"  # collisions under test; eq. 5 would add 0.03 m per m/s of its own
    w = speed
    s.air.wind = [
        (0.0, (w, 0, 0)),
        (0.6, (w, 0, 0)),
        (0.9, (-w, 0, 0.3 * w)),
        (1.6, (-w, 0, 0.3 * w)),
        (1.9, (w, 0, -0.3 * w)),
        (2.5, (w, 0, -0.3 * w)),
    ]
    return s


def test_wind_reversal_against_the_pole():
    s = reversal_scene()
    sim = flagsim.Simulation(s)
    assert {"pole", "self_collision"} <= set(sim.stages)
    out = run_checked(sim, 250, s, pole=s.pole)
    assert out["crossings"] == 0
    assert out["min_distance"] >= 0.5 * s.self_collision.thickness
    assert out["inside_pole"] == 0
    assert out["contacts"] > 100  # the flag did fold onto itself
    assert out["max_strain"] < 0.2  # collisions keep the cloth's strain limit (0.1) as well
    assert "self_collision" in sim.timings and sim.timings["self_collision"] > 0


def test_pole_alone_keeps_every_vertex_out():
    s = reversal_scene(self_collision=False)
    sim = flagsim.Simulation(s)
    assert "pole" in sim.stages and "self_collision" not in sim.stages
    assert sim.self_collision_stats is None
    free = ~np.asarray(sim.pinned)
    closest = np.inf
    for _ in range(250):
        sim.step()
        x = sim.positions
        assert not inside_cylinder(x, s.pole.radius, s.pole.base, s.pole.height).any()
        closest = min(
            closest, np.hypot(x[free, 0] - s.pole.base[0], x[free, 2] - s.pole.base[2]).min()
        )
    # blown onto it, not through it: held on its contact plane, 1.002 radii from the axis
    assert s.pole.radius <= closest <= 1.0021 * s.pole.radius
    assert sim.max_strain() < 0.15


def test_no_pole_no_stage():
    s = flagsim.Scene.paper()
    s.pole.enabled = False
    assert "pole" not in flagsim.Simulation(s).stages


def test_same_scene_same_bytes_with_collisions():
    s = reversal_scene(speed=6.0)
    a, b = flagsim.Simulation(s), flagsim.Simulation(s)
    a.step(150)
    b.step(150)
    assert a.positions.tobytes() == b.positions.tobytes()
    assert a.velocities.tobytes() == b.velocities.tobytes()


def test_invalid_collision_parameters_raise():
    s = flagsim.Scene.paper()
    with pytest.raises(
        ValueError, match=r"self_collision\.thickness should be finite and > 0, " r"got -0\.001"
    ):
        s.self_collision.thickness = -0.001
    with pytest.raises(ValueError, match=r"pole\.radius should be in \(0, 1e\+06\] m, got 0"):
        s.pole.radius = 0.0
    # a thickness beyond the flat flag's own vertex-to-triangle gap is refused
    s.flag.rows, s.flag.cols = 64, 96
    s.self_collision.thickness = 0.02
    s.self_collision.enabled = True
    with pytest.raises(ValueError, match=r"self_collision\.thickness should be < 0\.0"):
        flagsim.Simulation(s)
