"""What a benchmark steps: flagsim's Simulation and Fluid, the numpy Stam FFT baseline, and
the FFTW floor of an FFT projection. Peers (PyBullet, MuJoCo, pyPBD) are in peers.py.

A stepper is built outside the timing and offers ``step(n)``; optionally ``timings()`` (seconds
per stage, cumulative), ``info()`` (a small dict for the report) and ``ok()`` (state finite).
Features that other issues add are detected, never assumed: ``features()`` says which exist.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import warnings
from typing import Any

import numpy as np

#: Air grids are a 2 m periodic box (the paper's 16^3 at 12.5 cm), whatever the resolution.
AIR_BOX = 2.0
#: Air and cloth step, s (the paper's).
DT = 0.01
AIR_VISCOSITY = 1.5e-5  # m^2/s, air


# ---- feature detection ------------------------------------------------------------------------


def plain_paper_scene():
    """Scene.paper() with only what the foundation has: analytic (uniform) wind, and
    self-collision and flapping off where the scene has them. Features are detected against it,
    and the cloth workloads start from it."""
    import flagsim

    s = flagsim.Scene.paper()
    s.air.model = "uniform"
    if hasattr(s, "self_collision"):
        s.self_collision.enabled = False
    if hasattr(s, "flapping"):
        s.flapping.mode = "off"
    return s


def _added_stages(section: str, configure) -> tuple[bool, str]:
    """(True, "") when configure(scene) on the plain paper scene builds a stage it lacks."""
    import flagsim

    if not hasattr(flagsim.Scene.paper(), section):
        return False, f"Scene has no '{section}' section in this build"
    try:
        base = set(flagsim.Simulation(plain_paper_scene()).stages)
        scene = plain_paper_scene()
        configure(scene)
        added = set(flagsim.Simulation(scene).stages) - base
    except (AttributeError, TypeError, ValueError) as e:
        return False, f"rejected by this build ({e})"
    if not added:
        return False, "accepted by the scene but no stage is built for it yet"
    return True, ""


def features() -> dict[str, tuple[bool, str]]:
    """{feature: (available, why not)} for the parts other issues add."""
    import flagsim

    out: dict[str, tuple[bool, str]] = {}
    out["fluid"] = (
        (True, "")
        if hasattr(flagsim, "Fluid")
        else (False, "flagsim.Fluid does not exist yet (the air solver, issue 4)")
    )

    def self_collision(s):
        s.self_collision.enabled = True

    def flapping(s):
        s.flapping.mode = "displace"

    def grid_air(s):
        s.air.model = "grid"

    ok, why = _added_stages("self_collision", self_collision)
    out["self_collision"] = (ok, "" if ok else f"self-collision (issue 5): {why}")
    ok, why = _added_stages("flapping", flapping)
    out["flapping"] = (ok, "" if ok else f"flapping (issue 5): {why}")
    out["fft"] = (
        (True, "")
        if out["fluid"][0] and flagsim.has_fftw()
        else (False, "this flagsim was built without FFTW")
    )
    if out["fluid"][0]:
        ok, why = _added_stages("air", grid_air)
        out["grid_air"] = (ok, "" if ok else f"grid air in the Simulation (issue 4): {why}")
    else:
        out["grid_air"] = (False, "grid air in the Simulation needs flagsim.Fluid (issue 4)")
    return out


# ---- flagsim -----------------------------------------------------------------------------------


def cloth_scene(rows: int, cols: int, integrator: str = "implicit", self_collision: bool = False):
    """The paper scene's flag (same size, mass, pins, dt) meshed with rows x cols masses, alone:
    in the analytic wind (no grid), no flapping."""
    s = plain_paper_scene()
    paper_spacing = _spacing(s.flag)
    s.name = f"cloth {rows}x{cols}"
    s.flag.rows = rows
    s.flag.cols = cols
    s.integrator.method = integrator
    if self_collision:
        s.self_collision.enabled = True
        # The contact thickness scales with the spacing, at the paper's ratio (0.005 m on 77 mm),
        # so every size is the same problem, meshed finer: a fixed thickness would exceed the rest
        # gap between a vertex and the triangles around it on fine meshes, and a mixed rule
        # (the paper's value, capped at 0.4 x spacing) gave 13 candidate pairs per vertex at
        # 32 x 32 but 36 at 64 x 64, which the per-vertex cost slope then measured instead of
        # the algorithm (docs/design.md, "Benchmark workloads").
        s.self_collision.thickness *= _spacing(s.flag) / paper_spacing
    return s


def _spacing(flag) -> float:
    """The smaller distance between neighbouring masses at rest, m."""
    return min(flag.width / (flag.cols - 1), flag.height / (flag.rows - 1))


def paper_scene(full: bool, pipeline: bool = True, coupling: str = "one_way"):
    """Scene.paper() as built in (whatever it switches on); full: with grid air, self-collision
    and flapping switched on. pipeline: air.pipeline (the air beside the cloth on two threads);
    coupling: air.coupling."""
    import flagsim

    s = flagsim.Scene.paper()
    if full:
        s.air.model = "grid"
        s.self_collision.enabled = True
        s.flapping.mode = "displace"
    s.air.pipeline = pipeline
    s.air.coupling = coupling
    return s


def large_scene(pipeline: bool = True):
    """Scene.large(): the paper scene meshed finer (64 x 64 flag, 64^3 air, self-collision,
    eq. 5, dt = 0.01 s), with air.pipeline as given."""
    import flagsim

    s = flagsim.Scene.large()
    s.air.pipeline = pipeline
    return s


def multiflag_scene(count: int):
    """`count` (<= 16) paper flags on their poles, 2 m apart on a 4 x 4 plan, in one periodic
    32^3 grid of 0.25 m cells with a 2 m/s mean flow (the paper's fan left out): the air is the
    same for every count, so the cloth's share shows how the cost grows with the flags."""
    import copy

    import flagsim

    s = flagsim.Scene.paper()
    s.air.fans = []
    s.air.resolution = (32, 32, 32)
    s.air.cell_size = 0.25
    s.air.origin = (-1.0, -4.0, -4.0)
    s.air.wind = (2.0, 0.0, 0.0)
    flags = []
    for k in range(count):
        f = copy.copy(s.flags[0])
        x, z = 2.0 * (k % 4), -3.0 + 2.0 * (k // 4)
        f.origin = (x + 0.055, 0.0, z)
        f.pole.base = (x, -2.5, z)
        flags.append(f)
    s.flags = flags
    return s


class SimulationStepper:
    def __init__(self, scene):
        import flagsim

        self.sim = flagsim.Simulation(scene)

    def step(self, n: int) -> None:
        self.sim.step(n)

    def timings(self) -> dict[str, float]:
        return dict(self.sim.timings)

    def info(self) -> dict[str, Any]:
        import flagsim

        pipelined = self.sim.pipelined and flagsim.num_threads() > 1
        return {
            "notes": "air beside the cloth (air.pipeline)" if pipelined else "",
            "vertices": int(self.sim.positions.shape[0]),
            "stages": list(self.sim.stages),
            "last_step": dict(self.sim.last_step_stats),
            "max_strain": float(self.sim.max_strain()),
        }

    def ok(self) -> bool:
        return bool(np.isfinite(self.sim.positions).all())


def smooth_periodic_field(points: np.ndarray, box: float = AIR_BOX, seed: int = 0) -> np.ndarray:
    """A seeded smooth periodic velocity field (M, 3) m/s: 2 m/s along +x plus 6 random modes.

    Benchmarks start from it rather than from uniform wind, where an iterative pressure solve
    would have nothing to do.
    """
    rng = np.random.default_rng(seed)
    u = np.zeros_like(points, dtype=float)
    u[:, 0] = 2.0
    for _ in range(6):
        k = rng.integers(-3, 4, size=3)
        if not k.any():
            k[0] = 1
        amp = rng.normal(size=3)
        phase = rng.uniform(0, 2 * np.pi)
        u += np.outer(np.sin(2 * np.pi / box * points @ k + phase), amp)
    return u


def set_velocity_by_planes(fluid, fn) -> None:
    """fluid.set_velocity(fn) for a pointwise fn, one x-plane of faces at a time through the
    component views: set_velocity evaluates fn on every face of a component at once (2M points at
    128^3, +231 MiB at the peak), which the +MiB column would count as the air's own memory."""
    h, origin = fluid.cell_size, np.asarray(fluid.origin, dtype=float)
    for c, name in enumerate("uvw"):
        view = getattr(fluid, name)
        shift = np.full(3, 0.5)
        shift[c] = 0.0  # a c-face sits on the cell boundary along axis c
        j, k = np.meshgrid(np.arange(view.shape[1]), np.arange(view.shape[2]), indexing="ij")
        for i in range(view.shape[0]):
            idx = np.stack([np.full(j.size, i), j.ravel(), k.ravel()], axis=1)
            points = origin + h * (idx + shift)
            view[i] = np.asarray(fn(points))[:, c].reshape(view.shape[1:])


class FluidStepper:
    """flagsim.Fluid alone on the periodic benchmark box."""

    def __init__(self, n: int, advection: str, pressure: str, precision: str = "double"):
        import flagsim

        self.fluid = flagsim.Fluid(
            resolution=(n, n, n),
            cell_size=AIR_BOX / n,
            origin=(0.0, 0.0, 0.0),
            boundary="periodic",
            advection=advection,
            pressure=pressure,
            precision=precision,
            viscosity=AIR_VISCOSITY,
        )
        set_velocity_by_planes(self.fluid, smooth_periodic_field)

    def step(self, n: int) -> None:
        self.fluid.step(DT, n)

    def timings(self) -> dict[str, float]:
        """Stage seconds when the Fluid reports them (stats['seconds_<stage>'], cumulative)."""
        stats = getattr(self.fluid, "stats", None)
        if not isinstance(stats, dict):
            return {}
        return {
            k[len("seconds_") :]: float(v) for k, v in stats.items() if k.startswith("seconds_")
        }

    def info(self) -> dict[str, Any]:
        stats = getattr(self.fluid, "stats", None)
        stats = dict(stats) if isinstance(stats, dict) else {}
        out: dict[str, Any] = {}
        if stats.get("pressure_iterations"):
            out["notes"] = f"{stats['pressure_iterations']} PCG iterations in the last projection"
        return out

    def ok(self) -> bool:
        return all(bool(np.isfinite(np.asarray(getattr(self.fluid, c))).all()) for c in "uvw")


def solid_plate(n: int) -> np.ndarray:
    """The solver workloads' solid: a plate of cells across the middle half of the tunnel's
    cross-section, n/8 cells thick (at least one), a quarter of the way downstream."""
    m = np.zeros((n, n, n), bool)
    m[n // 4 : n // 4 + max(1, n // 8), n // 4 : 3 * n // 4, n // 4 : 3 * n // 4] = True
    return m


#: SolverStepper.info's steps (Python slice of the steps run: the 3rd to the 12th).
ITERATION_WINDOW = (2, 12)


class SolverStepper:
    """flagsim.Fluid alone, to time its pressure solve: the 2 m box at n^3, no viscosity (so the
    'project' stage is the projection alone), from the seeded smooth field. 'tunnel+solid': inflow
    2 m/s through x-min and the solid plate (solid_plate) as a free-slip box obstacle, so the
    plate's faces are held (no flux) at every step; where the obstacles do not exist, as the
    pressure solve's solid cells alone (Fluid.set_solid_cells, faces zeroed at the start only)."""

    def __init__(self, n: int, boundary: str, pressure: str, precision: str = "double"):
        import flagsim

        tunnel = boundary.startswith("tunnel")
        solid = boundary.endswith("+solid")
        h = AIR_BOX / n
        kw: dict[str, Any] = {}
        obstacles = solid and hasattr(flagsim, "ObstacleParams")
        if obstacles:  # the cells of solid_plate(n): centres inside the box
            lo = np.array([n // 4, n // 4, n // 4]) * h
            hi = np.array([n // 4 + max(1, n // 8), 3 * n // 4, 3 * n // 4]) * h
            kw["obstacles"] = [
                flagsim.ObstacleParams(
                    shape="box",
                    center=tuple((lo + hi) / 2),
                    half_size=tuple((hi - lo) / 2),
                    slip="free_slip",
                )
            ]
        with warnings.catch_warnings():  # a plate n/8 cells thick: its wake is not the point
            warnings.filterwarnings("ignore", message="air.obstacles.*cells across")
            self.fluid = flagsim.Fluid(
                resolution=(n, n, n),
                cell_size=h,
                origin=(0.0, 0.0, 0.0),
                boundary="tunnel" if tunnel else "periodic",
                pressure=pressure,
                precision=precision,
                viscosity=0.0,
                wind=(2.0, 0.0, 0.0) if tunnel else None,
                **kw,
            )
        self.fluid.set_velocity(smooth_periodic_field)
        if solid and not obstacles:
            mask = solid_plate(n)
            self.fluid.set_solid_cells(mask)
            for axis, name in enumerate("uvw"):
                a = getattr(self.fluid, name)
                pad = np.zeros_like(mask.take([0], axis=axis))
                a[
                    np.concatenate([pad, mask], axis=axis) | np.concatenate([mask, pad], axis=axis)
                ] = 0
        self.iterations: list[int] = []

    def step(self, n: int) -> None:
        for _ in range(n):  # one at a time: each projection's iteration count
            self.fluid.step(DT)
            self.iterations.append(int(self.fluid.stats["pressure_iterations"]))

    def timings(self) -> dict[str, float]:
        return {
            k[len("seconds_") :]: float(v)
            for k, v in self.fluid.stats.items()
            if k.startswith("seconds_")
        }

    def info(self) -> dict[str, Any]:
        """The iterations of steps ITERATION_WINDOW (1-based: 3 to 12), the same steps of the same
        flow at every size: the timed runs' step counts follow each machine's speed, and the
        flow settles as it goes (the tunnel's first steps take 7 iterations, 6 after, and a
        32^3 run timed to 200 steps reached 4), so "the last steps run" compared the sizes at
        different times. Steps the timing did not run are run here, untimed."""
        start, end = ITERATION_WINDOW
        if len(self.iterations) < end:
            self.step(end - len(self.iterations))
        its = self.iterations[start:end]
        if not its or max(its) == 0:
            return {}
        return {
            "iterations": float(np.mean(its)),
            "notes": f"CG iterations per projection: mean {np.mean(its):.1f}, max {max(its)} "
            f"(steps {start + 1}-{end})",
        }

    def ok(self) -> bool:
        return all(bool(np.isfinite(np.asarray(getattr(self.fluid, c))).all()) for c in "uvw")


class NumpyFluidStepper:
    """The numpy air baseline (benchmarks/stam_numpy.py: textbook Stam FFT Stable Fluids,
    collocated, chunked gather), same box, field, dt and viscosity as FluidStepper."""

    def __init__(self, n: int):
        from .stam_numpy import StamFftNumpy

        self.fluid = StamFftNumpy(n, AIR_BOX, viscosity=AIR_VISCOSITY)
        self.fluid.set_velocity(smooth_periodic_field)

    def step(self, n: int) -> None:
        for _ in range(n):
            self.fluid.step(DT)

    def info(self) -> dict[str, Any]:
        return {"notes": f"textbook Stam FFT solver, collocated grid, {self.fluid.fft}"}

    def ok(self) -> bool:
        return bool(np.isfinite(self.fluid.vel).all())


def numpy_baseline_available() -> tuple[bool, str]:
    """The baseline needs numpy only (scipy.fft, when installed, is faster: the bench extra)."""
    return True, ""


# ---- FFTW floor --------------------------------------------------------------------------------

_FFTW_ESTIMATE = 1 << 6


def _load_fftw():
    for name in (ctypes.util.find_library("fftw3"), "libfftw3.so.3", "libfftw3.dylib"):
        if not name:
            continue
        try:
            return ctypes.CDLL(name)
        except OSError:
            continue
    return None


def fftw_available() -> tuple[bool, str]:
    if _load_fftw() is None:
        return False, "the FFTW 3 shared library (libfftw3) was not found"
    return True, ""


class FftwFloorStepper:
    """One 'step' = 3 forward r2c + 3 inverse c2r double transforms of an n^3 grid, one thread,
    FFTW_ESTIMATE plans (as flagsim's fft projection plans them): the floor of a spectral diffusion
    and projection (flagsim's explicit viscosity needs 1 r2c + 1 c2r of them, docs/design.md)."""

    def __init__(self, n: int):
        lib = _load_fftw()
        if lib is None:
            raise RuntimeError("libfftw3 not found")
        self.lib = lib
        lib.fftw_plan_dft_r2c_3d.restype = ctypes.c_void_p
        lib.fftw_plan_dft_r2c_3d.argtypes = [ctypes.c_int] * 3 + [
            ctypes.c_void_p,
            ctypes.c_void_p,
            ctypes.c_uint,
        ]
        lib.fftw_plan_dft_c2r_3d.restype = ctypes.c_void_p
        lib.fftw_plan_dft_c2r_3d.argtypes = lib.fftw_plan_dft_r2c_3d.argtypes
        lib.fftw_execute.argtypes = [ctypes.c_void_p]
        lib.fftw_destroy_plan.argtypes = [ctypes.c_void_p]
        self.real = [np.random.default_rng(c).standard_normal((n, n, n)) for c in range(3)]
        self.spec = [np.zeros((n, n, n // 2 + 1), dtype=np.complex128) for _ in range(3)]
        self.plans = []
        for r, c in zip(self.real, self.spec):
            keep = r.copy()  # planning may overwrite (not with ESTIMATE, but be safe)
            self.plans.append(
                lib.fftw_plan_dft_r2c_3d(n, n, n, r.ctypes.data, c.ctypes.data, _FFTW_ESTIMATE)
            )
            self.plans.append(
                lib.fftw_plan_dft_c2r_3d(n, n, n, c.ctypes.data, r.ctypes.data, _FFTW_ESTIMATE)
            )
            r[...] = keep
        if not all(self.plans):
            raise RuntimeError("FFTW planning failed")
        self.scale = 1.0 / n**3

    def step(self, n: int) -> None:
        execute = self.lib.fftw_execute
        for _ in range(n):
            for p in self.plans:
                execute(p)
            # keep the data bounded: c2r leaves n^3 x the input
            for r in self.real:
                r *= self.scale

    def ok(self) -> bool:
        return all(bool(np.isfinite(r).all()) for r in self.real)

    def __del__(self):
        for p in getattr(self, "plans", []):
            if p:
                self.lib.fftw_destroy_plan(p)


# ---- Taylor-Green: float32 grid accuracy against double -----------------------------------------


def taylor_green_errors(n: int = 32, steps: int = 50, viscosity: float = 0.05) -> dict[str, float]:
    """Relative max error of a decaying Taylor-Green vortex after `steps` steps of DT, for the
    double and the float grid, and their difference relative to the double result.

    u = U sin(kx) cos(ky), v = -U cos(kx) sin(ky), w = 0 decays as exp(-2 nu k^2 t) (exact for
    Navier-Stokes); k = 2 pi / box.
    """
    import flagsim

    k = 2 * np.pi / AIR_BOX

    def tg(points):
        x, y = points[:, 0], points[:, 1]
        u = np.zeros_like(points)
        u[:, 0] = np.sin(k * x) * np.cos(k * y)
        u[:, 1] = -np.cos(k * x) * np.sin(k * y)
        return u

    out: dict[str, float] = {}
    fields = {}
    for precision in ("double", "float"):
        f = flagsim.Fluid(
            resolution=(n, n, n),
            cell_size=AIR_BOX / n,
            origin=(0.0, 0.0, 0.0),
            boundary="periodic",
            advection="semi_lagrangian",
            pressure="fft",
            precision=precision,
            viscosity=viscosity,
        )
        f.set_velocity(tg)
        f.step(DT, steps)
        decay = math.exp(-2 * viscosity * k * k * DT * steps)
        exact = tg(f.face_positions(0))[:, 0] * decay
        u = np.asarray(f.u, dtype=float).reshape(-1)
        fields[precision] = u
        out[f"error_{precision}"] = float(np.abs(u - exact).max() / decay)
    out["float_vs_double"] = float(
        np.abs(fields["float"] - fields["double"]).max() / np.abs(fields["double"]).max()
    )
    out["n"] = n
    out["steps"] = steps
    return out
