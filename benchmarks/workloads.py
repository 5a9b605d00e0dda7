"""Which workloads a benchmark run measures, and which it skips (and why).

Groups (``--only``): ``paper`` (the paper scene as built in, and the full pipeline: grid air,
self-collision, flapping), ``cloth`` (the flag alone in analytic wind at 8 x 11 .. 128 x 128 for
each integrator, with and without self-collision), ``air`` (flagsim.Fluid alone at 16^3 ..
128^3 for each advection scheme and pressure backend, the float grid, and the FFTW floor),
``solver`` (the pressure solvers at 16^3 .. 128^3: a tunnel with a solid plate for multigrid and
pcg, the periodic box for multigrid and fft; iterations, projection time and memory),
``multiflag`` (1, 4 and 16 paper flags in one 32^3 grid: the air once, the cloth per flag), and
with ``--peers`` the same cloth in PyBullet, MuJoCo and pyPBD and the numpy Stam FFT air
baseline and Taichi's Stable Fluids (CPU) where Taichi is installed. Every workload runs at each
requested thread count (1 and 2 by default) except the peers and baselines, which are
single-threaded.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

GROUPS = ("paper", "cloth", "air", "solver", "multiflag", "peers")
#: The multiflag group: paper flags in one 32^3 air grid (quick runs: 1 and 4; smoke: 1).
FLAG_COUNTS = (1, 4, 16)
CLOTH_SIZES = ((8, 11), (32, 32), (64, 64), (128, 128))
AIR_SIZES = (16, 32, 64, 128)
INTEGRATORS = ("implicit", "explicit")
ADVECTION = ("semi_lagrangian", "maccormack")
PRESSURE = ("fft", "pcg")
#: The solver group's workloads: (boundary with or without the solid plate, pressure backend).
SOLVERS = (
    ("tunnel+solid", "multigrid"),
    ("tunnel+solid", "pcg"),
    ("periodic", "multigrid"),
    ("periodic", "fft"),
)
THREADS = (1, 2)
#: Scene.large(): a 64 x 64 flag in a 64^3 air grid (the paper scene meshed finer).
LARGE_SIZE = "64x64+64^3"
SHORT = {"semi_lagrangian": "sl", "maccormack": "maccormack"}

#: Protocol per mode: seconds a run must last at least, runs measured, steps dropped first.
PROTOCOLS = {
    "full": {"min_time": 1.0, "repeats": 3, "warmup": 5},
    "quick": {"min_time": 0.1, "repeats": 3, "warmup": 3},
    "smoke": {"min_time": 0.01, "repeats": 2, "warmup": 2},
}


@dataclass
class Workload:
    group: str  # paper | cloth | air | solver | peers
    engine: str  # flagsim | numpy | fftw | pybullet | mujoco | pypbd
    variant: str  # e.g. implicit, implicit+self-collision, sl/fft, sl/fft/float, builtin, full,
    # tunnel+solid/multigrid
    size: str  # 8x11, 64^3
    n: int  # vertices or cells
    threads: int
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return f"{self.group}/{self.engine}/{self.variant}/{self.size}/t{self.threads}"

    def spec(self, protocol: dict[str, Any]) -> dict[str, Any]:
        return {
            "name": self.name,
            "threads": self.threads,
            "params": self.params,
            "protocol": protocol,
        }


@dataclass
class Selection:
    mode: str = "full"  # full | quick | smoke
    groups: tuple[str, ...] = ("paper", "cloth", "air", "solver", "multiflag")
    cloth_sizes: tuple[tuple[int, int], ...] | None = None  # None: the mode's default
    air_sizes: tuple[int, ...] | None = None
    threads: tuple[int, ...] | None = None
    integrators: tuple[str, ...] = INTEGRATORS
    advection: tuple[str, ...] = ADVECTION
    pressure: tuple[str, ...] = PRESSURE
    self_collision: tuple[bool, ...] = (False, True)
    float_grid: bool = True


def _defaults(sel: Selection):
    """(cloth sizes, air sizes, threads) of the mode where the selection leaves them open."""
    if sel.mode == "smoke":
        cloth, air, threads = ((8, 11),), (16,), (1,)
    elif sel.mode == "quick":
        cloth, air, threads = ((8, 11), (32, 32), (64, 64)), (16, 32, 64), THREADS
    else:
        cloth, air, threads = CLOTH_SIZES, AIR_SIZES, THREADS
    return (sel.cloth_sizes or cloth, sel.air_sizes or air, sel.threads or threads)


def _thread_counts(sel: Selection, threads, is_largest: bool, main_variant: bool):
    """Quick and smoke runs measure extra thread counts only at the largest size of the main
    variant (where they matter); full runs measure every thread count everywhere."""
    if sel.mode == "full" or sel.threads is not None:
        return threads
    if is_largest and main_variant:
        return threads
    return threads[:1]


def _pipeline_workloads(sel: Selection, threads) -> list[Workload]:
    """Issue 28: the air beside the cloth (air.pipeline, the default: "full", "large") against
    the serial order ("/serial": air.pipeline = false, every thread in each stage's loops) at
    each thread count above one, so the ratio comes from one run; the full paper scene two-way,
    lagged ("full/two_way_lagged", pipelined) and serial ("full/two_way"), at every thread count;
    and the large scene (Scene.large: 64 x 64 flag, 64^3 air, self-collision, eq. 5, dt = 0.01)
    at every thread count. Smoke runs take the paper scene's serial row alone."""
    multi = [t for t in threads if t > 1]
    serial = {"kind": "paper", "full": True, "pipeline": False}
    work = [
        Workload("paper", "flagsim", "full/serial", "8x11", 88, t, serial)
        for t in (multi if sel.mode != "smoke" else threads[:1])
    ]
    if sel.mode == "smoke":
        return work
    # two-way: the lagged scheme with its air beside the cloth at every thread count, and the
    # serial two-way scheme (its air takes this step's reaction, after the cloth) to compare with
    for coupling in ("two_way_lagged", "two_way"):
        params = {"kind": "paper", "full": True, "coupling": coupling}
        work += [
            Workload("paper", "flagsim", f"full/{coupling}", "8x11", 88, t, params) for t in threads
        ]
    # quick runs: the large scene at the largest thread count only (a step is ~10 ms)
    counts = threads if sel.mode == "full" or sel.threads is not None else threads[-1:]
    for variant, pipeline, ts in (("large", True, counts), ("large/serial", False, multi)):
        params = {"kind": "large", "pipeline": pipeline}
        work += [
            Workload("paper", "flagsim", variant, LARGE_SIZE, 64 * 64, t, params)
            for t in ts
            if t in counts
        ]
    return work


def catalogue(
    sel: Selection,
    features: dict[str, tuple[bool, str]],
    peer_status: dict[str, tuple[bool, str]] | None = None,
    baselines: dict[str, tuple[bool, str]] | None = None,
):
    """(workloads to run, [(what, why skipped)]) for a selection, given the features this build
    has (engines.features()), the peers installed and the baselines available."""
    cloth_sizes, air_sizes, threads = _defaults(sel)
    peer_status = peer_status or {}
    baselines = baselines or {}
    work: list[Workload] = []
    skipped: list[tuple[str, str]] = []

    if "paper" in sel.groups:
        for t in threads if sel.mode != "smoke" else threads[:1]:
            work.append(
                Workload(
                    "paper", "flagsim", "builtin", "8x11", 88, t, {"kind": "paper", "full": False}
                )
            )
        missing = [
            why
            for key, (ok, why) in features.items()
            if key in ("grid_air", "self_collision", "flapping") and not ok
        ]
        if missing:
            skipped.append(
                (
                    "paper scene, full pipeline (grid air + self-collision + flapping)",
                    "; ".join(missing),
                )
            )
        else:
            for t in threads if sel.mode != "smoke" else threads[:1]:
                work.append(
                    Workload(
                        "paper", "flagsim", "full", "8x11", 88, t, {"kind": "paper", "full": True}
                    )
                )
            work += _pipeline_workloads(sel, threads)

    want_cloth = "cloth" in sel.groups
    if want_cloth:
        collision_options = list(sel.self_collision)
        if sel.mode == "smoke":
            collision_options = collision_options[:1]
        if True in collision_options and not features.get("self_collision", (False, ""))[0]:
            skipped.append(
                (
                    "cloth with self-collision",
                    features.get("self_collision", (False, "self-collision is not built"))[1],
                )
            )
            collision_options = [c for c in collision_options if not c]
        largest = max(cloth_sizes, key=lambda rc: rc[0] * rc[1])
        for integrator in sel.integrators:
            for sc in collision_options:
                for rows, cols in cloth_sizes:
                    main = integrator == sel.integrators[0] and not sc
                    for t in _thread_counts(sel, threads, (rows, cols) == largest, main):
                        variant = integrator + ("+self-collision" if sc else "")
                        work.append(
                            Workload(
                                "cloth",
                                "flagsim",
                                variant,
                                f"{rows}x{cols}",
                                rows * cols,
                                t,
                                {
                                    "kind": "cloth",
                                    "rows": rows,
                                    "cols": cols,
                                    "integrator": integrator,
                                    "self_collision": sc,
                                },
                            )
                        )

    if "air" in sel.groups:
        if not features.get("fluid", (False, ""))[0]:
            skipped.append(
                ("air alone (flagsim.Fluid)", features.get("fluid", (False, "no Fluid"))[1])
            )
        else:
            largest = max(air_sizes)
            for adv in sel.advection:
                for pres in sel.pressure:
                    main = adv == sel.advection[0] and pres == sel.pressure[0]
                    sizes = (
                        air_sizes
                        if (main or sel.mode == "full" or sel.air_sizes)
                        else air_sizes[:2]
                    )
                    for n in sizes:
                        for t in _thread_counts(sel, threads, n == max(sizes), main):
                            work.append(
                                Workload(
                                    "air",
                                    "flagsim",
                                    f"{SHORT[adv]}/{pres}",
                                    f"{n}^3",
                                    n**3,
                                    t,
                                    {
                                        "kind": "fluid",
                                        "n": n,
                                        "advection": adv,
                                        "pressure": pres,
                                        "precision": "double",
                                    },
                                )
                            )
            if sel.float_grid and sel.mode != "smoke":
                adv, pres = sel.advection[0], sel.pressure[0]
                for n in air_sizes:
                    for t in _thread_counts(sel, threads, n == largest, True):
                        work.append(
                            Workload(
                                "air",
                                "flagsim",
                                f"{SHORT[adv]}/{pres}/float",
                                f"{n}^3",
                                n**3,
                                t,
                                {
                                    "kind": "fluid",
                                    "n": n,
                                    "advection": adv,
                                    "pressure": pres,
                                    "precision": "float",
                                },
                            )
                        )
        ok, why = baselines.get("fftw", (False, "not checked"))
        if ok:
            for n in air_sizes:
                work.append(
                    Workload(
                        "air",
                        "fftw",
                        "3r2c+3c2r",
                        f"{n}^3",
                        n**3,
                        1,
                        {"kind": "fftw_floor", "n": n},
                    )
                )
        else:
            skipped.append(("FFTW floor (3 r2c + 3 c2r)", why))

    if "multiflag" in sel.groups:
        if not features.get("grid_air", (False, ""))[0]:
            skipped.append(("several flags in one grid", features.get("grid_air", (False, ""))[1]))
        else:
            counts = {"smoke": FLAG_COUNTS[:1], "quick": FLAG_COUNTS[:2]}.get(sel.mode, FLAG_COUNTS)
            for count in counts:
                for t in threads[:1] if sel.mode != "full" else threads:
                    work.append(
                        Workload(
                            "multiflag",
                            "flagsim",
                            "paper-flags/32^3",
                            f"{count}x88",
                            88 * count,
                            t,
                            {"kind": "multiflag", "flags": count},
                        )
                    )

    if "solver" in sel.groups:
        if not features.get("fluid", (False, ""))[0]:
            skipped.append(("pressure solvers", features.get("fluid", (False, "no Fluid"))[1]))
        else:
            # Quick and smoke runs: the small sizes on one thread (the full run is the record).
            sizes = sel.air_sizes or (
                AIR_SIZES if sel.mode == "full" else (16, 32) if sel.mode == "quick" else (16,)
            )
            counts = sel.threads or (THREADS if sel.mode == "full" else (1,))
            for boundary, pressure in SOLVERS:
                if pressure == "fft" and not features.get("fft", (True, ""))[0]:
                    skipped.append((f"solver {boundary}/fft", features["fft"][1]))
                    continue
                if sel.mode == "smoke" and pressure == "pcg":
                    continue
                for n in sizes:
                    for t in counts:
                        work.append(
                            Workload(
                                "solver",
                                "flagsim",
                                f"{boundary}/{pressure}",
                                f"{n}^3",
                                n**3,
                                t,
                                {
                                    "kind": "solver",
                                    "n": n,
                                    "boundary": boundary,
                                    "pressure": pressure,
                                },
                            )
                        )

    if "peers" in sel.groups:
        peer_sizes = cloth_sizes if sel.mode != "quick" or sel.cloth_sizes else cloth_sizes[:2]
        for peer, (ok, why) in peer_status.items():
            if not ok:
                skipped.append((f"peer {peer}", why))
                continue
            for rows, cols in peer_sizes:
                work.append(
                    Workload(
                        "peers",
                        peer,
                        "cloth",
                        f"{rows}x{cols}",
                        rows * cols,
                        1,
                        {"kind": "peer", "peer": peer, "rows": rows, "cols": cols},
                    )
                )
        # flagsim's side of the comparison, at one thread, if the cloth group did not measure it
        have = {w.name for w in work}
        for integrator in INTEGRATORS:
            for rows, cols in peer_sizes:
                w = Workload(
                    "cloth",
                    "flagsim",
                    integrator,
                    f"{rows}x{cols}",
                    rows * cols,
                    1,
                    {
                        "kind": "cloth",
                        "rows": rows,
                        "cols": cols,
                        "integrator": integrator,
                        "self_collision": False,
                    },
                )
                if w.name not in have:
                    work.append(w)
        ok, why = baselines.get("numpy", (False, "not checked"))
        if not ok:
            skipped.append(("numpy Stam FFT baseline", why))
        elif not features.get("fluid", (False, ""))[0]:
            skipped.append(
                (
                    "numpy Stam FFT baseline",
                    "nothing to compare it with: " + features.get("fluid", (False, ""))[1],
                )
            )
        else:
            numpy_sizes = air_sizes if sel.mode != "quick" or sel.air_sizes else air_sizes[:2]
            for n in numpy_sizes:
                work.append(
                    Workload(
                        "peers",
                        "numpy",
                        "stam fft",
                        f"{n}^3",
                        n**3,
                        1,
                        {"kind": "numpy_fluid", "n": n},
                    )
                )
            ok, why = baselines.get("taichi", (False, "not checked"))
            if not ok:
                skipped.append(("air peer taichi", why))
            else:
                for n in numpy_sizes:
                    work.append(
                        Workload(
                            "peers",
                            "taichi",
                            "stable fluids",
                            f"{n}^3",
                            n**3,
                            1,
                            {"kind": "taichi_fluid", "n": n},
                        )
                    )
    return work, skipped
