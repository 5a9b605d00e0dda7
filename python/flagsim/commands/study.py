"""Run a study and write its CSV, markdown report (and plots) to --out.

  accuracy   error against run time: spring-mass pair, banner angle, flag trajectory, Taylor-Green
             vortex, the coupled paper scene, plane Poiseuille flow and the cylinder at Re = 100
             (St and C_D against published values), with observed convergence orders, the
             Pareto front, and the cheapest setting per error target
  flutter    the paper's flag at 0 and 2..20 m/s, per model (one-way + eq. 5, one-way +
             turbulence, two-way + turbulence + the pole's wake when built) and drag model
             (paper, triangle): flapping frequency, amplitude, Strouhal number, the bending
             wave's length and speed, the force coefficient on the pole against EN 1991-1-4's
             free flag, the droop angle, and the cost per simulated second (docs/flutter.md)
  stability  a matrix over stiffness, wind, dt, areal density, flapping mode and integrator
             plus pathological cases; every case ends plausible (finite, energy ledger balanced,
             strain within the scene's promise), diverged (reported), implausible or non-finite
             (the last two must never happen: the command then exits 1)

Cases run through a process pool (--jobs N) or on a Dask cluster (--scheduler ADDRESS, or
--workers N for a local one; docs/distributed.md), and an interrupted study resumes from its CSV.
DIR/tasks.csv says where each case ran, how many attempts it took and how long. Timings are most
meaningful with --jobs 1 on a quiet machine.

examples:
  flagsim study stability --out out/stability --jobs 2
  flagsim study stability --out out/stability --scheduler tcp://scheduler:8786
  flagsim study accuracy --out out/accuracy --docs docs/reports   # docs/reports/accuracy.md
  flagsim study flutter --out out/flutter --jobs 2 --docs docs/reports
  flagsim study flutter --out out/flutter-quick --quick             # seconds
"""

from __future__ import annotations

import os

from ._common import add_cluster_options, cluster_executor, local_jobs


def configure(p):
    p.add_argument("study", choices=("accuracy", "flutter", "stability"), help="which study to run")
    p.add_argument(
        "--out", required=True, metavar="DIR", help="directory for CSV, report and plots"
    )
    p.add_argument(
        "--jobs",
        type=int,
        metavar="N",
        help="local worker processes (default 1: timings undisturbed); not with --scheduler "
        "or --workers",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="a reduced sweep / matrix (minutes instead of tens of minutes; flutter: seconds)",
    )
    p.add_argument(
        "--docs",
        metavar="DIR",
        help="also write the report (and plots) into DIR as accuracy.md / flutter.md / "
        "stability.md (plots in DIR/images)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_cluster_options(p)


def run(args):
    from .. import study

    jobs = local_jobs(args)  # a ValueError: the CLI's one error funnel prints it and exits 2
    report = os.path.join(args.docs, f"{args.study}.md") if args.docs else None
    with cluster_executor(args) as executor:
        return _run(args, study, report, jobs, executor)


def _run(args, study, report, jobs, executor):
    common = dict(jobs=jobs, executor=executor, progress=not args.quiet, report_path=report)
    plot_dir = os.path.join(args.docs, "images") if args.docs else None
    if args.study == "stability":
        rows = study.run_stability(args.out, reduced=args.quick, **common)
        from ..study.stability import headline, summarize

        for (integ,), c in summarize(rows).items():
            print(f"{integ:>18}: " + ", ".join(f"{n} {o}" for o, n in c.items()))
        print(headline(rows))
        total = summarize(rows, by=())[()]
        silent = total["implausible"] + total["nonfinite"]
    elif args.study == "flutter":
        rows = study.run_flutter(args.out, quick=args.quick, plot_dir=plot_dir, **common)
        from ..study.flutter import headline

        print(headline(rows))
        silent = 0
    else:
        study.run_accuracy(args.out, quick=args.quick, plot_dir=plot_dir, **common)
        silent = 0
    print(f"report: {report or os.path.join(args.out, args.study + '.md')}")
    return 1 if silent else 0
