"""Studies users asked for: error against run time (`accuracy`) and stability on stiff and
extreme cases (`stability`). Both run their cases through a concurrent.futures.Executor
(local processes by default), resume from their CSV, and write CSV + markdown (+ PNG plots).

    python -m flagsim.study stability --out DIR [--reduced] [--jobs N]
    python -m flagsim.study accuracy --out DIR [--quick] [--jobs N]
"""

from __future__ import annotations

import functools
import math
import os

from .report import machine_description, write_text
from .runner import run_cases


def run_stability(
    out: str,
    *,
    reduced: bool = False,
    jobs: int = 1,
    executor=None,
    progress: bool = True,
    report_path: str | None = None,
) -> list[dict[str, str]]:
    from . import stability

    rows = run_cases(
        stability.cases(reduced),
        stability.run_case,
        os.path.join(out, "stability.csv"),
        stability.COLUMNS,
        jobs=jobs,
        executor=executor,
        progress=progress,
        desc="stability",
    )
    stability.write_report(
        rows, report_path or os.path.join(out, "stability.md"), machine_description()
    )
    return rows


def run_accuracy(
    out: str,
    *,
    quick: bool = False,
    jobs: int = 1,
    executor=None,
    progress: bool = True,
    report_path: str | None = None,
    plot_dir: str | None = None,
) -> list[dict[str, str]]:
    from . import accuracy

    state_dir = os.path.join(out, "states")
    fn = functools.partial(accuracy.run_case, state_dir=state_dir)
    rows = run_cases(
        accuracy.cases(quick),
        fn,
        os.path.join(out, "runs.csv"),
        accuracy.COLUMNS,
        jobs=jobs,
        executor=executor,
        progress=progress,
        desc="accuracy",
    )
    rows = [dict(r) for r in rows]
    accuracy.fill_state_errors(rows, state_dir)
    from .runner import _rewrite_clean

    _rewrite_clean(os.path.join(out, "accuracy.csv"), accuracy.COLUMNS, rows)
    plots = write_accuracy_plots(rows, plot_dir or out)
    write_accuracy_report(
        rows,
        report_path or os.path.join(out, "accuracy.md"),
        plots,
        os.path.dirname(report_path) if report_path else out,
    )
    return rows


PART_TITLES = {
    "pair": "Spring-mass pair: max deviation over one period / amplitude",
    "trajectory": "Paper flag in uniform wind: RMS vertex error at t = 1 s (m)",
    "banner": "Banner equilibrium angle error after 20 s (rad)",
    "air": "Taylor-Green vortex: RMS velocity error at t = T (m/s)",
    "coupled": "Paper scene in its air grid: RMS vertex error at t = 1 s (m)",
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


def write_accuracy_plots(rows, directory) -> dict[str, str]:
    """One log-log PNG per part: error against seconds per step, the Pareto front marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .accuracy import pareto

    os.makedirs(directory, exist_ok=True)
    paths = {}
    for part, title in PART_TITLES.items():
        series = _series(rows, part)
        if not series:
            continue
        fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=100)
        allpts = []
        for name, rs in sorted(series.items()):
            pts = sorted((float(r["seconds_per_step"]), float(r["error"])) for r in rs)
            allpts += pts
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=name, ms=4)
        front = sorted(allpts[i] for i in pareto(allpts))
        ax.loglog([p[0] for p in front], [p[1] for p in front], "k--", lw=1, label="Pareto front")
        ax.set_xlabel("wall time per step (s)")
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


def _describe(r) -> str:
    bits = [r["method"]]
    if r.get("resolution"):
        bits.append(f"{r['resolution']}^3 grid")
    if r.get("dt"):
        bits.append(f"dt = {float(r['dt']):.4g} s")
    return ", ".join(bits)


def write_accuracy_report(rows, path, plots, relative_to) -> None:
    from .accuracy import observed_order, pareto

    lines = [
        "# Accuracy study: error against run time",
        "",
        "Generated by `flagsim study accuracy`; rerun it to regenerate this page.",
        "",
        f"Machine: {machine_description()}",
        "",
        "Each point: the settings, the error against an analytic solution or a converged "
        "reference, the median wall time per step over repeated runs, and steps per second. "
        "Points on the Pareto front (no other point is both cheaper and more accurate) are "
        "marked with *.",
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
    lines.append("")
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
        lines += ["| settings | error | s/step | steps/s | |", "|---|---:|---:|---:|---|"]
        ok = [r for r in pr if r["error"] not in ("", "nan")]
        front = {
            id(ok[i])
            for i in pareto([(float(r["seconds_per_step"]), float(r["error"])) for r in ok])
        }
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
                    f"| {settings} | {float(r['error']):.3g} | "
                    f"{float(r['seconds_per_step']):.3g} | "
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


def main(argv=None) -> int:
    from ..cli import main as cli_main

    return cli_main(["study", *(argv if argv is not None else __import__("sys").argv[1:])])
