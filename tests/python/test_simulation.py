"""The Simulation from Python: physics, views, divergence handling, determinism."""

import gc
import math
import time
import weakref

import flagsim
import numpy as np
import pytest
from conftest import spring_pair


@pytest.mark.parametrize("method", ["explicit", "implicit"])
def test_spring_pair_error_falls_at_first_order(method):
    probe = flagsim.Simulation(spring_pair(method))
    m = probe.node_mass[3]
    k = 100.0
    T = 2 * math.pi * math.sqrt(m / k)
    errs = []
    for div in (100, 200, 400):
        sim = flagsim.Simulation(spring_pair(method, k, T / div))
        y0 = sim.positions[3, 1]
        sim.positions[3, 1] -= 1e-4
        worst = 0.0
        for _ in range(div):
            sim.step()
            exact = -1e-4 * math.cos(math.sqrt(k / m) * sim.time)
            worst = max(worst, abs(sim.positions[3, 1] - y0 - exact) / 1e-4)
        errs.append(worst)
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((orders > 0.85) & (orders < 1.2)), orders


def test_banner_settles_at_analytic_angle():
    s = flagsim.Scene.banner()
    s.dt = 0.02
    sim = flagsim.Simulation(s)
    sim.step(1500)
    u = np.linalg.norm(s.air.wind[0][1])
    want = math.atan(
        0.5 * s.drag.coefficient * s.air.density * u * u / (s.flag.areal_density * 9.81)
    )
    x = sim.positions.reshape(s.flag.rows, s.flag.cols, 3)
    d = x[1:] - x[:1]
    assert np.abs(np.arctan2(d[..., 2], -d[..., 1]) - want).max() < 1e-6


def stiff(method, adaptive):
    s = flagsim.Scene.paper()
    s.flag.stretch_stiffness = s.flag.shear_stiffness = s.flag.bend_stiffness = 1e6
    s.integrator.method = method
    s.integrator.adaptive = adaptive
    s.flapping.mode = "off"  # eq. 5 displaces positions directly: the integrator is under test
    return s


def test_implicit_stable_with_stiff_springs():
    sim = flagsim.Simulation(stiff("implicit", False))
    sim.step(100)
    assert np.isfinite(sim.positions).all()
    assert sim.max_strain() < 0.01


def test_explicit_adaptive_substeps_on_stiff_springs():
    sim = flagsim.Simulation(stiff("explicit", True))
    sim.step(5)
    assert sim.last_step_stats["substeps"] > 10
    assert sim.max_strain() < 0.01


def test_explicit_without_substeps_unstable_at_rest_is_rejected_before_any_step():
    with pytest.raises(ValueError, match=r"^integrator\.substeps should be >= \d+ .*got 1$"):
        flagsim.Simulation(stiff("explicit", False))


def test_explicit_step_that_becomes_unstable_raises_and_restores_state():
    # stable at rest (the stable step is 0.95 ms); a gust to 1000 m/s raises the drag slope
    # beyond what dt allows
    s = flagsim.Scene.paper()
    s.air.model = "uniform"
    s.air.wind = [(0.0, (2.0, 0.0, 0.0)), (0.02, (2.0, 0.0, 0.0)), (0.1, (1000.0, 0.0, 0.0))]
    s.flapping.mode = "off"
    s.integrator.method, s.integrator.adaptive, s.integrator.energy_tolerance = "explicit", False, 0
    s.dt = 5e-4
    sim = flagsim.Simulation(s)
    for _ in range(200):
        x, v, n = sim.positions.copy(), sim.velocities.copy(), sim.step_count
        try:
            sim.step()
        except flagsim.DivergenceError as e:
            assert np.array_equal(sim.positions, x) and np.array_equal(sim.velocities, v)
            assert sim.step_count == n == e.step and n > 40
            assert e.cause == "unstable_step"
            assert math.isclose(e.time, n * sim.scene.dt)
            assert "diverged at step" in str(e) and "restored" in str(e)
            return
        assert np.isfinite(sim.positions).all()
    pytest.fail("a gust to 1000 m/s never made the explicit step unstable")


def test_positions_are_views_that_outlive_their_name(paper):
    sim = flagsim.Simulation(paper)
    p = sim.positions
    assert p.base is not None and p.flags.writeable and not p.flags.owndata
    assert np.shares_memory(p, sim.positions)  # no copy per access
    ref = weakref.ref(sim)
    sim.step(3)
    moved = p.copy()
    del sim
    gc.collect()
    assert ref() is not None  # the view keeps the simulation alive
    assert np.array_equal(p, moved)
    assert p.shape == (88, 3) and p.dtype == np.float64


def test_setting_positions_copies_into_the_same_buffer(paper):
    sim = flagsim.Simulation(paper)
    view = sim.positions
    new = sim.rest_positions + [0.0, 0.0, 0.01]
    sim.positions = new
    assert np.array_equal(view, new)
    assert np.allclose(sim.normals[:, 2], 1.0)
    with pytest.raises(ValueError, match=r"positions should have shape \(88, 3\)"):
        sim.positions = np.zeros((3, 3))
    bad = new.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"positions\[5\] should be finite"):
        sim.positions = bad
    assert np.array_equal(view, new)  # unchanged by the rejected assignment


def test_read_only_arrays_and_sizes(paper):
    sim = flagsim.Simulation(paper)
    assert sim.triangles.dtype == np.int32 and sim.triangles.shape == (2 * 7 * 10, 3)
    assert sim.uv.shape == (88, 2) and sim.uv.min() == 0 and sim.uv.max() == 1
    assert not sim.normals.flags.writeable
    with pytest.raises(ValueError):
        sim.normals[0, 0] = 1
    assert sim.pinned.sum() == paper.flag.rows
    assert math.isclose(
        sim.node_mass.sum(), paper.flag.areal_density * paper.flag.width * paper.flag.height
    )
    assert np.allclose(sim.node_mass, paper.flag.areal_density * sim.node_area)


def test_same_scene_twice_gives_identical_bytes(paper):
    paper.air.wind = [(0.0, (1.0, 0.0, 0.5)), (1.0, (6.0, 0.0, -2.0))]
    a, b = flagsim.Simulation(paper), flagsim.Simulation(paper)
    a.step(150)
    b.step(150)
    assert a.positions.tobytes() == b.positions.tobytes()
    assert a.velocities.tobytes() == b.velocities.tobytes()


def test_stages_leave_out_what_the_scene_does_not_need(paper):
    stages = set(flagsim.Simulation(paper).stages)
    assert {"fluid", "gravity", "drag", "springs", "integrate"} <= stages and "wind" not in stages
    paper.gravity = (0, 0, 0)
    paper.air.model = "none"
    sim = flagsim.Simulation(paper)
    assert not {"wind", "fluid", "gravity", "drag"} & set(sim.stages)
    sim.step(5)
    assert set(sim.timings) == set(sim.stages)
    assert all(t > 0 for t in sim.timings.values()), sim.timings  # each stage ran, timed


def test_energy_and_time(paper):
    sim = flagsim.Simulation(paper)
    e0 = sim.energy()
    # the seeded imperfection (0.1 mm out of plane) stretches the springs by ~1e-11 J
    assert e0["kinetic"] == 0 and 0 <= e0["spring"] < 1e-9
    sim.step(100)
    assert sim.time == pytest.approx(1.0, abs=1e-12) and sim.step_count == 100
    assert sim.energy()["gravity"] < e0["gravity"]  # it sagged
    pts = np.array([[0.0, 0.0, 0.0], [5.0, 1.0, 2.0]])
    assert sim.fluid.time == pytest.approx(1.0, abs=1e-12)  # the air grid keeps pace
    np.testing.assert_array_equal(sim.air_velocity(pts), sim.fluid.sample(pts))


def test_step_rejects_negative_count(paper):
    sim = flagsim.Simulation(paper)
    with pytest.raises(ValueError, match="n should be >= 0, got -1"):
        sim.step(-1)


def test_a_second_thread_stepping_the_same_simulation_is_refused():
    # step() releases the GIL; two threads stepping one Simulation used to interleave its stages
    # (spurious DivergenceErrors, step_count 545 instead of 1000). The second is now refused and
    # the first one's steps all count.
    import threading

    s = flagsim.Scene.paper()
    s.air.model = "uniform"
    s.flag.rows = s.flag.cols = 48  # long enough steps for the calls to overlap
    sim = flagsim.Simulation(s)
    errors, worker_errors = [], []

    def long_run():
        try:
            sim.step(60)
        except RuntimeError as e:  # refused: this thread's call came second after all
            worker_errors.append(e)

    t = threading.Thread(target=long_run)
    t.start()
    while sim.step_count == 0 and t.is_alive():  # until the long call is under way
        time.sleep(0.0005)
    assert not worker_errors
    done = 0  # steps this thread got in before the other call began
    while t.is_alive():
        try:
            sim.step(1)
            done += 1
        except RuntimeError as e:
            errors.append(str(e))
            t.join(0.01)
    t.join()
    assert errors and all("another thread is stepping this Simulation" in e for e in errors)
    assert sim.step_count == 60 + done  # every accepted step counted once, none interleaved
    sim.step(1)  # free again once the other call returned
    assert sim.step_count == 61 + done
