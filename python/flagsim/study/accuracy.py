"""`flagsim study accuracy`: error against run time, with observed convergence orders.

Parts (each point: settings, error, median wall time per step over repeats, steps per second):
  pair        spring-mass pair: largest deviation from the analytic oscillation over one period
  banner      banner in uniform wind: equilibrium-angle error, tan(theta) = D / (m g)
  trajectory  paper flag (uniform wind) at t = 1 s: RMS vertex error against a Richardson-
              extrapolated implicit reference (dt = 1e-4 and 2e-4)
  air         extruded 2-D Taylor-Green vortex at t = T against the exact solution (needs Fluid)
  coupled     paper scene in its air grid at t = 1 s against the finest grid and smallest dt
              (needs Fluid)
  poiseuille  no-slip channel: developed profile against the analytic parabola (accuracy_solids)
  cylinder    flow past a cylinder at Re = 100: Strouhal number and mean drag coefficient
              against published values (accuracy_solids)
Cases run as pure functions of their settings through the study runner; each case stores its
final state (trajectory, coupled) so errors are computed after all cases finished.
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

import numpy as np

import flagsim

from .common import set_method, state_result
from .report import write_text

COLUMNS = [
    "id",
    "part",
    "method",
    "dt",
    "resolution",
    "advection",
    "pressure",
    "tolerance",
    "refinement",
    "steps",
    "error",
    "strouhal",
    "drag_coefficient",
    "seconds_per_step",
    "steps_per_second",
    "state",
]

METHODS = ("implicit", "explicit_adaptive", "explicit_sub8")


# ---- scenes -------------------------------------------------------------------------------------


def pair_scene(method: str, dt: float, k: float = 100.0) -> flagsim.Scene:
    """One free mass on a vertical spring (vertices 0-2 pinned): period 2 pi sqrt(m_3 / k)."""
    s = flagsim.Scene()
    s.flag.rows = s.flag.cols = 2
    s.flag.width = s.flag.height = 0.1
    s.flag.stretch_stiffness = k
    s.flag.shear_stiffness = s.flag.bend_stiffness = s.flag.damping = 0.0
    s.flag.pinned_vertices = [0, 1, 2]
    s.air.model = "none"
    s.gravity = (0, 0, 0)
    s.integrator.cg_tolerance = 1e-12
    s.dt = dt
    set_method(s, method)
    return s


def trajectory_scene(method: str, dt: float) -> flagsim.Scene:
    s = flagsim.Scene.paper()
    s.air.model = "uniform"  # cloth alone: the coupled part runs the grid
    s.flapping.mode = "off"
    s.air.wind = (2.0, 0.0, 0.6)  # out of the flag's plane, so it swings
    s.integrator.cg_tolerance = 1e-10
    s.dt = dt
    set_method(s, method)
    return s


def banner_scene(method: str, dt: float) -> flagsim.Scene:
    s = flagsim.Scene.banner()
    s.dt = dt
    set_method(s, method)
    return s


# ---- cases --------------------------------------------------------------------------------------


def cases(quick: bool = False) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    pair_divs = (25, 50, 100, 200) if quick else (25, 50, 100, 200, 400, 800, 1600)
    for m in ("implicit", "explicit"):
        for div in pair_divs:
            out.append(dict(id=f"pair-{m}-T/{div}", part="pair", method=m, dt=div, repeats=3))
    traj_dts = (0.02, 0.01, 0.005) if quick else (0.02, 0.01, 0.005, 0.0025, 0.00125, 0.000625)
    for m in METHODS:
        for dt in traj_dts:
            out.append(
                dict(
                    id=f"trajectory-{m}-{dt:g}",
                    part="trajectory",
                    method=m,
                    dt=dt,
                    repeats=1 if quick else 3,
                )
            )
    ref_dts = (2e-3, 1e-3) if quick else (2e-4, 1e-4)
    for dt in ref_dts:
        out.append(
            dict(
                id=f"trajectory-reference-{dt:g}",
                part="trajectory-reference",
                method="implicit",
                dt=dt,
                repeats=1,
            )
        )
    for m in ("implicit", "explicit_adaptive"):
        for dt in (0.02, 0.01) if quick else (0.04, 0.02, 0.01, 0.005):
            out.append(dict(id=f"banner-{m}-{dt:g}", part="banner", method=m, dt=dt, repeats=1))
    from . import accuracy_air, accuracy_solids

    out += accuracy_air.cases(quick)
    out += accuracy_solids.cases(quick)
    return out


def _timed_run(sim: flagsim.Simulation, steps: int) -> float:
    t0 = time.perf_counter()
    sim.step(steps)
    return time.perf_counter() - t0


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    """Pure function of the case's settings (apart from the wall times it measures)."""
    part = case["part"]
    if part == "pair":
        return _run_pair(case)
    if part in ("trajectory", "trajectory-reference"):
        return _run_trajectory(case)
    if part == "banner":
        return _run_banner(case)
    if part in ("poiseuille", "cylinder"):
        from . import accuracy_solids

        return accuracy_solids.run_case(case)
    from . import accuracy_air

    return accuracy_air.run_case(case)


def _run_pair(case: dict[str, Any]) -> dict[str, Any]:
    method, div = case["method"], int(case["dt"])
    probe = flagsim.Simulation(pair_scene(method, 1e-3))
    m, k = probe.node_mass[3], 100.0
    w = math.sqrt(k / m)
    T = 2 * math.pi / w
    dt = T / div
    times, err = [], 0.0
    for _ in range(int(case.get("repeats", 1))):
        sim = flagsim.Simulation(pair_scene(method, dt))
        y0 = sim.positions[3, 1]
        sim.positions[3, 1] -= 1e-4
        err, t = 0.0, 0.0
        for _ in range(div):
            t += _timed_run(sim, 1)
            exact = -1e-4 * math.cos(w * sim.time)
            err = max(err, abs(sim.positions[3, 1] - y0 - exact) / 1e-4)
        times.append(t / div)
    spp = float(np.median(times))
    return dict(dt=dt, steps=div, error=err, seconds_per_step=spp, steps_per_second=1 / spp)


def _run_trajectory(case: dict[str, Any]) -> dict[str, Any]:
    dt = float(case["dt"])
    steps = round(1.0 / dt)
    times = []
    sim = None
    for _ in range(int(case.get("repeats", 1))):
        try:
            sim = flagsim.Simulation(trajectory_scene(case["method"], dt))
        except ValueError as e:  # a setting that cannot run, named before any step
            return dict(
                dt=dt,
                steps=0,
                error="",
                seconds_per_step="",
                steps_per_second="",
                state=f"rejected: {str(e).split(' should')[0]}",
            )
        try:
            times.append(_timed_run(sim, steps) / steps)
        except flagsim.DivergenceError as e:
            return dict(
                dt=dt,
                steps=sim.step_count,
                error="",
                seconds_per_step="",
                steps_per_second="",
                state=f"diverged: {e.cause}",
            )
    spp = float(np.median(times))
    return dict(
        dt=dt,
        steps=steps,
        seconds_per_step=spp,
        steps_per_second=1 / spp,
        **state_result(case["id"], sim.positions.copy()),
    )


def _run_banner(case: dict[str, Any]) -> dict[str, Any]:
    dt = float(case["dt"])
    s = banner_scene(case["method"], dt)
    sim = flagsim.Simulation(s)
    steps = round(20.0 / dt)
    spp = _timed_run(sim, steps) / steps
    u = float(np.linalg.norm(s.air.wind[0][1]))
    want = math.atan(
        0.5 * s.drag.coefficient * s.air.density * u * u / (s.flag.areal_density * 9.81)
    )
    x = sim.positions.reshape(s.flag.rows, s.flag.cols, 3)
    d = x[1:] - x[:1]
    err = float(np.abs(np.arctan2(d[..., 2], -d[..., 1]) - want).max())
    return dict(dt=dt, steps=steps, error=err, seconds_per_step=spp, steps_per_second=1 / spp)


# ---- analysis -----------------------------------------------------------------------------------


def fill_state_errors(rows: list[dict[str, str]], state_dir: str) -> None:
    """Errors of the cases that stored a final state, against their part's reference."""
    refs = sorted(
        (r for r in rows if r["part"] == "trajectory-reference"), key=lambda r: float(r["dt"])
    )
    if len(refs) == 2 and all(r["state"].endswith(".npy") for r in refs):
        fine = np.load(os.path.join(state_dir, refs[0]["state"]))
        coarse = np.load(os.path.join(state_dir, refs[1]["state"]))
        reference = 2 * fine - coarse  # Richardson: backward Euler is first order in dt
        for r in rows:
            if r["part"] == "trajectory" and r["state"].endswith(".npy"):
                x = np.load(os.path.join(state_dir, r["state"]))
                r["error"] = repr(float(np.sqrt(((x - reference) ** 2).sum(axis=1).mean())))
        refs[0]["error"] = repr(float(np.sqrt(((fine - reference) ** 2).sum(axis=1).mean())))
    from . import accuracy_air

    accuracy_air.fill_state_errors(rows, state_dir)


def observed_order(
    rows: list[dict[str, str]], part: str, method: str, key: str = "dt", **match: str
) -> float:
    """Least-squares slope of log(error) against log(key) over the part's points."""
    pts = [
        (float(r[key]), float(r["error"]))
        for r in rows
        if r["part"] == part
        and r["method"] == method
        and r["error"] not in ("", "nan")
        and float(r["error"]) > 0
        and all(r.get(k) == v for k, v in match.items())
    ]
    if len(pts) < 2:
        return math.nan
    h, e = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(h, e, 1)[0])


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats in both cost and error (lower is better)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


# ---- report ---------------------------------------------------------------------------------

PART_TITLES = {
    "pair": "Spring-mass pair: max deviation over one period / amplitude",
    "trajectory": "Paper flag in uniform wind: RMS vertex error at t = 1 s (m)",
    "banner": "Banner equilibrium angle error after 20 s (rad)",
    "air": "Taylor-Green vortex: RMS velocity error at t = T (m/s)",
    "coupled": "Paper scene in its air grid: RMS vertex error at t = 1 s (m)",
    "poiseuille": "Plane Poiseuille flow: RMS profile error / U",
    "cylinder": "Cylinder at Re = 100: larger relative error of St and mean C_D",
}


def _series(rows, part):
    out: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        if r["part"] == part and r["error"] not in ("", "nan") and r["seconds_per_step"]:
            key = (
                r["method"]
                if part != "air"
                else (
                    f"{r['advection']} + {r['pressure']} "
                    f"(tol {float(r['tolerance']):g}, {r['refinement']})"
                )
            )
            if part == "coupled":
                key = f"{r['method']}, {r['resolution']}^3"
            out.setdefault(key, []).append(r)
    return out


def write_plots(rows, directory) -> dict[str, str]:
    """One log-log PNG per part: error against wall time per simulated second (what a user pays
    for a second of animation: a smaller dt pays for its extra steps), the Pareto front marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(directory, exist_ok=True)
    paths = {}
    for part, title in PART_TITLES.items():
        series = _series(rows, part)
        if not series:
            continue
        fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=100)
        allpts = []
        for name, rs in sorted(series.items()):
            pts = sorted((_cost(r), float(r["error"])) for r in rs)
            allpts += pts
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=name, ms=4)
        front = sorted(allpts[i] for i in pareto(allpts))
        ax.loglog([p[0] for p in front], [p[1] for p in front], "k--", lw=1, label="Pareto front")
        ax.set_xlabel("wall time per simulated second (s/s)")
        ax.set_ylabel("error")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        path = os.path.join(directory, f"accuracy_{part}.png")
        tmp = path + ".tmp.png"
        fig.savefig(tmp)
        plt.close(fig)
        os.replace(tmp, path)
        paths[part] = path
    return paths


def _cost(r) -> float:
    """Wall seconds per simulated second: a smaller dt pays for its extra steps."""
    return float(r["seconds_per_step"]) / float(r["dt"])


def _cheapest(rows, part, target):
    ok = [
        r
        for r in rows
        if r["part"] == part and r["error"] not in ("", "nan") and float(r["error"]) <= target
    ]
    return min(ok, key=_cost) if ok else None


def _cheapest_table(rows, part, title) -> list[str]:
    lines = [
        f"## {title}: cheapest setting per error target",
        "",
        "Cheapest = least wall time per simulated second (seconds per step / dt).",
        "",
        "| target | cheapest setting | error (m) | wall s per simulated s | steps/s |",
        "|---|---|---:|---:|---:|",
    ]
    for target in (1e-2, 1e-3, 1e-4):
        r = _cheapest(rows, part, target)
        lines.append(
            f"| {target:g} m | "
            + (
                f"{_describe(r)} | {float(r['error']):.3g} | {_cost(r):.3g} | "
                f"{float(r['steps_per_second']):,.0f} |"
                if r
                else "none of the sweep | | | |"
            )
        )
    return lines + [""]


def _solids_section(rows) -> list[str]:
    """The cylinder against its references, resolution by resolution."""
    cyl = [r for r in rows if r["part"] == "cylinder"]
    if not cyl:
        return []
    from .accuracy_solids import CD_RANGE, ST_REF

    lines = [
        "## Solids in the air: the cylinder at Re = 100",
        "",
        f"References: Strouhal number {ST_REF:.4f} (Williamson's fit St(Re) = -3.3265/Re + 0.1816 "
        f"+ 1.6e-4 Re), mean drag coefficient {CD_RANGE[0]}-{CD_RANGE[1]}. Within 5 % of both "
        "is marked *.",
        "",
        "| advection | cells per D | pressure | St | St error | C_D | C_D error "
        "| wall s per simulated s | |",
        "|---|---:|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in sorted(cyl, key=lambda r: (r["method"], int(r["resolution"]))):
        if r["strouhal"] in ("", "nan"):
            lines.append(
                f"| {r['method']} | {r['resolution']} | {r['pressure']} | {r['state']} "
                "| | | | | |"
            )
            continue
        st, cd = float(r["strouhal"]), float(r["drag_coefficient"])
        st_err = st / ST_REF - 1
        cd_err = (
            0.0
            if CD_RANGE[0] <= cd <= CD_RANGE[1]
            else min(cd / CD_RANGE[0] - 1, cd / CD_RANGE[1] - 1, key=abs)
        )
        ok = abs(st_err) <= 0.05 and abs(cd_err) <= 0.05
        lines.append(
            f"| {r['method']} | {r['resolution']} | {r['pressure']} | {st:.4f} | {st_err:+.1%} "
            f"| {cd:.3f} | {cd_err:+.1%} | {_cost(r):.3g} | {'*' if ok else ''} |"
        )
    return lines + [""]


def _describe(r) -> str:
    bits = [r["method"]]
    if r["part"] == "poiseuille":
        bits.append(f"{r['resolution']} cells across the channel, {r['refinement']}")
    elif r["part"] == "cylinder":
        bits.append(f"{r['resolution']} cells per diameter, {r['pressure']}")
    elif r.get("resolution"):
        bits.append(f"{r['resolution']}^3 grid")
    if r.get("dt"):
        bits.append(f"dt = {float(r['dt']):.4g} s")
    return ", ".join(bits)


def write_report(rows, path, plots, relative_to, machine: str) -> None:
    """The markdown report; machine: the machine line (run_accuracy reads machine_description()
    before it writes anything, so a report regenerated into a checkout does not call its own
    plots local changes)."""
    lines = [
        "# Accuracy study: error against run time",
        "",
        "Generated by `flagsim study accuracy`; rerun it to regenerate this page.",
        "",
        f"Machine: {machine}",
        "",
        "Each point: the settings, the error against an analytic solution or a converged "
        "reference, and its cost as a user pays it: wall time per simulated second (the median "
        "wall time per step over repeated runs, divided by dt), with steps per second beside "
        "it. Plots, Pareto fronts and tables all use that cost. Points on the Pareto front (no "
        "other point is both cheaper and more accurate) are marked with *.",
        "",
    ]
    lines += [
        "## Observed convergence orders",
        "",
        "| part | method | order | against |",
        "|---|---|---:|---|",
    ]
    for m in ("explicit", "implicit"):
        lines.append(f"| pair | {m} | {observed_order(rows, 'pair', m):.2f} | dt |")
    for m in ("implicit", "explicit_adaptive", "explicit_sub8"):
        lines.append(f"| trajectory | {m} | {observed_order(rows, 'trajectory', m):.2f} | dt |")
    for adv in ("semi_lagrangian", "maccormack"):
        for p in ("fft", "pcg"):
            for ref, label in (
                ("cfl", "h, dt proportional to h"),
                ("dt~h^2", "h, dt proportional to h^2"),
            ):
                q = observed_order(
                    rows,
                    "air",
                    adv,
                    key="resolution",
                    pressure=p,
                    tolerance=repr(1e-8),
                    refinement=ref,
                )
                if not math.isnan(q):
                    lines.append(f"| air | {adv} + {p} | {-q:.2f} | {label} |")
    dts = sorted({float(r["dt"]) for r in rows if r["part"] == "coupled"})
    for m in ("implicit", "explicit_adaptive"):
        if dts:
            q = observed_order(rows, "coupled", m, key="resolution", dt=repr(dts[0]))
            lines.append(
                f"| coupled (dt = {dts[0]:g} s) | {m} | {-q:.2f} | "
                "grid h, against the finest grid |"
            )
    for adv in ("semi_lagrangian", "maccormack"):
        for ref, label in (("cfl", "h, dt proportional to h"), ("dt~h^2", "h, dt ~ h^2")):
            q = observed_order(rows, "poiseuille", adv, key="resolution", refinement=ref)
            if not math.isnan(q):
                lines.append(f"| poiseuille | {adv} | {-q:.2f} | {label} |")
    lines.append("")
    lines += _solids_section(rows)
    if any(r["part"] == "coupled" for r in rows):
        lines += _cheapest_table(rows, "coupled", "Coupled paper scene")
        paper = [
            r
            for r in rows
            if r["part"] == "coupled"
            and r["resolution"] == "16"
            and abs(float(r["dt"]) - 0.01) < 1e-12
            and r["error"]
        ]
        for r in paper:
            lines.append(
                f"The paper's own setting (16^3 grid, dt = 0.01 s, {r['method']}): "
                f"error {float(r['error']):.3g} m at {float(r['steps_per_second']):,.0f} steps/s "
                f"({_cost(r):.3g} wall s per simulated s)."
            )
            lines.append("")
    if any(r["part"] == "trajectory" for r in rows):
        lines += _cheapest_table(rows, "trajectory", "Cloth alone (paper flag, uniform wind)")
    for part, title in PART_TITLES.items():
        pr = [r for r in rows if r["part"] == part]
        if not pr:
            continue
        lines += [f"## {title}", ""]
        if part in plots:
            lines += [f"![{part}]({os.path.relpath(plots[part], relative_to)})", ""]
        lines += [
            "| settings | error | wall s per simulated s | steps/s | |",
            "|---|---:|---:|---:|---|",
        ]
        ok = [r for r in pr if r["error"] not in ("", "nan")]
        front = {id(ok[i]) for i in pareto([(_cost(r), float(r["error"])) for r in ok])}
        for r in pr:
            settings = (
                _describe(r)
                if part != "air"
                else (
                    f"{r['advection']} + {r['pressure']}, tol {float(r['tolerance']):g}, "
                    f"{r['resolution']}^2 x 4, "
                    f"dt = {float(r['dt']):.3g} s"
                )
            )
            if r["error"] in ("", "nan"):
                lines.append(f"| {settings} | {r['state'] or 'n/a'} | | | |")
            else:
                lines.append(
                    f"| {settings} | {float(r['error']):.3g} | {_cost(r):.3g} | "
                    f"{float(r['steps_per_second']):,.0f} | {'*' if id(r) in front else ''} |"
                )
        lines.append("")
    if not any(r["part"] in ("air", "coupled") for r in rows):
        lines += [
            "The air parts (Taylor-Green, coupled scene) need the Stable Fluids solver "
            "(flagsim.Fluid) and were not run.",
            "",
        ]
    write_text(path, "\n".join(lines))
