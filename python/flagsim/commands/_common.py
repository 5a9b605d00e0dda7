"""Helpers shared by the sub-commands: scene lookup, animation and cluster options."""

from __future__ import annotations

import hashlib
from pathlib import Path


class UnknownScene(ValueError):
    pass


def add_scene_argument(parser):
    """The SCENE positional every scene command takes (load it with load_scene)."""
    parser.add_argument(
        "scene",
        metavar="SCENE",
        help="a built-in scene name ('flagsim scenes' lists them) or a TOML scene file",
    )


def load_scene(spec):
    """(scene, description) for SCENE: a TOML file, a built-in or a gallery scene name.

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
    elif spec in flagsim.Scene.gallery():
        from flagsim.scene import gallery_path

        scene = flagsim.Scene.load(gallery_path(spec))
        source = {
            "gallery": spec,
            "sha256": hashlib.sha256(Path(gallery_path(spec)).read_bytes()).hexdigest(),
        }
    else:
        known = flagsim.Scene.builtins()
        if spec not in known:
            raise UnknownScene(
                f"unknown scene '{spec}': the built-in scenes are "
                f"{', '.join(sorted(known))}, the gallery scenes "
                f"{', '.join(sorted(flagsim.Scene.gallery()))} (or give a .toml scene file)"
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


def add_cluster_options(parser):
    """--scheduler and --workers: run the command's tasks on a Dask cluster (docs/distributed.md;
    needs the optional extra: pip install 'flagsim[distributed]')."""
    group = parser.add_argument_group(
        "cluster", "run the tasks on a Dask cluster (docs/distributed.md; needs Dask distributed)"
    )
    group.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler (tcp://host:8786); its workers run the tasks, and see "
        "the output folder if it is shared (else they return their files to this process)",
    )
    group.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="start a local Dask cluster of N worker processes (one thread each) for this run",
    )


def cluster_executor(args):
    """Context manager yielding the Dask executor that --scheduler / --workers ask for, or None
    (the command's local process pool)."""
    from .._pool import cluster

    return cluster(
        scheduler=getattr(args, "scheduler", None), workers=getattr(args, "workers", None)
    )


def local_jobs(args):
    """--jobs (the local pool's size; default 1), refused beside --scheduler / --workers."""
    if args.jobs is not None and (args.scheduler is not None or args.workers is not None):
        raise ValueError(
            "--jobs should not be given with --scheduler or --workers: it sizes the local "
            "process pool, and the cluster's workers run the tasks"
        )
    jobs = 1 if args.jobs is None else args.jobs
    if jobs < 1:
        raise ValueError(f"--jobs should be >= 1, got {jobs}")
    return jobs


def check_animation_tools(args):
    """Fail before any work if the requested output cannot be made."""
    import shutil

    from ..povray import FfmpegNotFound, find_povray

    if getattr(args, "scheduler", None) is None and getattr(args, "workers", None) is None:
        find_povray()  # on a cluster the workers render: each finds its own
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
    with cluster_executor(args) as executor:
        result = povray.render(
            out_dir,
            width=width,
            height=height,
            jobs=args.jobs,
            executor=executor,
            progress=not quiet,
            force=force,
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
