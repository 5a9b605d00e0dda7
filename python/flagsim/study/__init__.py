"""Studies users asked for: error against run time (`accuracy`), stability on stiff and
extreme cases (`stability`), and the flag's flapping against published flags (`flutter`). All
run their cases through a concurrent.futures.Executor (local processes by default; a Dask
cluster's, docs/distributed.md), resume from their CSV, and write CSV + markdown (+ PNG plots),
and tasks.csv: where each case ran and how long it took.

    python -m flagsim.study stability --out DIR [--reduced] [--jobs N]
    python -m flagsim.study accuracy --out DIR [--quick] [--jobs N]
    python -m flagsim.study flutter --out DIR [--quick] [--jobs N]

    from distributed import Client
    with Client("tcp://scheduler:8786") as client:
        run_stability("out/stab", executor=client.get_executor())
"""

from __future__ import annotations

import os

from .report import machine_description
from .runner import run_cases

#: the study's task index (runner.INDEX_COLUMNS): which worker ran each case, attempts, seconds
TASK_INDEX = "tasks.csv"


def _run(module, cases, out: str, csv: str, *, jobs, executor, progress, **kw):
    """The study's cases through the runner (resumable CSV out/csv, the task index beside it)."""
    return run_cases(
        cases,
        module.run_case,
        os.path.join(out, csv),
        module.COLUMNS,
        jobs=jobs,
        executor=executor,
        progress=progress,
        desc=module.__name__.rsplit(".", 1)[-1],
        index=os.path.join(out, TASK_INDEX),
        **kw,
    )


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

    machine = machine_description()  # before anything is written: see accuracy.write_report
    rows = _run(
        stability,
        stability.cases(reduced),
        out,
        "stability.csv",
        jobs=jobs,
        executor=executor,
        progress=progress,
    )
    stability.write_report(rows, report_path or os.path.join(out, "stability.md"), machine)
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

    machine = machine_description()
    state_dir = os.path.join(out, "states")
    rows = _run(
        accuracy,
        accuracy.cases(quick),
        out,
        "runs.csv",
        jobs=jobs,
        executor=executor,
        progress=progress,
        files_dir=state_dir,  # the final states the cases return
    )
    rows = [dict(r) for r in rows]
    accuracy.fill_state_errors(rows, state_dir)
    from .runner import _rewrite_clean

    _rewrite_clean(os.path.join(out, "accuracy.csv"), accuracy.COLUMNS, rows)
    plots = accuracy.write_plots(rows, plot_dir or out)
    accuracy.write_report(
        rows,
        report_path or os.path.join(out, "accuracy.md"),
        plots,
        os.path.dirname(report_path) if report_path else out,
        machine,
    )
    return rows


def run_flutter(
    out: str,
    *,
    quick: bool = False,
    jobs: int = 1,
    executor=None,
    progress: bool = True,
    report_path: str | None = None,
    plot_dir: str | None = None,
) -> list[dict[str, str]]:
    from . import flutter

    machine = machine_description()
    rows = _run(
        flutter,
        flutter.cases(quick),
        out,
        "flutter.csv",
        jobs=jobs,
        executor=executor,
        progress=progress,
    )
    plot = flutter.write_plots(rows, plot_dir or out)
    report = report_path or os.path.join(out, "flutter.md")
    flutter.write_report(rows, report, plot, os.path.dirname(os.path.abspath(report)), machine)
    return rows
