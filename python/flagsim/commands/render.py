"""Render an existing export (made by `flagsim run ... --out DIR`) with POV-Ray, on every core,
and assemble the frames into an animated GIF (or MP4), whose path is printed at the end.
Frames whose images are up to date are kept, so an interrupted render resumes.

On a Dask cluster (--scheduler ADDRESS, or --workers N for a local one; docs/distributed.md)
each frame is a task: POV-Ray must be installed on every worker (not here), and a worker that
does not see DIR gets the files POV-Ray reads with the task and returns the picture.

examples:
  flagsim render out/demo --width 1280 --height 960
  flagsim render /shared/out/demo --scheduler tcp://scheduler:8786
"""

from __future__ import annotations

from ._common import (
    add_animation_options,
    add_cluster_options,
    check_animation_tools,
    local_jobs,
    render_and_assemble,
)


def configure(p):
    p.add_argument("dir", metavar="DIR", help="the export folder (holds export.json, flag.pov)")
    p.add_argument("--width", type=int, metavar="W", help="picture width (default: the export's)")
    p.add_argument("--height", type=int, metavar="H", help="picture height (default: the export's)")
    p.add_argument("--force", action="store_true", help="render every frame again")
    add_animation_options(p)
    add_cluster_options(p)


def run(args):
    from ..povray import load_export

    load_export(args.dir)  # a clear error for a folder that is not a complete export
    if args.jobs is not None:
        local_jobs(args)  # refused beside --scheduler / --workers
    check_animation_tools(args)
    print(
        render_and_assemble(args.dir, args, width=args.width, height=args.height, force=args.force)
    )
    return 0
