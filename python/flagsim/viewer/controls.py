"""The viewer's controls as plain Python: what play, pause, step, reset and the sliders do to the
simulation, the real-time pacing and the panel's figures. No drawing happens here (window.py draws
and calls these), so tests drive a Controller exactly as the window's callbacks do.

Changing the wind, the flapping mode or the integrator rebuilds the Simulation from the changed
scene (a Simulation's scene is fixed once built) and carries the state over: positions,
velocities and, with an air grid, its velocity field. The clock the panel shows goes on; the new
Simulation's own time starts at 0, so a keyframed wind is replaced by the steady wind the slider
sets, and the flapping wave fades in again over `flapping.ramp` (docs/viewer.md).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..povray.mesh import flags_of, mesh_arrays

#: keyboard shortcuts of the live window: (key, what it does, Controller method, ImGui key
#: names). `flagsim view --help` lists them; Controller.press(key) does what they do.
KEYS = (
    ("space", "play / pause", "toggle", ("Space",)),
    ("n", "pause and advance one step", "step", ("N",)),
    ("r", "reset: start the scene again with the current controls", "reset", ("R",)),
    (
        "+",
        "wind speed up by 0.5 m/s (a steady wind from then on)",
        "wind_up",
        ("Equal", "KeypadAdd"),
    ),
    ("-", "wind speed down by 0.5 m/s", "wind_down", ("Minus", "KeypadSubtract")),
    ("]", "turn the wind by +15 degrees (from +x towards +z)", "turn_wind_up", ("RightBracket",)),
    ("[", "turn the wind by -15 degrees", "turn_wind_down", ("LeftBracket",)),
    ("f", "next flapping mode (displace, force, visual, off)", "next_flapping", ("F",)),
    ("i", "switch the integrator (implicit <-> explicit)", "other_integrator", ("I",)),
    ("v", "show / hide the air slice (speed colours and arrows)", "toggle_air", ("V",)),
)

FLAPPING_MODES = ("displace", "force", "visual", "off")
INTEGRATORS = ("implicit", "explicit")
WIND_SPEED_STEP = 0.5  # m/s per key press
WIND_DIRECTION_STEP = 15.0  # degrees per key press
MAX_WIND_SPEED = 50.0  # m/s: a storm is ~25 m/s; beyond this the slider is a typo
STATS_WINDOW = 1.0  # s of wall time the panel's rates are averaged over
FRAME_BUDGET = 0.8  # fraction of a frame's wall time the steps may take (the rest draws)


def horizontal_wind(wind):
    """(speed m/s, direction degrees, vertical m/s) of a wind vector: speed and direction in the
    horizontal x-z plane, direction measured from +x towards +z."""
    wx, wy, wz = (float(c) for c in wind)
    speed = math.hypot(wx, wz)
    direction = math.degrees(math.atan2(wz, wx)) if speed > 0 else 0.0
    return speed, direction, wy


def wind_vector(speed, direction, vertical=0.0):
    """The wind (3,) m/s from a horizontal speed, a direction (degrees from +x towards +z) and a
    vertical component."""
    a = math.radians(direction)
    return (speed * math.cos(a), float(vertical), speed * math.sin(a))


def _turn(v, degrees, centre=(0.0, 0.0, 0.0)):
    """v turned about the vertical axis through `centre` by `degrees` (+x towards +z)."""
    a = math.radians(degrees)
    x, y, z = (float(v[i]) - float(centre[i]) for i in range(3))
    c, s = math.cos(a), math.sin(a)
    return (centre[0] + c * x - s * z, centre[1] + y, centre[2] + s * x + c * z)


def shift_keys(keys, t0):
    """Piecewise-linear keyframes [(t, value), ...] (held before the first key and after the
    last, as WindSchedule::at) as seen by a simulation that starts at t0: the value at t0 becomes
    the key at 0 and the later keys move back by t0."""
    keys = [(float(t), v) for t, v in keys]
    if t0 <= keys[0][0]:
        return [(t - t0, v) for t, v in keys]
    if t0 >= keys[-1][0]:
        return [(0.0, keys[-1][1])]
    i = next(i for i in range(1, len(keys)) if keys[i][0] > t0)
    (ta, va), (tb, vb) = keys[i - 1], keys[i]
    return [(0.0, _lerp(va, vb, (t0 - ta) / (tb - ta)))] + [(t - t0, v) for t, v in keys[i:]]


def _lerp(a, b, f):
    if isinstance(a, (tuple, list)):
        return tuple(float(x) + f * (float(y) - float(x)) for x, y in zip(a, b))
    return float(a) + f * (float(b) - float(a))


def steps_for_frame(owed, dt, seconds_per_step, wall_seconds, budget=FRAME_BUDGET):
    """How many steps a frame takes to keep the simulation on the wall clock.

    owed              simulated seconds the simulation is behind the wall clock (this frame's
                      wall time included)
    seconds_per_step  measured cost of one step (0 or None: unknown, no cap)
    wall_seconds      the frame's wall time; the steps may take `budget` of it

    Returns (steps, behind): the whole steps owed, capped at what fits in the budget (at least
    one); behind is True when the cap cut them, i.e. the simulation cannot keep up with real time.
    """
    n = int(math.floor(owed / dt + 1e-9)) if owed > 0 else 0
    if not seconds_per_step or n <= 1:
        return n, False
    cap = max(1, int(budget * wall_seconds / seconds_per_step))
    return (cap, True) if n > cap else (n, False)


@dataclass
class Stats:
    """What the panel shows."""

    steps_per_second: float  # steps per second spent stepping (the simulation's own speed)
    realtime_ratio: float  # simulated / wall time over the last STATS_WINDOW s (real time = 1.0)
    behind: bool  # the last frames could not keep up with real time
    stage_split: dict  # stage -> fraction of the stepping time over the window
    energy: dict  # kinetic, gravity, spring, total (J), sim.energy()
    time: float  # simulated time shown, s


class Controller:
    """The state behind the viewer: the simulation, the controls and the real-time pacing.

    sim    a flagsim.Simulation; reset goes back to its scene's initial state
    clock  wall clock that times the steps (time.perf_counter)
    """

    def __init__(self, sim, *, clock=time.perf_counter):
        import flagsim

        self._flagsim = flagsim
        self.base_scene = sim.scene  # a copy: every rebuilt scene derives from it
        self.clock = clock
        self.playing = True
        self.show_air = False
        self.behind = False
        air = self.base_scene.air
        self.has_wind = air.model != "none" and len(air.wind) > 0
        w0 = air.wind[0][1] if self.has_wind else (0.0, 0.0, 0.0)
        self.wind_speed, self.wind_direction, self._wind_vertical = horizontal_wind(w0)
        self._base_direction = self.wind_direction
        self.wind_set = False  # the slider has set a steady wind (else: the scene's schedule)
        self.flapping = self.base_scene.flapping.mode
        self.integrator = self.base_scene.integrator.method
        self._seconds_per_step = None  # running estimate of one step's cost, s
        self._install(sim, time_offset=0.0, carried=False)

    def _install(self, sim, *, time_offset, carried):
        self.sim = sim
        self.time_offset = time_offset  # simulated time before this Simulation's start, s
        self._carried = carried  # state copied in, not stepped yet (render geometry stale)
        self._owed = 0.0  # simulated seconds owed to the wall clock
        self._window = deque()  # per frame: (wall s, simulated s, stepping s, steps, timings)
        self._window_start = dict(sim.timings)  # stage timings before the window's first frame

    # --- the scene the controls describe -------------------------------------------------
    def scene(self, start=0.0):
        """The base scene with the current controls, for a Simulation that starts at simulated
        time `start`: keyframed schedules (wind, fan strengths) are shifted by it, unless the
        wind slider has set a steady wind."""
        s = self._flagsim.Scene.from_dict(self.base_scene.to_dict())
        if self.has_wind:
            fans = list(s.air.fans)
            if self.wind_set:
                s.air.wind = [
                    (0.0, wind_vector(self.wind_speed, self.wind_direction, self._wind_vertical))
                ]
                turn = self.wind_direction - self._base_direction
                pole = self.base_scene.pole
                centre = tuple(pole.base) if pole.enabled else (0.0, 0.0, 0.0)
                for fan in fans:  # the air's set-up turns as a whole: the fans with the wind
                    fan.direction = _turn(fan.direction, turn)
                    fan.center = _turn(fan.center, turn, centre)
            else:
                s.air.wind = shift_keys(s.air.wind, start)
            for fan in fans:
                if len(fan.strength) > 0:
                    fan.strength = shift_keys(fan.strength, start)
            s.air.fans = fans
        specs = list(s.flags)  # every flag follows the controls (s.flapping is flag 0's)
        for spec in specs:
            spec.flapping.mode = self.flapping
            spec.integrator.method = self.integrator
        s.flags = specs
        return s

    @property
    def time(self):
        """Simulated time since the start or the last reset, s (goes on across rebuilds)."""
        return self.time_offset + self.sim.time

    # --- buttons -------------------------------------------------------------------------
    def play(self):
        self.playing = True
        self._owed = 0.0

    def pause(self):
        self.playing = False
        self._owed = 0.0

    def toggle(self):
        if self.playing:
            self.pause()
        else:
            self.play()

    def step(self):
        """Pause and advance exactly one step of scene.dt."""
        self.pause()
        self._step(1, wall_seconds=0.0)

    def reset(self):
        """Start the scene again from its initial state with the current controls (the play
        state is kept)."""
        self._install(self._flagsim.Simulation(self.scene()), time_offset=0.0, carried=False)

    # --- sliders -------------------------------------------------------------------------
    def set_wind(self, speed=None, direction=None):
        """A steady wind of `speed` m/s (horizontal) towards `direction` degrees (from +x towards
        +z; the fans turn with it about the pole), the vertical component the scene's. The state
        carries over. ValueError for a bad value or a scene without wind."""
        if not self.has_wind:
            raise ValueError("wind: this scene has no wind to change (air.model is 'none')")
        speed = self.wind_speed if speed is None else float(speed)
        direction = self.wind_direction if direction is None else float(direction)
        if not (math.isfinite(speed) and 0.0 <= speed <= MAX_WIND_SPEED):
            raise ValueError(f"wind speed should be in [0, {MAX_WIND_SPEED:g}] m/s, got {speed}")
        if not math.isfinite(direction):
            raise ValueError(f"wind direction should be finite (degrees), got {direction}")
        direction = (direction + 180.0) % 360.0 - 180.0
        if self.wind_set and (speed, direction) == (self.wind_speed, self.wind_direction):
            return
        self._change(wind_speed=speed, wind_direction=direction, wind_set=True)

    def set_flapping(self, mode):
        """Flapping mode, one of FLAPPING_MODES (docs/flapping.md). The state carries over."""
        if mode not in FLAPPING_MODES:
            raise ValueError(
                f"flapping mode should be one of {', '.join(FLAPPING_MODES)}, got {mode!r}"
            )
        if mode != self.flapping:
            self._change(flapping=mode)

    def set_integrator(self, method):
        """Integrator, 'implicit' or 'explicit'. The state carries over."""
        if method not in INTEGRATORS:
            raise ValueError(
                f"integrator should be one of {', '.join(INTEGRATORS)}, got {method!r}"
            )
        if method != self.integrator:
            self._change(integrator=method)

    def wind_up(self):
        self.set_wind(speed=min(self.wind_speed + WIND_SPEED_STEP, MAX_WIND_SPEED))

    def wind_down(self):
        self.set_wind(speed=max(self.wind_speed - WIND_SPEED_STEP, 0.0))

    def turn_wind_up(self):
        self.set_wind(direction=self.wind_direction + WIND_DIRECTION_STEP)

    def turn_wind_down(self):
        self.set_wind(direction=self.wind_direction - WIND_DIRECTION_STEP)

    def toggle_air(self):
        self.show_air = not self.show_air

    def press(self, key):
        """Do what the keyboard shortcut `key` (a name in KEYS) does."""
        actions = {k: action for k, _, action, _ in KEYS}
        if key not in actions:
            raise ValueError(f"key should be one of {', '.join(actions)}, got {key!r}")
        getattr(self, actions[key])()

    def next_flapping(self):
        i = FLAPPING_MODES.index(self.flapping)
        self.set_flapping(FLAPPING_MODES[(i + 1) % len(FLAPPING_MODES)])

    def other_integrator(self):
        self.set_integrator(INTEGRATORS[1 - INTEGRATORS.index(self.integrator)])

    def _change(self, **controls):
        """Set the controls and rebuild; if the changed scene is refused (a ValueError naming
        what), the controls and the simulation stay as they were."""
        before = {k: getattr(self, k) for k in controls}
        for k, v in controls.items():
            setattr(self, k, v)
        try:
            self._rebuild()
        except Exception:
            for k, v in before.items():
                setattr(self, k, v)
            raise

    def _rebuild(self):
        """A Simulation of the current controls that goes on from the current state."""
        old = self.sim
        start = self.time
        new = self._flagsim.Simulation(self.scene(start))
        for a, b in zip(flags_of(old), flags_of(new)):  # every flag's state
            b.positions = a.positions
            b.velocities = a.velocities
        if old.fluid is not None and new.fluid is not None:
            for c in ("u", "v", "w"):
                setattr(new.fluid, c, getattr(old.fluid, c))
        self._install(new, time_offset=start, carried=True)

    # --- the frame loop ------------------------------------------------------------------
    def advance(self, wall_seconds):
        """One frame of `wall_seconds` of wall time. While playing, take the steps that keep the
        simulated time on the wall clock, capped so that stepping takes at most FRAME_BUDGET of
        the frame; when capped, `behind` is set and the debt dropped (not carried into later
        frames). Returns the number of steps taken."""
        wall_seconds = max(0.0, float(wall_seconds))
        n = 0
        if self.playing:
            self._owed += wall_seconds
            dt = self.sim.scene.dt
            n, self.behind = steps_for_frame(self._owed, dt, self._seconds_per_step, wall_seconds)
            self._owed = 0.0 if self.behind else self._owed - n * dt
        self._step(n, wall_seconds)
        return n

    def step_frame(self, n, wall_seconds):
        """One frame of a fixed-rate run (the headless screenshot): `n` steps whatever the wall
        clock says, counted in the panel's figures with the frame's `wall_seconds`."""
        if n < 0:
            raise ValueError(f"n should be >= 0, got {n}")
        self._step(int(n), max(0.0, float(wall_seconds)))

    def _step(self, n, wall_seconds):
        spent = 0.0
        if n > 0:
            t0 = self.clock()
            self.sim.step(n)
            spent = self.clock() - t0
            self._carried = False
            per = spent / n
            old = self._seconds_per_step
            self._seconds_per_step = per if old is None else 0.8 * old + 0.2 * per
        frame = (wall_seconds, n * self.sim.scene.dt, spent, n, dict(self.sim.timings))
        self._window.append(frame)
        wall = sum(f[0] for f in self._window)
        while len(self._window) > 1 and wall - self._window[0][0] >= STATS_WINDOW:
            wall -= self._window[0][0]
            self._window_start = self._window.popleft()[4]

    def stats(self):
        """The panel's figures over the frames of the last STATS_WINDOW seconds."""
        wall = sum(f[0] for f in self._window)
        simulated = sum(f[1] for f in self._window)
        spent = sum(f[2] for f in self._window)
        steps = sum(f[3] for f in self._window)
        now = self._window[-1][4] if self._window else self._window_start
        delta = {k: v - self._window_start.get(k, 0.0) for k, v in now.items()}
        total = sum(delta.values())
        e = self.sim.energy()
        e["total"] = e["kinetic"] + e["gravity"] + e["spring"]
        return Stats(
            steps_per_second=steps / spent if spent > 0 else 0.0,
            realtime_ratio=simulated / wall if wall > 0 else 0.0,
            behind=self.behind,
            stage_split={k: v / total for k, v in delta.items()} if total > 0 else {},
            energy=e,
            time=self.time,
        )

    def mesh(self):
        """(positions, normals) to draw: the render geometry (flapping 'visual' displaces it),
        or, right after a rebuild and before the new Simulation's first step has computed its
        render geometry, the carried-over positions. A scene of several flags: every flag's,
        flag 0's vertices first, in the order of `topology()`."""
        if self._carried:
            parts = [(f.positions, f.normals) for f in flags_of(self.sim)]
        else:
            parts = [(f.render_positions, f.render_normals) for f in flags_of(self.sim)]
        if len(parts) == 1:
            return np.asarray(parts[0][0]), np.asarray(parts[0][1])
        return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))

    def topology(self):
        """(triangles, uv) of the drawn mesh: every flag's, as `mesh()` orders the vertices
        (each flag's uv in [0, 1])."""
        _, _, uv, triangles = mesh_arrays(self.sim)
        return np.asarray(triangles), np.asarray(uv)
