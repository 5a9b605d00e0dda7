"""Command line of the benchmark: `python -m benchmarks` from the repository root (`make bench`)."""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Any

from . import workloads as wl

EXAMPLES = """examples:
  python -m benchmarks --quick --out out/bench            about a minute
  python -m benchmarks --only cloth --sizes 8x11,128x128 --threads 1
  python -m benchmarks --only air --sizes 32,64 --advection semi_lagrangian --pressure fft,pcg
  python -m benchmarks --only solver --sizes 64,128        multigrid against pcg and fft
  python -m benchmarks --peers --docs docs/reports/performance.md  the full run behind the docs
"""


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark's options to a parser (`python -m benchmarks` uses this)."""
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EXAMPLES
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument(
        "--quick",
        action="store_true",
        help="fewer sizes and thread counts, runs of >= 0.1 s (about a minute)",
    )
    mode.add_argument(
        "--smoke",
        action="store_true",
        help="the smallest of each group, runs of >= 0.01 s (seconds; for CI)",
    )
    parser.add_argument(
        "--out",
        default="out/bench",
        metavar="DIR",
        help="directory for results.csv, results.md, scaling.png, peers.csv, results.json "
        "(default: %(default)s)",
    )
    parser.add_argument(
        "--only",
        metavar="GROUPS",
        help=f"comma-separated groups among {', '.join(wl.GROUPS)} "
        "(default: paper,cloth,air,solver)",
    )
    parser.add_argument(
        "--peers",
        action="store_true",
        help="also run PyBullet, MuJoCo and pyPBD on the same cloth and the numpy Stable "
        "Fluids baseline on the same air (pip install .[bench]); missing ones are skipped",
    )
    parser.add_argument(
        "--sizes",
        metavar="LIST",
        help="comma-separated sizes: ROWSxCOLS for cloth (8x11), N or N^3 for air and solver (64)",
    )
    parser.add_argument(
        "--threads", metavar="LIST", help="comma-separated thread counts (default: 1,2)"
    )
    parser.add_argument("--integrators", metavar="LIST", help=f"among {', '.join(wl.INTEGRATORS)}")
    parser.add_argument("--advection", metavar="LIST", help=f"among {', '.join(wl.ADVECTION)}")
    parser.add_argument("--pressure", metavar="LIST", help=f"among {', '.join(wl.PRESSURE)}")
    parser.add_argument(
        "--no-self-collision", action="store_true", help="cloth without self-collision only"
    )
    parser.add_argument("--no-float", action="store_true", help="skip the float32 grid variants")
    parser.add_argument(
        "--min-time", type=float, metavar="S", help="a run lasts at least S seconds"
    )
    parser.add_argument(
        "--repeats", type=int, metavar="N", help="runs per workload (min and median)"
    )
    parser.add_argument("--warmup", type=int, metavar="N", help="steps dropped before timing")
    parser.add_argument(
        "--timeout",
        type=float,
        default=1800.0,
        metavar="S",
        help="give up on one workload after S seconds (default: %(default)g)",
    )
    parser.add_argument(
        "--docs",
        metavar="PATH",
        help="also write the report as PATH (docs/reports/performance.md) with its plot beside",
    )
    parser.add_argument("--no-plot", action="store_true", help="no PNG (matplotlib not needed)")
    parser.add_argument(
        "--list", action="store_true", help="list the workloads and skips, run nothing"
    )


def _split(text: str | None) -> list[str]:
    return [t.strip() for t in (text or "").split(",") if t.strip()]


def _choices(name: str, text: str | None, allowed) -> tuple[str, ...] | None:
    if text is None:
        return None
    items = _split(text)
    bad = [i for i in items if i not in allowed]
    if bad or not items:
        raise ValueError(
            f"--{name} should be a comma-separated list among {', '.join(allowed)}, got {text!r}"
        )
    return tuple(items)


def parse_sizes(text: str | None):
    """('8x11,64') -> (((8, 11),), (64,)); None for a group the list does not mention."""
    if text is None:
        return None, None
    cloth, air = [], []
    for tok in _split(text):
        t = tok.lower().replace("^3", "")
        try:
            if "x" in t:
                r, c = (int(v) for v in t.split("x"))
                if r < 2 or c < 2:
                    raise ValueError
                cloth.append((r, c))
            else:
                n = int(t)
                if n < 2:
                    raise ValueError
                air.append(n)
        except ValueError:
            raise ValueError(
                f"--sizes should list ROWSxCOLS (>= 2) or N (>= 2) items, got {tok!r}"
            ) from None
    if not cloth and not air:
        raise ValueError(f"--sizes should list at least one size, got {text!r}")
    return (tuple(cloth) or None), (tuple(air) or None)


def selection(args) -> tuple[wl.Selection, dict[str, Any]]:
    mode = "smoke" if args.smoke else "quick" if args.quick else "full"
    groups = _choices("only", args.only, wl.GROUPS) or wl.Selection().groups
    if args.peers and "peers" not in groups:
        groups = groups + ("peers",)
    cloth_sizes, air_sizes = parse_sizes(args.sizes)
    threads = None
    if args.threads is not None:
        try:
            threads = tuple(int(t) for t in _split(args.threads))
        except ValueError:
            threads = ()
        if not threads or min(threads) < 1:
            raise ValueError(
                f"--threads should be a comma-separated list of counts >= 1, got {args.threads!r}"
            )
    sel = wl.Selection(
        mode=mode,
        groups=groups,
        cloth_sizes=cloth_sizes,
        air_sizes=air_sizes,
        threads=threads,
        integrators=_choices("integrators", args.integrators, wl.INTEGRATORS) or wl.INTEGRATORS,
        advection=_choices("advection", args.advection, wl.ADVECTION) or wl.ADVECTION,
        pressure=_choices("pressure", args.pressure, wl.PRESSURE) or wl.PRESSURE,
        self_collision=(False,) if args.no_self_collision else (False, True),
        float_grid=not args.no_float,
    )
    protocol = dict(wl.PROTOCOLS[mode])
    for key in ("min_time", "repeats", "warmup"):
        v = getattr(args, key)
        if v is not None:
            if (key == "min_time" and not v > 0) or (
                key != "min_time" and v < (1 if key == "repeats" else 0)
            ):
                bound = "> 0" if key == "min_time" else ">= 1" if key == "repeats" else ">= 0"
                raise ValueError(f"--{key.replace('_', '-')} should be {bound}, got {v}")
            protocol[key] = v
    return sel, protocol


def run_workload(w: wl.Workload, protocol: dict[str, Any], timeout: float) -> dict[str, Any]:
    """Measure one workload in a fresh process; a failure comes back as {'ok': False, 'error'}."""
    spec = json.dumps(w.spec(protocol))
    import flagsim

    # The worker runs in a temporary directory: make sure it imports this same flagsim and these
    # same benchmarks.
    package_root = os.path.dirname(os.path.dirname(os.path.abspath(flagsim.__file__)))
    bench_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    paths = [package_root, bench_root] + [
        os.path.abspath(p) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p
    ]
    env = dict(
        os.environ,
        OMP_NUM_THREADS=str(w.threads),
        OPENBLAS_NUM_THREADS="1",
        MKL_NUM_THREADS="1",
        PYTHONPATH=os.pathsep.join(paths),
    )
    with tempfile.TemporaryDirectory(prefix="flagsim-bench-") as tmp:
        path = os.path.join(tmp, "result.json")
        try:
            # cwd: engines that write logs to the working directory (MuJoCo) write them there
            proc = subprocess.run(
                [sys.executable, "-m", "benchmarks.worker", spec, path],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
                timeout=timeout,
                cwd=tmp,
            )
        except subprocess.TimeoutExpired:
            return {"ok": False, "error": f"timed out after {timeout:g} s"}
        if os.path.exists(path):
            with open(path, encoding="utf-8") as f:
                return json.load(f)
        tail = (proc.stderr or "").strip().splitlines()[-1:] or ["no output"]
        return {"ok": False, "error": f"worker exited with code {proc.returncode}: {tail[0]}"}


def _progress(i: int, total: int, w: wl.Workload, row: dict[str, Any]) -> str:
    head = f"[{i}/{total}] {w.name}: "
    if not row["ok"]:
        return head + "FAILED: " + row["note"]
    return (
        head + f"{row['steps_per_s']:,.1f} steps/s (median {row['ms_median']:.4g} ms, min "
        f"{row['ms_min']:.4g} ms, cpu {row['cpu_ms_median']:.4g} ms), +{row['workload_mb']:.1f} MiB"
    )


def taylor_green(sel: wl.Selection, features) -> dict[str, Any] | None:
    if (
        "air" not in sel.groups
        or not sel.float_grid
        or sel.mode == "smoke"
        or not features["fluid"][0]
    ):
        return None
    from .engines import taylor_green_errors

    try:
        return taylor_green_errors()
    except Exception as e:  # reported, never fatal
        return {"error": f"{type(e).__name__}: {e}"}


def run(args) -> int:
    """Run the benchmark an argparse namespace describes (configure()'s options); exit code."""
    try:
        sel, protocol = selection(args)
    except ValueError as e:
        print(f"benchmarks: error: {e}", file=sys.stderr)
        return 2
    from . import engines, machine, peers, report

    features = engines.features()
    peer_status = {p: peers.peer_available(p) for p in peers.PEERS} if "peers" in sel.groups else {}
    from .taichi_air import taichi_available

    baselines = {
        "fftw": engines.fftw_available(),
        "numpy": engines.numpy_baseline_available(),
        "taichi": taichi_available(),
    }
    work, skipped = wl.catalogue(sel, features, peer_status, baselines)
    for what, why in skipped:
        print(f"skip {what}: {why}", flush=True)
    if args.list:
        for w in work:
            print(w.name)
        print(f"{len(work)} workloads, {len(skipped)} skipped")
        return 0
    if not work:
        print("benchmarks: error: nothing to run with this selection", file=sys.stderr)
        return 2

    os.makedirs(args.out, exist_ok=True)
    desc = machine.describe()
    argv = getattr(args, "_argv", None)
    command = (
        ("python -m benchmarks " + " ".join(argv))
        if argv is not None
        else "flagsim " + " ".join(sys.argv[1:])
    )
    print(
        f"{len(work)} workloads on {desc['cpu']} ({desc['usable_cpus']} cpus, "
        f"load {desc['load_average_start']}),"
        f" flagsim {desc['git_revision']}; results in {args.out}",
        flush=True,
    )
    rows: list[dict[str, Any]] = []
    t_start = time.perf_counter()
    interrupted = False
    try:
        for i, w in enumerate(work, 1):
            row = report.make_row(w, run_workload(w, protocol, args.timeout))
            rows.append(row)
            print(_progress(i, len(work), w, row), flush=True)
    except KeyboardInterrupt:
        interrupted = True
        print("interrupted: writing the workloads measured so far", file=sys.stderr)
    accuracy = None if interrupted else taylor_green(sel, features)
    load_end = machine.load_average()
    comps = report.comparisons(rows)
    plot_name = None
    slope_list = report.slopes(rows)
    if not args.no_plot:
        plot_name = "scaling.png"
        slope_list = report.plot(
            os.path.join(args.out, plot_name),
            rows,
            title=f"{desc['cpu']}, flagsim {desc['git_revision']}, {desc['date']}",
        )
    target_list = report.targets(rows, comps, accuracy)
    report.write_csv(os.path.join(args.out, "results.csv"), rows, desc)
    if comps:
        report.write_peers_csv(os.path.join(args.out, "peers.csv"), comps)
    probe = report.probe_summary(rows)
    md_args = dict(command=command, protocol=protocol, load_end=load_end, probe=probe)
    with open(os.path.join(args.out, "results.md"), "w", encoding="utf-8") as f:
        f.write(
            report.markdown(
                rows, desc, skipped, comps, slope_list, target_list, plot_name=plot_name, **md_args
            )
        )
    with open(os.path.join(args.out, "results.json"), "w", encoding="utf-8") as f:
        json.dump(
            {
                "machine": desc,
                "protocol": protocol,
                "command": command,
                "load_average_end": load_end,
                "rows": [{k: v for k, v in r.items()} for r in rows],
                "skipped": skipped,
                "comparisons": comps,
                "slopes": slope_list,
                "targets": target_list,
                "taylor_green": accuracy,
                "speed_probe": probe,
            },
            f,
            indent=1,
            default=str,
        )
    if args.docs:
        docs_dir = os.path.dirname(os.path.abspath(args.docs))
        os.makedirs(docs_dir, exist_ok=True)
        docs_plot = None
        if plot_name:
            docs_plot = os.path.splitext(os.path.basename(args.docs))[0] + ".png"
            shutil.copyfile(os.path.join(args.out, plot_name), os.path.join(docs_dir, docs_plot))
        with open(args.docs, "w", encoding="utf-8") as f:
            f.write(
                report.markdown(
                    rows,
                    desc,
                    skipped,
                    comps,
                    slope_list,
                    target_list,
                    plot_name=docs_plot,
                    docs=True,
                    **md_args,
                )
            )
    for name, measured, verdict in target_list:
        print(f"target: {name}: {measured} [{verdict}]")
    if probe:
        print(report.probe_sentence(probe))
    print(
        f"done in {time.perf_counter() - t_start:.0f} s: {sum(r['ok'] for r in rows)} measured, "
        f"{sum(not r['ok'] for r in rows)} failed, {len(skipped)} skipped; "
        f"see {args.out}/results.md"
    )
    return 130 if interrupted else 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of `python -m benchmarks`; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    import benchmarks

    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=benchmarks.__doc__)
    configure(parser)
    args = parser.parse_args(argv)
    args._argv = argv
    return run(args)
