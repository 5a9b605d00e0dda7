"""Helpers shared by the sub-commands: scene lookup, animation options."""

from __future__ import annotations

import hashlib
from pathlib import Path


class UnknownScene(ValueError):
    pass


def load_scene(spec):
    """(scene, description) for SCENE: a TOML file, or a built-in scene name.

    The description (JSON-able) identifies what the frames depend on, for the export's resume
    check: the source and every scene field (flagsim.scene.to_dict).
    """
    import flagsim

    path = Path(spec)
    if spec.endswith(".toml") or path.is_file():
        if not path.is_file():
            raise FileNotFoundError(f"scene file '{spec}' not found")
        # Scene.load's own ValueError (e.g. an unknown key, named with its section) passes on.
        scene = flagsim.Scene.load(str(path))
        source = {
            "file": str(path.resolve()),
            "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        }
    else:
        known = flagsim.Scene.builtins()
        if spec not in known:
            raise UnknownScene(
                f"unknown scene '{spec}': the built-in scenes are "
                f"{', '.join(sorted(known))} (or give a .toml scene file)"
            )
        scene = flagsim.Scene.named(spec)
        source = {"builtin": spec}
    from flagsim.scene import to_dict

    return scene, {"source": source, "scene": to_dict(scene), "flagsim": flagsim.__version__}


def add_animation_options(parser):
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--gif",
        action="store_true",
        help="assemble the frames into an animated GIF, DIR/flag.gif (default)",
    )
    group.add_argument(
        "--mp4",
        action="store_true",
        help="assemble the frames into an H.264 MP4, DIR/flag.mp4 (needs ffmpeg)",
    )
    parser.add_argument(
        "--jobs", type=int, metavar="N", help="POV-Ray processes at once (default: three per core)"
    )
    parser.add_argument(
        "--quiet", "-q", action="store_true", help="no progress bars; print only the resulting path"
    )


def check_animation_tools(args):
    """Fail before any work if the requested output cannot be made."""
    import shutil

    from ..povray import FfmpegNotFound, find_povray

    find_povray()
    if args.mp4 and shutil.which("ffmpeg") is None:
        raise FfmpegNotFound(
            "--mp4 needs ffmpeg, which is not installed: install the Debian "
            "package 'ffmpeg' (sudo apt-get install ffmpeg), or use --gif"
        )
    if args.jobs is not None and args.jobs < 1:
        raise ValueError(f"--jobs should be >= 1, got {args.jobs}")


def render_and_assemble(out_dir, args, *, width=None, height=None, force=False):
    """Render the export and assemble the animation; returns the animation's path."""
    import sys

    from .. import povray

    quiet = args.quiet
    result = povray.render(
        out_dir, width=width, height=height, jobs=args.jobs, progress=not quiet, force=force
    )
    for frame, lines in sorted(result.diagnostics.items()):
        print(f"flagsim: POV-Ray said for frame {frame}: " + " | ".join(lines), file=sys.stderr)
    manifest = povray.read_manifest(out_dir)
    fps = manifest["fps"]
    if args.mp4:
        path = povray.make_mp4(out_dir, Path(out_dir) / "flag.mp4", fps, manifest["frames"] - 1)
    else:
        path = povray.make_gif(result.images, Path(out_dir) / "flag.gif", fps)
    if not quiet:
        print(
            f"rendered {len(result.rendered)} frames ({len(result.skipped)} up to date) in "
            f"{result.wall_seconds:.1f} s",
            file=sys.stderr,
        )
    return path
