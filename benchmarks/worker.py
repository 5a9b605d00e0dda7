"""One workload, measured in its own process: ``python -m benchmarks.worker SPEC RESULT``.

SPEC is the workload as JSON; RESULT is the path the measurement is written to as JSON (stdout
is left to the engines, some of which print banners). A process per workload makes the peak
memory (ru_maxrss) the workload's own and keeps one engine's state from leaking into the next.

Protocol (``measure``): build (timed apart) -> ``warmup`` steps dropped (fewer when they take
longer than ``min_time``) -> the steps per run
doubled/extrapolated until one run lasts at least ``min_time`` -> ``repeats`` runs of that many
steps, each giving wall and CPU seconds per step; the stage split is the difference of the
engine's cumulative stage timers over those runs.
"""

from __future__ import annotations

import json
import math
import resource
import sys
import time
import traceback
from typing import Any


def rss_mb() -> float:
    """Peak resident set size of this process so far, MiB (Linux reports ru_maxrss in KiB)."""
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / (2**20 if sys.platform == "darwin" else 2**10)


def measure(stepper, *, min_time: float, repeats: int, warmup: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    for _ in range(warmup):  # one at a time: a slow workload drops fewer steps than asked
        stepper.step(1)
        if time.perf_counter() - t0 > min_time:
            break
    n = 1
    while True:
        t0 = time.perf_counter()
        stepper.step(n)
        elapsed = time.perf_counter() - t0
        if elapsed >= min_time:
            break
        grow = 1.25 * min_time / max(elapsed, 1e-9)
        n = int(min(100 * n, max(2 * n, math.ceil(n * grow))))
    timings = getattr(stepper, "timings", None)
    before = timings() if timings else {}
    wall, cpu = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        stepper.step(n)
        t1, c1 = time.perf_counter(), time.process_time()
        wall.append((t1 - t0) / n)
        cpu.append((c1 - c0) / n)
    after = timings() if timings else {}
    steps = n * repeats
    stages = {k: (after[k] - before.get(k, 0.0)) / steps for k in after}
    return {"steps_per_run": n, "runs": repeats, "wall_s": wall, "cpu_s": cpu, "stages_s": stages}


def build(spec: dict[str, Any]):
    """The stepper a workload spec describes (see workloads.Workload.params)."""
    from . import engines, peers

    p = spec["params"]
    kind = p["kind"]
    if kind == "cloth":
        return engines.SimulationStepper(
            engines.cloth_scene(p["rows"], p["cols"], p["integrator"], p["self_collision"])
        )
    if kind == "paper":
        return engines.SimulationStepper(
            engines.paper_scene(p["full"], p.get("pipeline", True), p.get("coupling", "one_way"))
        )
    if kind == "large":
        return engines.SimulationStepper(engines.large_scene(p["pipeline"]))
    if kind == "multiflag":
        return engines.SimulationStepper(engines.multiflag_scene(p["flags"]))
    if kind == "fluid":
        return engines.FluidStepper(p["n"], p["advection"], p["pressure"], p["precision"])
    if kind == "solver":
        return engines.SolverStepper(p["n"], p["boundary"], p["pressure"])
    if kind == "numpy_fluid":
        return engines.NumpyFluidStepper(p["n"])
    if kind == "taichi_fluid":
        from .taichi_air import TaichiFluid

        return TaichiFluid(p["n"], engines.AIR_BOX, engines.smooth_periodic_field, engines.DT)
    if kind == "fftw_floor":
        return engines.FftwFloorStepper(p["n"])
    if kind == "peer":
        return peers.make(p["peer"], p["rows"], p["cols"])
    raise ValueError(f"unknown workload kind {kind!r}")


def run(spec: dict[str, Any]) -> dict[str, Any]:
    import flagsim

    from .machine import speed_probe

    proto = spec["protocol"]
    out: dict[str, Any] = {"name": spec["name"], "ok": False, "error": ""}
    probe_before = speed_probe()  # the machine's speed just before the workload (one thread)
    flagsim.set_num_threads(int(spec["threads"]))
    rss0 = rss_mb()
    t0 = time.perf_counter()
    stepper = build(spec)
    out["build_s"] = time.perf_counter() - t0
    try:
        out.update(
            measure(
                stepper,
                min_time=float(proto["min_time"]),
                repeats=int(proto["repeats"]),
                warmup=int(proto["warmup"]),
            )
        )
    except flagsim.DivergenceError as e:
        out["error"] = f"diverged: {e}"
        return out
    out["rss_start_mb"] = rss0
    out["rss_peak_mb"] = rss_mb()
    info = getattr(stepper, "info", None)
    out["info"] = info() if info else {}
    check = getattr(stepper, "ok", None)
    out["ok"] = bool(check()) if check else True
    if not out["ok"]:  # the strain itself is in out["info"], and so in the row's note
        out["error"] = "state not finite or torn apart after the runs"
    out["probe_ms"] = [probe_before, speed_probe()]  # and just after
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    spec = json.loads(argv[0])
    try:
        result = run(spec)
    except Exception as e:  # reported in the table, never fatal to the benchmark
        result = {
            "name": spec.get("name", "?"),
            "ok": False,
            "error": f"{type(e).__name__}: {e}".strip(),
            "traceback": traceback.format_exc(limit=6),
        }
    with open(argv[1], "w", encoding="utf-8") as f:
        json.dump(result, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
