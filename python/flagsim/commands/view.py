"""Watch a scene in a live window (polyscope, `pip install 'flagsim[viewer]'`): the flag with
its texture, the pole and, on request, a slice of the air. The panel plays, pauses, steps and
resets, sets the wind, the flapping mode and the integrator, and shows steps/s, simulated/wall
time (real time = 1.0; it says when the simulation falls behind), the stage split and the
energy. The simulation runs as fast as real time allows.

With --screenshot, no window opens: FRAMES frames are drawn off-screen (EGL, no display needed),
one per 1/FPS simulated seconds, and the last is written as a PNG (docs/viewer.md).

keyboard shortcuts (live window):
{keys}
  mouse: left drag turns the camera, right drag (or shift + left) moves it, the wheel zooms

examples:
  flagsim view paper
  flagsim view my_scene.toml --texture flag.png --air
  flagsim view paper --screenshot docs/images/viewer.png --frames 75
"""

from __future__ import annotations

import sys

from ..viewer.controls import KEYS
from ._common import add_scene_argument, load_scene

__doc__ = __doc__.format(keys="\n".join(f"  {key:<6} {what}" for key, what, _, _ in KEYS))


def configure(p):
    add_scene_argument(p)
    p.add_argument(
        "--screenshot",
        metavar="PNG",
        help="draw off-screen (no window, no display needed) and write the last frame here",
    )
    p.add_argument(
        "--frames",
        type=int,
        metavar="N",
        help="frames to draw before the screenshot (default 50: 2 s at 25 frames/s)",
    )
    p.add_argument(
        "--fps",
        type=float,
        metavar="F",
        help="screenshot frames per simulated second (default 25)",
    )
    p.add_argument("--width", type=int, metavar="W", help="pixels (default 1280, screenshot 960)")
    p.add_argument("--height", type=int, metavar="H", help="pixels (default 720, screenshot 540)")
    p.add_argument(
        "--texture",
        metavar="IMAGE",
        help="image mapped onto the flag (uv); default: the built-in red flag with a white cross",
    )
    p.add_argument("--air", action="store_true", help="start with the air slice shown")
    p.add_argument("--no-panel", action="store_true", help="screenshot without the control panel")
    p.add_argument(
        "--quiet", "-q", action="store_true", help="no progress bar; print only the PNG's path"
    )


def run(args):
    import flagsim
    from flagsim import viewer

    from ..cli import CommandError
    from ..povray import scenefiles

    scenefiles.check_texture(args.texture)
    if args.screenshot is None:
        given = {"--no-panel": args.no_panel, "--frames": args.frames is not None}
        given["--fps"] = args.fps is not None
        for option in (k for k, v in given.items() if v):
            raise ValueError(f"{option} applies to --screenshot only")
        viewer.check_size(args.width or 1280, args.height or 720)
        scene, _ = load_scene(args.scene)
        ctrl = viewer.Controller(flagsim.Simulation(scene))
        ctrl.show_air = args.air
        try:
            viewer.show(
                ctrl, texture=args.texture, width=args.width or 1280, height=args.height or 720
            )
        except viewer.ViewerUnavailable as e:
            raise CommandError(str(e)) from None
        return 0
    path = viewer.check_png_path(args.screenshot)
    args.frames = 50 if args.frames is None else args.frames
    args.fps = 25.0 if args.fps is None else args.fps
    if args.frames < 1:
        raise ValueError(f"--frames should be >= 1, got {args.frames}")
    viewer.check_size(args.width or 960, args.height or 540, panel=not args.no_panel)
    scene, _ = load_scene(args.scene)
    try:
        result = viewer.screenshot(
            flagsim.Simulation(scene),
            path,
            frames=args.frames,
            fps=args.fps,
            width=args.width or 960,
            height=args.height or 540,
            texture=args.texture,
            panel=not args.no_panel,
            air=args.air,
            progress=not args.quiet,
        )
    except viewer.ViewerUnavailable as e:
        raise CommandError(str(e)) from None
    if not args.quiet:
        print(
            f"drew {result.frames} frames in {result.wall_seconds:.1f} s: "
            f"{result.frames_per_second:.1f} frames/s, simulated / wall time "
            f"{result.realtime_ratio:.2f} (real time = 1.0); stepping alone "
            f"{result.steps_per_second:,.0f} steps/s",
            file=sys.stderr,
        )
    print(result.path)
    return 0
