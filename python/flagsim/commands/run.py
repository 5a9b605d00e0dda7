"""Simulate a scene and export it as a POV-Ray animation into DIR: one mesh2 file per frame
(frames/), the master scene (flag.pov) and flag.ini (`povray flag.ini` renders every frame).
With --render, POV-Ray renders the frames on every core and they are assembled into an animated
GIF (or MP4); its path is printed at the end.

With --usd FILE (`pip install 'flagsim[usd]'`), the same frames also go into one USD file for
Blender, Houdini and other USD readers: the flag as a mesh with time-sampled points and
normals, its uv, and the pole (docs/usd.md). --usd alone needs no --out.

Running the same command again resumes an interrupted run: frames already exported or rendered
are kept. DIR must be new, empty, or a flagsim export; flagsim never deletes or overwrites a file
it did not create, and refuses a second process writing into DIR at the same time
(docs/rendering.md).

examples:
  flagsim run paper --seconds 4 --fps 25 --out out/demo --render --gif
  flagsim run my_scene.toml --out out/mine --render --width 800 --height 600 --texture flag.png
  flagsim run paper --seconds 4 --fps 25 --usd out/flag.usdc
"""

from __future__ import annotations

import sys
from pathlib import Path

from ._common import (
    add_animation_options,
    add_scene_argument,
    check_animation_tools,
    load_scene,
    render_and_assemble,
)


def configure(p):
    add_scene_argument(p)
    p.add_argument(
        "--out", "-o", metavar="DIR", help="output folder of the POV-Ray export (or use --usd)"
    )
    p.add_argument(
        "--usd",
        metavar="FILE",
        help="also (or only) write the frames as USD: a .usdc (binary), .usda (text) or .usd file",
    )
    p.add_argument(
        "--seconds", type=float, default=4.0, metavar="S", help="simulated time, s (default 4)"
    )
    p.add_argument(
        "--fps",
        type=float,
        default=25.0,
        metavar="F",
        help="frames per simulated second, independent of the time step (default 25)",
    )
    p.add_argument(
        "--render",
        action="store_true",
        help="render the frames with POV-Ray and assemble an animation",
    )
    p.add_argument(
        "--width", type=int, default=480, metavar="W", help="picture width, pixels " "(default 480)"
    )
    p.add_argument(
        "--height", type=int, default=360, metavar="H", help="picture height, pixels (default 360)"
    )
    p.add_argument(
        "--texture",
        metavar="IMAGE",
        help="image (png, jpeg, gif, tga, ppm, tiff, ...) mapped onto the flag; "
        "default: a built-in red flag with a white cross",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a flagsim export of another scene or other settings (or with a "
        "damaged export.json) in DIR; other files in DIR are kept",
    )
    add_animation_options(p)


def run(args):
    import flagsim

    from .. import povray
    from ..cli import CommandError
    from ..povray import scenefiles

    render = args.render or args.gif or args.mp4
    if args.out is None and args.usd is None:
        raise ValueError("give --out DIR (POV-Ray export), --usd FILE, or both")
    if args.out is None and render:
        raise ValueError("--render needs --out DIR: POV-Ray renders the export there")
    scenefiles.check_texture(args.texture)
    scene, description = load_scene(args.scene)
    recorder = None
    if args.usd is not None:
        from .. import usd

        usd.check_path(args.usd)
        try:
            usd.require()
        except usd.UsdUnavailable as e:
            raise CommandError(str(e)) from None
    if render:
        check_animation_tools(args)
    sim = flagsim.Simulation(scene)
    if args.out is None:
        result = usd.write(
            sim, args.usd, seconds=args.seconds, fps=args.fps, scene=scene, progress=not args.quiet
        )
        if not args.quiet:
            print(
                f"wrote {result.frames} frames to {result.path} ({result.bytes / 1e3:,.0f} kB; "
                f"{result.steps} steps in {result.wall_seconds:.1f} s)",
                file=sys.stderr,
            )
        print(result.path)
        return 0
    if args.usd is not None:
        recorder = usd.Recorder(sim, fps=args.fps, scene=scene)
    key = {"scene": description, "fps": float(args.fps), "dt": float(scene.dt)}
    result = povray.export(
        sim,
        args.out,
        seconds=args.seconds,
        fps=args.fps,
        scene=scene,
        width=args.width,
        height=args.height,
        texture=args.texture,
        key=key,
        overwrite=args.overwrite,
        progress=not args.quiet,
        on_frame=None if recorder is None else recorder.add_frame,
    )
    out = Path(args.out)
    if not args.quiet:
        print(
            f"exported {result.frames} frames to {out} ({result.written} written, "
            f"{result.kept} kept; {result.steps} steps in {result.wall_seconds:.1f} s)",
            file=sys.stderr,
        )
    if recorder is not None:
        size = recorder.save(args.usd)
        if not args.quiet:
            print(
                f"wrote {recorder.frames} frames to {args.usd} ({size / 1e3:,.0f} kB)",
                file=sys.stderr,
            )
    if not render:
        if not args.quiet:
            print(f"render it with:  flagsim render {out}", file=sys.stderr)
        print(out)
        return 0
    print(render_and_assemble(out, args))
    return 0
