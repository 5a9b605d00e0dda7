"""The viewer's controls (flagsim.viewer.controls), driven as the window's callbacks drive them:
pause, step, reset, the wind, flapping and integrator controls, the keys, the real-time pacing
and the panel's figures. No OpenGL needed."""

import math
import subprocess
import sys

import flagsim
import numpy as np
import pytest
from flagsim.viewer.controls import (
    KEYS,
    WIND_DIRECTION_STEP,
    WIND_SPEED_STEP,
    Controller,
    shift_keys,
    steps_for_frame,
)


class FakeClock:
    """A wall clock that moves `per_call` seconds each time it is read: each batch of steps
    seems to take exactly that long, whatever the machine."""

    def __init__(self, per_call):
        self.t = 0.0
        self.per_call = per_call

    def __call__(self):
        self.t += self.per_call
        return self.t


def paper_controller(clock=None):
    return Controller(flagsim.Simulation(flagsim.Scene.paper()), clock=clock or FakeClock(0.0))


def test_pause_play_and_single_step():
    c = paper_controller()
    dt = c.sim.scene.dt
    assert c.playing
    c.pause()
    assert c.advance(0.5) == 0 and c.sim.step_count == 0 and c.time == 0.0
    c.step()
    assert not c.playing and c.sim.step_count == 1 and c.time == pytest.approx(dt)
    c.play()
    assert c.advance(0.1) == 10 and c.time == pytest.approx(11 * dt)
    c.press("space")
    assert not c.playing and c.advance(0.2) == 0
    c.press("space")
    assert c.playing


def test_playing_keeps_the_simulated_time_on_the_wall_clock():
    # 30 frames of 1/30 s each: the simulation ends one second further (to within a step), and
    # the panel says real time, not behind.
    c = paper_controller()
    for _ in range(30):
        c.advance(1.0 / 30.0)
    assert abs(c.time - 1.0) <= c.sim.scene.dt
    st = c.stats()
    assert not st.behind and st.realtime_ratio == pytest.approx(1.0, abs=0.011)


def test_a_simulation_slower_than_real_time_is_capped_and_says_so():
    # Every batch of steps "takes" 0.5 s: the first frame learns that (10 steps in 0.5 s), the
    # next may spend only 80 % of its 0.1 s on steps, i.e. one step, and reports falling behind.
    assert steps_for_frame(0.1, 0.01, None, 0.1) == (10, False)
    assert steps_for_frame(0.1, 0.01, 0.001, 0.1) == (10, False)
    assert steps_for_frame(0.1, 0.01, 0.02, 0.1) == (4, True)
    assert steps_for_frame(0.1, 0.01, 1.0, 0.1) == (1, True)  # always at least one step
    c = paper_controller(FakeClock(0.5))
    assert c.advance(0.1) == 10 and not c.behind
    assert c.advance(0.1) == 1 and c.behind
    st = c.stats()
    assert st.behind and st.realtime_ratio == pytest.approx(0.11 / 0.2)
    # the debt is dropped, not carried: a later fast frame does not race to catch up
    c.clock.per_call = 0.0
    c._seconds_per_step = 1e-5
    assert c.advance(0.1) == 10 and not c.behind


def test_stats_split_the_stepping_time_over_the_built_stages_and_sum_the_energy():
    c = paper_controller(FakeClock(1e-3))
    for _ in range(10):
        c.advance(0.04)
    st = c.stats()
    assert set(st.stage_split) <= set(c.sim.stages) and "fluid" in st.stage_split
    assert sum(st.stage_split.values()) == pytest.approx(1.0)
    e = c.sim.energy()
    assert st.energy["total"] == pytest.approx(e["kinetic"] + e["gravity"] + e["spring"])
    assert st.steps_per_second == pytest.approx(40 / (10 * 1e-3))  # 40 steps, 1 ms per batch
    assert st.time == pytest.approx(0.4)


def test_wind_slider_turns_the_air_and_carries_the_state_over():
    c = paper_controller()
    for _ in range(10):
        c.advance(0.1)
    x, v = np.array(c.sim.positions), np.array(c.sim.velocities)
    u = np.array(c.sim.fluid.u)
    t = c.time
    c.set_wind(speed=1.5, direction=90.0)  # from +x to +z
    # the new simulation goes on from the same state and clock ...
    assert c.time == t and c.sim.time == 0.0
    np.testing.assert_array_equal(c.sim.positions, x)
    np.testing.assert_array_equal(c.sim.velocities, v)
    np.testing.assert_array_equal(c.sim.fluid.u, u)
    # ... with the wind and the paper's fan turned a quarter turn about the pole (x -> z)
    (t0, w), *rest = c.sim.scene.air.wind
    assert t0 == 0.0 and rest == [] and np.allclose(w, (0.0, 0.0, 1.5), atol=1e-12)
    fan = c.sim.scene.air.fans[0]
    assert np.allclose(fan.direction, (0.0, 0.0, 1.0), atol=1e-12)
    assert np.allclose(fan.center, (0.0, -0.27, -0.3), atol=1e-12)
    # and the flag follows it: after 1.5 s it streams towards +z, where the unchanged wind keeps
    # it in the x-y plane
    for _ in range(15):
        c.advance(0.1)
    same = paper_controller()
    for _ in range(25):
        same.advance(0.1)
    assert np.mean(c.sim.positions[:, 2]) > 0.25
    assert abs(np.mean(same.sim.positions[:, 2])) < 0.05
    assert np.mean(same.sim.positions[:, 0]) > np.mean(c.sim.positions[:, 0]) + 0.15


def test_wind_keys_step_speed_and_direction_and_bad_values_are_refused():
    c = paper_controller()
    c.press("+")
    assert c.wind_speed == 1.5 + WIND_SPEED_STEP
    assert np.allclose(c.sim.scene.air.wind[0][1], (2.0, 0.0, 0.0))
    c.press("]")
    c.press("]")
    assert c.wind_direction == pytest.approx(2 * WIND_DIRECTION_STEP)
    c.press("[")
    c.press("-")
    a = math.radians(WIND_DIRECTION_STEP)
    assert np.allclose(c.sim.scene.air.wind[0][1], (1.5 * math.cos(a), 0.0, 1.5 * math.sin(a)))
    scene = c.sim.scene
    with pytest.raises(ValueError, match=r"wind speed should be in \[0, 50\] m/s, got -1.0"):
        c.set_wind(speed=-1.0)
    with pytest.raises(ValueError, match="wind direction should be finite"):
        c.set_wind(direction=float("nan"))
    assert c.sim.scene.air.wind == scene.air.wind  # nothing changed
    still = flagsim.Scene.paper()
    still.air.model = "none"
    with pytest.raises(ValueError, match="no wind to change"):
        Controller(flagsim.Simulation(still)).press("+")
    with pytest.raises(ValueError, match="key should be one of"):
        c.press("q")


def test_a_control_whose_scene_is_refused_changes_nothing(monkeypatch):
    c = paper_controller()
    sim = c.sim

    def refuse(scene):
        raise ValueError(f"air.wind refused: {scene.air.wind}")

    monkeypatch.setattr(flagsim, "Simulation", refuse)
    with pytest.raises(ValueError, match="air.wind refused"):
        c.set_wind(speed=3.0, direction=90.0)
    with pytest.raises(ValueError, match="refused"):
        c.set_flapping("off")
    assert (c.sim, c.wind_speed, c.wind_direction, c.wind_set, c.flapping) == (
        sim,
        1.5,
        0.0,
        False,
        "displace",
    )


def test_flapping_and_integrator_controls_rebuild_with_the_chosen_stage():
    c = paper_controller()
    c.advance(0.2)
    assert "flap" in c.sim.stages
    c.press("f")  # displace -> force
    assert c.sim.scene.flapping.mode == "force" and "flap" in c.sim.stages
    c.set_flapping("visual")
    c.advance(0.1)
    # visual: the drawn flag is displaced along the normals, the simulated one is not
    drawn, _ = c.mesh()
    assert np.abs(drawn - c.sim.positions).max() > 1e-4
    c.set_flapping("off")
    assert "flap" not in c.sim.stages
    drawn, _ = c.mesh()
    np.testing.assert_array_equal(drawn, c.sim.positions)
    with pytest.raises(ValueError, match="flapping mode should be one of displace, force"):
        c.set_flapping("wave")
    c.press("i")
    assert c.integrator == "explicit" and c.sim.scene.integrator.method == "explicit"
    x = np.array(c.sim.positions)
    c.advance(0.3)  # the explicit integrator goes on from the implicit one's state
    assert np.all(np.isfinite(c.sim.positions)) and np.abs(c.sim.positions - x).max() < 0.1
    assert c.time == pytest.approx(0.6)
    with pytest.raises(ValueError, match="integrator should be one of implicit, explicit"):
        c.set_integrator("verlet")


def test_a_scene_of_several_flags_is_drawn_and_controlled_whole():
    # The gallery's row of four flags on their own poles (docs/multiflag.md): the mesh holds
    # every flag, the flapping and integrator controls reach every flag, and a rebuild carries
    # every flag's state over.
    from flagsim.povray.mesh import mesh_arrays

    scene = flagsim.scene.resolve("flag_row")
    c = Controller(flagsim.Simulation(scene), clock=FakeClock(0.0))
    c.advance(0.2)
    flags = c.sim.flags
    assert len(flags) == 4
    x, n = c.mesh()
    triangles, uv = c.topology()
    np.testing.assert_array_equal(x, np.concatenate([f.render_positions for f in flags]))
    assert n.shape == x.shape and uv.shape == (len(x), 2) and triangles.max() == len(x) - 1
    np.testing.assert_array_equal(triangles, mesh_arrays(c.sim)[3])
    before = [(np.array(f.positions), np.array(f.velocities)) for f in flags]
    c.set_flapping("off")
    c.set_integrator("explicit")
    assert [s.flapping.mode for s in c.sim.scene.flags] == ["off"] * 4
    assert [s.integrator.method for s in c.sim.scene.flags] == ["explicit"] * 4
    for f, (p, v) in zip(c.sim.flags, before):
        np.testing.assert_array_equal(f.positions, p)
        np.testing.assert_array_equal(f.velocities, v)
    np.testing.assert_array_equal(c.mesh()[0], np.concatenate([p for p, _ in before]))


def test_reset_starts_again_with_the_current_controls():
    c = paper_controller()
    c.advance(0.3)
    c.set_wind(speed=2.0)
    c.advance(0.3)
    c.press("r")
    assert c.time == 0.0 and c.sim.step_count == 0
    np.testing.assert_array_equal(c.sim.positions, flagsim.Simulation(c.sim.scene).positions)
    assert np.allclose(c.sim.scene.air.wind[0][1], (2.0, 0.0, 0.0))
    assert c.playing  # the play state is kept


def test_every_key_in_the_help_does_what_it_says():
    c = paper_controller()
    for _, _, action, imgui_keys in KEYS:
        assert callable(getattr(c, action)) and imgui_keys
    before = (c.playing, c.show_air, c.flapping, c.integrator)
    for key in ("space", "v", "f", "i"):
        c.press(key)
    assert (c.playing, c.show_air, c.flapping, c.integrator) == (
        not before[0],
        not before[1],
        "force",
        "explicit",
    )
    c.press("n")
    assert c.sim.step_count == 1 and not c.playing


def test_keyframed_wind_goes_on_across_a_rebuild():
    # A rebuild (here: flapping visual, then off again, which leaves the physics alone) starts a
    # new Simulation at time 0 with the schedule shifted, so the flag goes on as if nothing had
    # happened; only the implicit solver's warm start differs (CG to its tolerance).
    scene = flagsim.Scene.banner()
    scene.flapping.mode = "off"
    scene.air.wind = [(0.0, (0.0, 0.0, 1.0)), (1.0, (0.0, 0.0, 3.0))]
    c = Controller(flagsim.Simulation(scene), clock=FakeClock(0.0))
    ref = flagsim.Simulation(scene)
    c.advance(0.5)
    c.set_flapping("visual")
    c.set_flapping("off")
    assert c.sim.scene.air.wind == [(0.0, (0.0, 0.0, 2.0)), (0.5, (0.0, 0.0, 3.0))]
    c.advance(1.0)
    ref.step(150)
    assert c.time == pytest.approx(ref.time)
    assert np.abs(c.sim.positions - ref.positions).max() < 1e-6  # measured 8e-9; unshifted 0.06


def test_shift_keys_holds_the_ends_and_interpolates_between():
    keys = [(0.0, (1.0, 0.0, 0.0)), (2.0, (3.0, 0.0, 0.0))]
    assert shift_keys(keys, 0.0) == keys
    assert shift_keys(keys, 0.5) == [(0.0, (1.5, 0.0, 0.0)), (1.5, (3.0, 0.0, 0.0))]
    assert shift_keys(keys, 5.0) == [(0.0, (3.0, 0.0, 0.0))]
    assert shift_keys([(1.0, 2.0), (3.0, 4.0)], 0.5) == [(0.5, 2.0), (2.5, 4.0)]


def test_the_viewer_and_usd_modules_load_polyscope_and_pxr_only_when_drawing_or_writing():
    # `import flagsim` loads neither (tests/python/test_scene.py); neither do the controls, the
    # USD module, or `flagsim view --help`, in a fresh interpreter
    code = (
        "import sys, flagsim, flagsim.viewer, flagsim.usd; from flagsim import cli\n"
        "flagsim.viewer.Controller(flagsim.Simulation(flagsim.Scene.paper())).advance(0.02)\n"
        "try:\n    cli.main(['view', '--help'])\nexcept SystemExit:\n    pass\n"
        "print([m for m in ('polyscope', 'polyscope_bindings', 'pxr') if m in sys.modules])"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip().splitlines()[-1] == "[]"
