"""`flagsim study stability`: does every integrator survive stiff and extreme cases?

A matrix over spring stiffness, wind speed, time step, areal density and integrator, plus
pathological cases. Each case ends in exactly one outcome:
  stable            ran to the end; max strain and energy range are reported
  diverged          DivergenceError raised (state restored) with its cause
  silent_nonfinite  no error, yet some output is not finite: must never happen
"""
from __future__ import annotations

import itertools
import math
import time
from typing import Any

import numpy as np

import flagsim

INTEGRATORS = ("explicit", "explicit_adaptive", "implicit")
FULL = dict(k_s=(1e1, 1e3, 1e5, 1e7), wind=(0.0, 2.0, 10.0, 30.0, 60.0, 100.0),
            dt=(1e-4, 1e-3, 1e-2, 5e-2), density=(1e-3, 1e-1, 10.0))
REDUCED = dict(k_s=(1e1, 1e7), wind=(0.0, 100.0), dt=(1e-3, 5e-2), density=(1e-3, 10.0))
PATHOLOGICAL = ("coincident_masses", "strip_2xN", "fine_128x192", "wind_reversal_at_pole",
                "gust_30ms", "long_run_1000s")

COLUMNS = ["id", "kind", "integrator", "k_s", "wind", "dt", "density", "duration",
           "outcome", "cause", "steps", "max_strain", "energy_min", "energy_max",
           "max_substeps", "max_cg_iterations", "wall_s"]


def matrix_cases(axes: dict[str, tuple], duration: float) -> list[dict[str, Any]]:
    cases = []
    for k, w, dt, rho, integ in itertools.product(axes["k_s"], axes["wind"], axes["dt"],
                                                  axes["density"], INTEGRATORS):
        cases.append(dict(id=f"m-{integ}-k{k:g}-w{w:g}-dt{dt:g}-rho{rho:g}", kind="matrix",
                          integrator=integ, k_s=k, wind=w, dt=dt, density=rho,
                          duration=duration))
    return cases


def pathological_cases(reduced: bool) -> list[dict[str, Any]]:
    """All pathological cases; the reduced (CI) set leaves out the 128 x 192 flag, whose explicit
    run alone takes minutes on 2 cores (the full study and docs/stability.md include it)."""
    cases = []
    for name in PATHOLOGICAL:
        if reduced and name == "fine_128x192":
            continue
        for integ in INTEGRATORS:
            duration = {"long_run_1000s": 20.0 if reduced else 1000.0,
                        "fine_128x192": 0.1}.get(name, 0.5 if reduced else 2.0)
            cases.append(dict(id=f"p-{name}-{integ}", kind=name, integrator=integ, k_s=100.0,
                              wind=2.0, dt=0.01, density=0.15, duration=duration))
    return cases


def _integrator(scene: flagsim.Scene, name: str) -> None:
    scene.integrator.method = "implicit" if name == "implicit" else "explicit"
    scene.integrator.adaptive = name == "explicit_adaptive"


def build_scene(case: dict[str, Any]) -> tuple[flagsim.Scene, Any]:
    """Scene for a case, and an optional function preparing the simulation's initial state."""
    s = flagsim.Scene.paper()
    kind = case["kind"]
    k = float(case["k_s"])
    s.flag.stretch_stiffness, s.flag.shear_stiffness, s.flag.bend_stiffness = k, k / 5, k / 20
    s.flag.areal_density = float(case["density"])
    s.dt = float(case["dt"])
    s.air.model = "uniform"  # the matrix varies the wind itself; the grid is not under test here
    s.flapping.mode = "off"  # eq. 5's amplitude grows with wind speed: 3 m at 100 m/s
    w = float(case["wind"])
    direction = np.array([1.0, 0.0, 0.3]) / math.hypot(1.0, 0.3)
    s.air.wind = tuple(w * direction)
    _integrator(s, case["integrator"])
    prepare = None
    if kind == "coincident_masses":
        def prepare(sim):  # two neighbouring masses at one point: a spring of zero length
            x = sim.positions.copy()
            x[2] = x[1]
            sim.positions = x
    elif kind == "strip_2xN":
        s.flag.rows, s.flag.cols = 2, 40
        s.flag.height, s.flag.width = 0.05, 1.0
    elif kind == "fine_128x192":
        s.flag.rows, s.flag.cols = 128, 192
    elif kind == "wind_reversal_at_pole":
        s.air.wind = [(0.0, (8.0, 0.0, 1.0)), (0.3, (8.0, 0.0, 1.0)), (0.35, (-8.0, 0.0, -1.0))]
    elif kind == "gust_30ms":
        s.air.wind = [(0.0, (0.0, 0.0, 0.0)), (0.1, (0.0, 0.0, 0.0)), (0.12, (30.0, 0.0, 5.0))]
    elif kind == "long_run_1000s":  # conservative: no air, no damping; energy drift is the test
        s.air.model = "none"
        s.flag.damping = 0.0
    return s, prepare


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    """Pure function of the case: same settings, same result (apart from wall_s)."""
    scene, prepare = build_scene(case)
    sim = flagsim.Simulation(scene)
    if prepare:
        prepare(sim)
    steps = max(1, round(float(case["duration"]) / scene.dt))
    chunk = max(1, steps // 200)  # energy and strain sampled ~200 times
    e0 = sum(sim.energy().values())  # the range includes the start: dissipation shows
    e_min, e_max, strain, subs, cgs = e0, e0, 0.0, 0, 0  # strain: of the steps, not the set-up
    outcome, cause = "stable", ""
    t0 = time.perf_counter()
    done = 0
    try:
        while done < steps:
            n = min(chunk, steps - done)
            for _ in range(n):
                sim.step()
                st = sim.last_step_stats
                subs = max(subs, st["substeps"])
                cgs = max(cgs, st["cg_iterations"])
            done += n
            e = sum(sim.energy().values())
            e_min, e_max = min(e_min, e), max(e_max, e)
            strain = max(strain, sim.max_strain())
            if not _all_finite(sim, e):
                outcome, cause = "silent_nonfinite", "non-finite output without DivergenceError"
                break
    except flagsim.DivergenceError as err:
        outcome, cause = "diverged", err.cause
        if not _all_finite(sim, sum(sim.energy().values())):
            outcome, cause = "silent_nonfinite", "state not restored after DivergenceError"
    return dict(outcome=outcome, cause=cause, steps=sim.step_count, max_strain=f"{strain:.6g}",
                energy_min=f"{e_min:.6g}", energy_max=f"{e_max:.6g}", max_substeps=subs,
                max_cg_iterations=cgs, wall_s=f"{time.perf_counter() - t0:.4g}")


def _all_finite(sim: flagsim.Simulation, energy: float) -> bool:
    return bool(np.isfinite(sim.positions).all() and np.isfinite(sim.velocities).all()
                and np.isfinite(sim.normals).all() and math.isfinite(energy))


def cases(reduced: bool) -> list[dict[str, Any]]:
    axes = REDUCED if reduced else FULL
    # 0.2 s of simulated time per matrix case: 20 steps at the largest dt, 2,000 at the smallest;
    # an explicit run at k_s = 1e7 and 1e-3 kg/m^2 already takes ~4e5 substeps for it.
    return matrix_cases(axes, 0.05 if reduced else 0.2) + pathological_cases(reduced)


def summarize(rows: list[dict[str, str]]) -> dict[str, dict[str, int]]:
    """Counts of outcomes per integrator."""
    out: dict[str, dict[str, int]] = {}
    for r in rows:
        d = out.setdefault(r["integrator"], {"stable": 0, "diverged": 0, "silent_nonfinite": 0})
        d[r["outcome"]] += 1
    return out


def write_report(rows: list[dict[str, str]], path: str, machine: str) -> None:
    counts = summarize(rows)
    lines = ["# Stability study", "",
             "Generated by `flagsim study stability`; rerun it to regenerate this page.", "",
             f"Machine: {machine}", "",
             "Each case runs the paper's flag (8 x 11 masses, pinned to the pole, gravity, paper "
             "drag) with the settings of its row; springs: stretch k_s, shear k_s/5, bend k_s/20; "
             "wind along (1, 0, 0.3). Outcomes: **stable** (ran to the end), **diverged** "
             "(DivergenceError raised with the state restored; cause given), **silent_nonfinite** "
             "(non-finite output without an error: must never happen).", "",
             "## Counts", "", "| integrator | stable | diverged | silent non-finite |",
             "|---|---:|---:|---:|"]
    for integ in INTEGRATORS:
        c = counts.get(integ, {"stable": 0, "diverged": 0, "silent_nonfinite": 0})
        lines.append(f"| {integ} | {c['stable']} | {c['diverged']} | {c['silent_nonfinite']} |")
    causes: dict[str, int] = {}
    for r in rows:
        if r["outcome"] == "diverged":
            causes[f"{r['integrator']}: {r['cause']}"] = causes.get(f"{r['integrator']}: {r['cause']}", 0) + 1
    if causes:
        lines += ["", "Divergence causes: " + ", ".join(f"{k} ({v})" for k, v in sorted(causes.items()))]
    lines += ["", "## Pathological cases", "",
              "| case | integrator | outcome | cause | max strain | energy range (J) | max substeps | wall (s) |",
              "|---|---|---|---|---:|---|---:|---:|"]
    for r in rows:
        if r["kind"] != "matrix":
            lines.append(f"| {r['kind']} | {r['integrator']} | {r['outcome']} | {r['cause']} | "
                         f"{r['max_strain']} | {r['energy_min']} .. {r['energy_max']} | "
                         f"{r['max_substeps']} | {r['wall_s']} |")
    lines += ["", "## Matrix", "",
              "| integrator | k_s (N/m) | wind (m/s) | dt (s) | density (kg/m^2) | outcome | cause | max strain | max substeps | wall (s) |",
              "|---|---:|---:|---:|---:|---|---|---:|---:|---:|"]
    for r in rows:
        if r["kind"] == "matrix":
            lines.append(f"| {r['integrator']} | {r['k_s']} | {r['wind']} | {r['dt']} | {r['density']} | "
                         f"{r['outcome']} | {r['cause']} | {r['max_strain']} | {r['max_substeps']} | {r['wall_s']} |")
    from .report import write_text
    write_text(path, "\n".join(lines) + "\n")
