"""Run a scene under every combination of some settings: each combination is one task that
simulates, exports for POV-Ray and (--render) renders, written into DIR/NAME with NAME made of
its settings, e.g. DIR/air.wind=8_0_1,flag.stretch_stiffness=100 (lists of numbers joined by
"_"; a name with other characters, or longer than 80, ends in a hash). DIR/sweep.csv is the
index: each combination's settings, frames, the work done, where it ran, the attempts it took
and how long. Tasks run here (--jobs 1), in local processes (--jobs N), or on a Dask cluster
(--scheduler ADDRESS, or --workers N for a local one; docs/distributed.md). Running the same
command again resumes: finished combinations are kept.

KEY is a scene field as a TOML scene file names it (air.wind, flag.rows, integrator.method,
dt); each value is a TOML value (5, 0.01, [8, 0, 1], true; a bare word is a string), commas
inside [ ] do not separate values.

examples:
  flagsim sweep paper --vary 'air.wind=[2,0,0],[8,0,1]' --vary flag.stretch_stiffness=100,1000 \\
      --seconds 2 --out out/sweep --render --workers 2
  flagsim sweep my_scene.toml --vary integrator.method=implicit,explicit --out out/methods \\
      --scheduler tcp://scheduler:8786
"""

from __future__ import annotations

import sys

from ._common import (
    add_cluster_options,
    add_scene_argument,
    cluster_executor,
    load_scene,
    local_jobs,
)


def configure(p):
    add_scene_argument(p)
    p.add_argument(
        "--vary",
        action="append",
        required=True,
        metavar="KEY=V1,V2,...",
        help="a scene field and its values (repeat for more fields: every combination runs)",
    )
    p.add_argument("--out", "-o", required=True, metavar="DIR", help="output folder")
    p.add_argument(
        "--seconds", type=float, default=4.0, metavar="S", help="simulated time, s (default 4)"
    )
    p.add_argument(
        "--fps", type=float, default=25.0, metavar="F", help="frames per second (default 25)"
    )
    p.add_argument(
        "--render",
        action="store_true",
        help="render each combination with POV-Ray (on the worker) into NAME/flag.gif",
    )
    p.add_argument("--width", type=int, default=480, metavar="W", help="picture width (480)")
    p.add_argument("--height", type=int, default=360, metavar="H", help="picture height (360)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="redo a sweep of other settings in DIR (other files in DIR are kept)",
    )
    p.add_argument(
        "--jobs",
        type=int,
        metavar="N",
        help="local worker processes (default 1: here); not with --scheduler or --workers",
    )
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        metavar="N",
        help="flagsim threads per task (default 1; the same everywhere, so the same bytes)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    add_cluster_options(p)


def run(args):
    from ..sweep import parse_vary, run_sweep

    vary = {}
    for spec in args.vary:
        key, values = parse_vary(spec)
        if key in vary:
            raise ValueError(f"--vary {key} is given twice: give its values once, comma-separated")
        vary[key] = values
    jobs = local_jobs(args)
    scene, description = load_scene(args.scene)
    if args.render:
        check_povray_here(args)
    with cluster_executor(args) as executor:
        rows = run_sweep(
            scene,
            vary,
            args.out,
            seconds=args.seconds,
            fps=args.fps,
            width=args.width,
            height=args.height,
            render=args.render,
            overwrite=args.overwrite,
            source=description["source"],
            threads=args.threads,
            jobs=jobs,
            executor=executor,
            progress=not args.quiet,
        )
    if not args.quiet:
        work = {}
        for r in rows:
            work[r["work"] or "none"] = work.get(r["work"] or "none", 0) + 1
        done = ", ".join(f"{n} {w}" for w, n in sorted(work.items()))
        print(f"swept {len(rows)} combinations ({done})", file=sys.stderr)
    print(args.out)
    return 0


def check_povray_here(args):
    """Without a cluster the tasks render here: POV-Ray must be installed before any work."""
    if args.scheduler is None and args.workers is None:
        from ..povray import find_povray

        find_povray()
