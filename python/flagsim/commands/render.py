"""Render an existing export (made by `flagsim run ... --out DIR`) with POV-Ray, on every core,
and assemble the frames into an animated GIF (or MP4), whose path is printed at the end.
Frames whose images are up to date are kept, so an interrupted render resumes.
"""

from __future__ import annotations

from ._common import add_animation_options, check_animation_tools, render_and_assemble


def configure(p):
    p.add_argument("dir", metavar="DIR", help="the export folder (holds export.json, flag.pov)")
    p.add_argument("--width", type=int, metavar="W", help="picture width (default: the export's)")
    p.add_argument("--height", type=int, metavar="H", help="picture height (default: the export's)")
    p.add_argument("--force", action="store_true", help="render every frame again")
    add_animation_options(p)


def run(args):
    from ..povray import load_export

    load_export(args.dir)  # a clear error for a folder that is not a complete export
    check_animation_tools(args)
    print(
        render_and_assemble(args.dir, args, width=args.width, height=args.height, force=args.force)
    )
    return 0
