"""Scale-out benchmark (issue 25): the reduced stability study and a small sweep, run in this
process, in the local process pool and on a Dask LocalCluster of 1 and 2 worker processes (one
thread each), with their wall times and the ratios that matter:

  speedup_2v1         Dask 1 worker / Dask 2 workers (the issue's target: >= 1.7 on 2 idle cores)
  dask_over_pool      Dask N workers / local pool of N processes: the Dask path's overhead
  per_task_ms         wall time per task

    python -m benchmarks.cluster --out out/bench            # cluster.csv, cluster.md
    python -m benchmarks.cluster --only sweep --repeats 1

Every run starts from an empty folder (nothing to resume). A local pool is started by each run,
as each command starts its own, so its start-up is in its times; a Dask cluster outlives one
command, so its start-up (what `--workers N` adds to a command) is a row of its own. The CSV's '#'
lines describe the machine and its load: on a machine shared with other work the ratios say less
than on an idle one.
"""

from __future__ import annotations

import argparse
import csv
import logging
import os
import shutil
import statistics
import sys
import tempfile
import time

from .machine import describe, load_average

WORKLOADS = ("stability", "sweep")
SWEEP_VARY = {"air.wind": [[2, 0, 0], [5, 0, 0], [8, 0, 1]], "flag.stretch_stiffness": [100, 1000]}
SWEEP_SECONDS = 2.0
COLUMNS = ["workload", "tasks", "executor", "workers", "runs", "wall_s_min", "wall_s_median",
           "per_task_ms", "speedup_2v1", "dask_over_pool"]  # fmt: skip


def _stability(out, executor, jobs):
    from flagsim import study

    study.run_stability(out, reduced=True, jobs=jobs, executor=executor, progress=False)


def _sweep(out, executor, jobs):
    import flagsim
    from flagsim.sweep import run_sweep

    render = shutil.which("povray") is not None
    run_sweep(
        flagsim.Scene.paper(),
        SWEEP_VARY,
        out,
        seconds=SWEEP_SECONDS,
        render=render,
        width=160,
        height=120,
        source={"builtin": "paper"},
        jobs=jobs,
        executor=executor,
        progress=False,
    )


def _smoke(out, executor, jobs):
    import flagsim
    from flagsim.sweep import run_sweep

    run_sweep(flagsim.Scene.paper(), {"flag.rows": [5, 6]}, out, seconds=0.1, jobs=jobs,
              executor=executor, progress=False)  # fmt: skip


def _tasks(workload):
    if workload == "stability":
        from flagsim.study import stability

        return len(stability.cases(True))
    n = 1
    for values in SWEEP_VARY.values():
        n *= len(values)
    return n


def _time(fn, executor, jobs, repeats):
    times = []
    for _ in range(repeats):
        out = tempfile.mkdtemp(prefix="flagsim-bench-cluster-")
        try:
            t0 = time.perf_counter()
            fn(out, executor, jobs)
            times.append(time.perf_counter() - t0)
        finally:
            shutil.rmtree(out, ignore_errors=True)
    return times


def run(only=WORKLOADS, repeats=3, workers=(1, 2), smoke=False) -> list[dict]:
    import distributed

    rows = []
    for workload in only:
        fn = {"stability": _stability, "sweep": _sweep}[workload]
        if smoke:  # seconds: a 2-task sweep of 0.1 s without rendering
            fn = _smoke
        n = 2 if smoke else _tasks(workload)
        measured = {}
        measured[("here", 1)] = _time(fn, None, 1, repeats)
        for w in workers:
            if w > 1:
                measured[("pool", w)] = _time(fn, None, w, repeats)
        t0 = time.perf_counter()
        with (
            distributed.LocalCluster(
                n_workers=workers[0],
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",
                silence_logs=logging.ERROR,
            ) as cluster,
            distributed.Client(cluster) as client,
        ):
            client.wait_for_workers(workers[0])
            startup = time.perf_counter() - t0
            for w in workers:  # one cluster, grown: its start-up is timed apart
                cluster.scale(w)
                client.wait_for_workers(w)
                ex = client.get_executor()
                measured[("dask", w)] = _time(fn, ex, 1, repeats)
        for (kind, w), times in measured.items():
            med = statistics.median(times)
            row = dict(
                workload=workload,
                tasks=n,
                executor=kind,
                workers=w,
                runs=len(times),
                wall_s_min=f"{min(times):.3f}",
                wall_s_median=f"{med:.3f}",
                per_task_ms=f"{1e3 * med / n:.1f}",
                speedup_2v1="",
                dask_over_pool="",
            )
            if kind == "dask" and w > 1 and ("dask", 1) in measured:
                row["speedup_2v1"] = f"{min(measured[('dask', 1)]) / min(times):.2f}"
            base = ("pool", w) if w > 1 else ("here", 1)
            if kind == "dask" and base in measured:
                row["dask_over_pool"] = f"{min(times) / min(measured[base]):.2f}"
            rows.append(row)
        rows.append(dict.fromkeys(COLUMNS, ""))
        rows[-1].update(
            workload=f"{workload}: cluster start-up",
            executor="dask",
            workers=workers[0],
            runs=1,
            wall_s_min=f"{startup:.3f}",
            wall_s_median=f"{startup:.3f}",
        )
    return rows


def write(rows, out_dir, machine, load_end) -> None:
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "cluster.csv"), "w", newline="") as f:
        for k, v in {**machine, "load_average_end": load_end}.items():
            f.write(f"# {k}: {v}\n")
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(str(r[c]) for c in COLUMNS) + " |" for r in rows]
    with open(os.path.join(out_dir, "cluster.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m benchmarks.cluster",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="out/bench", metavar="DIR", help="for cluster.csv, cluster.md")
    p.add_argument("--only", metavar="LIST", help=f"among {', '.join(WORKLOADS)} (default: all)")
    p.add_argument("--repeats", type=int, default=3, metavar="N", help="runs each (min, median)")
    p.add_argument("--smoke", action="store_true", help="a 2-task sweep, once (seconds; for CI)")
    args = p.parse_args(argv)
    only = tuple(x.strip() for x in (args.only or ",".join(WORKLOADS)).split(",") if x.strip())
    bad = [x for x in only if x not in WORKLOADS]
    if bad or args.repeats < 1:
        p.error(f"--only should be among {', '.join(WORKLOADS)} and --repeats >= 1")
    machine = describe()
    rows = run(
        ("sweep",) if args.smoke else only, 1 if args.smoke else args.repeats, smoke=args.smoke
    )
    write(rows, args.out, machine, load_average())
    with open(os.path.join(args.out, "cluster.md")) as f:
        sys.stdout.write(f.read())
    return 0


if __name__ == "__main__":
    sys.exit(main())
