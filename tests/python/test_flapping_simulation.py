"""Flapping (paper eq. 5) inside the Simulation: the displacement it applies, its modes, u_p, the
flapping demo of paper §4.3 and the scene/TOML plumbing."""

import flagsim
import numpy as np
import pytest
from _perlin_reference import reference_eq5


def quiet_scene(mode="displace", wind=2.0, ramp=0.0):
    """The paper's flag with nothing moving it but eq. 5: uniform air of zero density (no drag,
    the wind only sets u_p), no gravity, no strain limiting (which would answer the wave); the
    whole wave from the first step (flapping.ramp = 0, the paper's start) unless `ramp` says."""
    s = flagsim.Scene.paper()
    s.air.model = "uniform"
    s.air.wind = (wind, 0.0, 0.0)
    s.air.density = 0.0
    s.gravity = (0.0, 0.0, 0.0)
    s.integrator.strain_limit = 0.0
    s.flag.imperfection = 0.0  # flat: eq. 5 alone moves it
    f = s.flapping
    f.mode, f.amplitude, f.l_max, f.speed, f.parabola, f.frequency, f.seed = (
        mode,
        0.02,
        0.25,
        0.8,
        1.3,
        3.5,
        11,
    )
    f.ramp = ramp
    return s


def eq5_inputs(sim):
    """(x, y, L) of eq. 5 from the simulation's rest state, computed here: uv, and the rest
    distance of each vertex to its nearest pinned vertex."""
    rest = np.asarray(sim.rest_positions)
    pins = rest[np.asarray(sim.pinned)]
    L = np.min(np.linalg.norm(rest[:, None, :] - pins[None, :, :], axis=2), axis=1)
    uv = np.asarray(sim.uv)
    return uv[:, 0], uv[:, 1], L


def test_displacement_with_dynamics_frozen_is_eq5_at_every_vertex():
    # From rest with no force acting, one step moves each vertex by exactly eq. 5 along its
    # normal (+z for the flat flag), evaluated at the end of the step. The whole wave at once
    # (ramp 0) stretches the springs across by fourth order in its amplitude: at 0.02 m/(m/s)
    # that is 0.13 J, the scene's whole energy scale, and the check redoes the step in pieces
    # (the springs then move the cloth in-plane); at 0.005 it is ~5e-4 J, a plausible jump.
    s = quiet_scene()
    s.flapping.amplitude = 0.005
    sim = flagsim.Simulation(s)
    rest = np.array(sim.rest_positions)
    x, y, L = eq5_inputs(sim)
    assert np.all(L[np.asarray(sim.pinned)] == 0) and L.max() > s.flapping.l_max
    sim.step()
    z = reference_eq5(x, y, L, 2.0, s.dt, s.flapping)
    assert np.abs(z).max() > 0.003  # a real displacement, not zeros
    assert sim.last_step_stats["energy_halvings"] == 0
    np.testing.assert_allclose(sim.positions[:, :2], rest[:, :2], rtol=0, atol=1e-14)
    np.testing.assert_allclose(sim.positions[:, 2] - rest[:, 2], z, rtol=0, atol=1e-14)
    np.testing.assert_allclose(sim.flap_displacement, z, rtol=0, atol=1e-15)
    assert sim.pole_air_speed == pytest.approx(2.0)


def test_the_wave_fades_in_over_the_ramp_from_a_flat_flag():
    # flapping.ramp = 0.05 s: after one step of 0.01 s eq. 5 is scaled by the smoothstep
    # S(0.2) = 0.104 (reference_eq5 computes S independently); the flag starts flat.
    s = quiet_scene(ramp=0.05)
    sim = flagsim.Simulation(s)
    rest = np.array(sim.rest_positions)
    np.testing.assert_array_equal(sim.positions, rest)
    x, y, L = eq5_inputs(sim)
    sim.step()
    z = reference_eq5(x, y, L, 2.0, s.dt, s.flapping)
    full = reference_eq5(x, y, L, 2.0, s.dt, quiet_scene().flapping)
    np.testing.assert_allclose(z, 0.104 * full, rtol=1e-12, atol=0)
    np.testing.assert_allclose(sim.positions[:, 2] - rest[:, 2], z, rtol=0, atol=1e-14)


def test_visual_mode_changes_only_the_exported_geometry():
    s_off = quiet_scene(mode="off")
    s_off.air.density = 1.2
    s_off.gravity = (0.0, -9.81, 0.0)
    s_off.air.wind = [(0.0, (2.0, 0.0, 0.5)), (1.0, (5.0, 0.0, -1.0))]
    s_vis = flagsim.Scene.from_dict(s_off.to_dict())
    s_vis.flapping.mode = "visual"
    off, vis = flagsim.Simulation(s_off), flagsim.Simulation(s_vis)
    assert "flap" not in off.stages and vis.stages[-1] == "flap"
    x, y, L = eq5_inputs(vis)
    for _ in range(6):
        off.step(10)
        vis.step(10)
        np.testing.assert_array_equal(vis.positions, off.positions)  # physics untouched
        np.testing.assert_array_equal(off.render_positions, off.positions)
        speed = np.mean(
            np.linalg.norm(vis.air_velocity(vis.rest_positions[:: s_vis.flag.cols]), axis=1)
        )
        assert vis.pole_air_speed == pytest.approx(speed, rel=1e-12)
        z = reference_eq5(x, y, L, speed, vis.time, s_vis.flapping)
        np.testing.assert_allclose(vis.flap_displacement, z, rtol=0, atol=1e-15)
        np.testing.assert_allclose(
            vis.render_positions, vis.positions + z[:, None] * vis.normals, rtol=0, atol=1e-14
        )
    assert not vis.render_positions.flags.writeable
    # the rendered normals belong to the rendered surface, not to the physics one
    assert np.abs(vis.render_normals - vis.normals).max() > 1e-3
    np.testing.assert_allclose(np.linalg.norm(vis.render_normals, axis=1), 1.0, atol=1e-12)


def test_air_speed_at_the_pole_follows_the_wind_schedule():
    s = quiet_scene(mode="visual")
    s.air.wind = [(0.0, (1.0, 0.0, 0.0)), (1.0, (3.0, 0.0, 4.0))]
    sim = flagsim.Simulation(s)
    for _ in range(5):
        sim.step(20)
        t = min(sim.time, 1.0)
        assert sim.pole_air_speed == pytest.approx(np.hypot(1.0 + 2.0 * t, 4.0 * t), rel=1e-12)


def test_air_speed_at_the_pole_follows_the_computed_air():
    s = flagsim.Scene.paper()
    s.air.model = "grid"
    s.flapping.mode = "visual"
    sim = flagsim.Simulation(s)
    edge = np.asarray(sim.rest_positions)[:: s.flag.cols]
    speeds = []
    for _ in range(4):
        sim.step(5)
        expected = np.mean(np.linalg.norm(sim.air_velocity(edge), axis=1))
        assert sim.pole_air_speed == pytest.approx(expected, rel=1e-12)
        speeds.append(sim.pole_air_speed)
    assert speeds[0] > 0 and len(set(speeds)) > 1  # the grid's air, changing as it develops


def wave_lags(sim, rows, cols, intervals=16, every=10, max_lag=6):
    """Columns by which the flag's z pattern moves along +x in `every` steps, per interval:
    the shift minimising the mismatch of consecutive snapshots."""
    lags = []
    for _ in range(intervals):
        a = sim.positions[:, 2].reshape(rows, cols).copy()
        sim.step(every)
        b = sim.positions[:, 2].reshape(rows, cols).copy()
        err = {}
        for lag in range(-max_lag, max_lag + 1):
            d = b[:, lag:] - a[:, : cols - lag] if lag >= 0 else b[:, : cols + lag] - a[:, -lag:]
            err[lag] = np.mean(d**2)
        lags.append(min(err, key=err.get))
    return np.array(lags)


@pytest.mark.parametrize("mode", ["displace", "force"])
def test_flapping_demo_wave_front_moves_away_from_the_pole(mode):
    s = flagsim.Scene.flapping_demo()
    s.flapping.mode = mode
    sim = flagsim.Simulation(s)
    assert not {"wind", "fluid", "drag"} & set(sim.stages)  # no air solver, no drag
    assert tuple(s.gravity) == (9.81, 0.0, 0.0)  # every mass pulled along +x
    rows, cols = s.flag.rows, s.flag.cols
    pinned = np.asarray(sim.pinned)
    rest = np.array(sim.rest_positions)
    sim.step(100)
    lags = wave_lags(sim, rows, cols)
    # eq. 5 moves the pattern v = 1 flag length per second: 0.1 s is 2.3 columns of 23. In
    # "force" the integrator solves the force with the springs and damping, which answer it
    # (a response of ~2 mm against ~10 mm displaced) and add the cloth's own waves: 12 of the
    # 16 intervals follow eq. 5's, all 16 with "displace".
    assert np.mean(lags > 0) >= (0.8 if mode == "displace" else 0.7), lags
    assert 1.5 <= np.median(lags) <= 3, lags
    np.testing.assert_array_equal(sim.positions[pinned], rest[pinned])
    assert np.abs(sim.positions[:, 2]).max() > 1e-3  # it flaps


def test_builtin_flapping_demo_is_registered():
    assert "flapping_demo" in flagsim.Scene.builtins()
    s = flagsim.Scene.named("flapping_demo")
    assert s.flapping.mode == "displace" and s.air.density == 0.0


def test_flapping_sections_load_from_toml(tmp_path):
    f = tmp_path / "flap.toml"
    f.write_text(
        'base = "paper"\n'
        '[flapping]\nmode = "visual"\namplitude = 0.03\nl_max = 0.1\nspeed = 0.5\n'
        "parabola = 2.0\nfrequency = 4.0\nseed = 7\n"
        "[self_collision]\nenabled = true\nthickness = 0.004\nfriction = 0.3\n"
        "iterations = 12\n"
        "[pole]\nradius = 0.03\nheight = 3.0\nbase = [0.0, -2.9, 0.0]\n"
    )
    s = flagsim.Scene.load(f)
    assert (s.flapping.mode, s.flapping.amplitude, s.flapping.seed) == ("visual", 0.03, 7)
    assert (s.self_collision.enabled, s.self_collision.thickness, s.self_collision.iterations) == (
        True,
        0.004,
        12,
    )
    assert s.pole.radius == 0.03 and tuple(s.pole.base) == (0.0, -2.9, 0.0)
    assert flagsim.Scene.from_dict(s.to_dict()).to_dict() == s.to_dict()
    f.write_text("[flapping]\nwobble = 1\n")
    with pytest.raises(ValueError, match=r"unknown key 'wobble' in section \[flapping\]"):
        flagsim.Scene.load(f)
    f.write_text('[flapping]\nmode = "wobble"\n')
    with pytest.raises(ValueError, match=r"flapping\.mode should be one of"):
        flagsim.Scene.load(f)


def test_invalid_flapping_parameters_raise():
    s = flagsim.Scene.paper()
    before = repr(s.flapping)
    with pytest.raises(ValueError, match=r"flapping\.l_max should be finite and > 0, got 0"):
        s.flapping.l_max = 0.0
    with pytest.raises(ValueError, match=r"flapping\.mode should be one of"):
        s.flapping.mode = "sometimes"
    after = repr(s.flapping)
    assert after == before  # rejected values leave the scene as it was
