"""Export a running simulation as a POV-Ray animation: one mesh2 include per frame.

Frames are taken at a frame rate independent of the time step: frame k is the state after
round(k / (fps * dt)) steps (within dt / 2 of t = k / fps). Every file is written whole or not at
all, so an interrupted export leaves only complete frames; running the same export again re-runs
the (deterministic) simulation and keeps every frame file that already holds the same text.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from . import scenefiles
from .lock import LOCK_NAME, ExportLock
from .mesh import format_mesh2, mesh_arrays

MANIFEST = "export.json"
MANIFEST_FORMAT = 1
MAX_FRAMES = 100_000  # frame files are numbered with 5 digits
MAX_STEPS = 10**9  # ~2 days of the paper scene at 5,000 steps/s: a typo, not a shot


class ExportConflict(ValueError):
    """The output folder holds an export made with other settings."""


@dataclass
class ExportResult:
    out_dir: Path
    frames: int  # frame files in the export
    written: int  # written by this call
    kept: int  # already there with the same content (resumed)
    steps: int  # simulation steps taken
    wall_seconds: float


def frame_steps(seconds, fps, dt):
    """Step index of each frame: k = 0 .. floor(seconds * fps), frame k at round(k / (fps*dt))."""
    if not (math.isfinite(seconds) and seconds >= 0):
        raise ValueError(f"seconds should be finite and >= 0, got {seconds}")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps should be finite and > 0, got {fps}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt should be finite and > 0, got {dt}")
    if fps * dt > 1.0 + 1e-9:
        raise ValueError(
            f"fps should be <= 1 / dt = {1.0 / dt:g} (one frame per step at most), got {fps}"
        )
    if not seconds / dt <= MAX_STEPS:
        raise ValueError(
            f"seconds / dt should be at most {MAX_STEPS:.0e} steps, got "
            f"{seconds / dt:.3g} (seconds = {seconds:g}, dt = {dt:g})"
        )
    frames = seconds * fps
    if not frames < MAX_FRAMES:  # also an overflow to inf
        raise ValueError(f"seconds * fps should be < {MAX_FRAMES} frames, got {frames:g}")
    n = int(math.floor(frames + 1e-9)) + 1
    if n > MAX_FRAMES:
        raise ValueError(f"seconds * fps should be < {MAX_FRAMES} frames, got {n}")
    return [int(round(k / (fps * dt))) for k in range(n)]


def _area_normal(positions, triangles):
    """Sum over triangles of (area x unit normal), oriented by the winding."""
    t = np.asarray(triangles)
    x = positions
    return 0.5 * np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]).sum(axis=0)


def read_manifest(out_dir):
    """The folder's export.json as a dict, or None when there is none; ExportConflict naming
    the problem when it is not a manifest flagsim can read."""
    path = Path(out_dir) / MANIFEST
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as e:
        raise ExportConflict(f"{path} is not a flagsim export manifest ({e})") from None
    except RecursionError:
        raise ExportConflict(
            f"{path} is not a flagsim export manifest (nested too deeply)"
        ) from None
    if not isinstance(manifest, dict) or "key" not in manifest:
        raise ExportConflict(
            f"{path} is not a flagsim export manifest (expected an object with "
            f"a 'key', got {type(manifest).__name__})"
        )
    return manifest


def _foreign_entries(out):
    """What a folder without a manifest holds besides flagsim's lock and the temporary file of a
    manifest write that was interrupted: anything there is the user's."""
    return sorted(
        p.name
        for p in out.iterdir()
        if not p.name.startswith(LOCK_NAME)
        and not (p.name.startswith(f".{MANIFEST}.") and p.name.endswith(".tmp"))
    )


def _prepare_folder(out, key, overwrite):
    """Check that flagsim may write into `out` (held under its lock) and return the manifest of
    the export there to resume, or None. flagsim writes only into a new or empty folder or one
    of its own exports; with overwrite it replaces an export of other settings, or one whose
    manifest it cannot read, deleting only the files it names itself."""
    try:
        old = read_manifest(out)
    except ExportConflict:
        if not overwrite:
            raise
        old = {"key": None}  # a damaged export of its own: replaced below
    if old is None:
        foreign = _foreign_entries(out)
        if foreign:
            shown = ", ".join(foreign[:5]) + (", ..." if len(foreign) > 5 else "")
            raise ExportConflict(
                f"{out} is not empty ({shown}) and holds no flagsim export "
                f"({MANIFEST}); flagsim writes only into a new or empty folder "
                f"or one of its own exports, so choose another output folder"
            )
        return None
    if old.get("key") != key:
        if not overwrite:
            raise ExportConflict(
                f"{out} holds an export of another scene or other settings; "
                f"choose another output folder or overwrite it"
            )
        _clear(out)
        return None
    return old


def _remove_stale(out, old_frames, frames):
    """Temporary files of an interrupted run; when the frame count changed, frames past the new
    last one and every image (POV-Ray's image names depend on the count)."""
    for folder in (out, out / scenefiles.FRAME_DIR, out / scenefiles.RENDER_DIR):
        if folder.is_dir():
            for pattern in (".*.tmp", ".*.tmp.png"):
                for p in folder.glob(pattern):
                    p.unlink(missing_ok=True)
    if old_frames != frames:
        for p in (out / scenefiles.FRAME_DIR).glob("flag_*.inc"):
            if int(p.stem.split("_")[1]) >= frames:
                p.unlink()
        for p in (out / scenefiles.RENDER_DIR).glob("frame_*.png"):
            p.unlink()


def _clear(out):
    """The frames and pictures of the export being replaced (only files flagsim names)."""
    for sub, pattern in (
        (scenefiles.FRAME_DIR, "flag_*.inc"),
        (scenefiles.RENDER_DIR, "frame_*.png"),
    ):
        for p in (out / sub).glob(pattern):
            p.unlink()


def export(
    sim,
    out_dir,
    *,
    seconds,
    fps=25.0,
    dt=None,
    scene=None,
    width=640,
    height=480,
    texture=None,
    key=None,
    overwrite=False,
    progress=True,
    povray_binary=None,
    on_frame=None,
):
    """Simulate ``seconds`` of ``sim`` and write a POV-Ray animation into ``out_dir``.

    sim        a flagsim.Simulation (or anything with step(n), step_count, time and the mesh
               arrays of write_mesh2); frames are counted from its current step
    dt         time step, s; default scene.dt, else sim.dt
    scene      supplies dt and the pole (scene.pole.radius/height/base) for the master scene;
               default sim.scene
    width, height  picture size written into flag.ini (flagsim render can override it)
    texture    image file mapped onto the flag (uv), or None for the built-in red-and-white flag
    key        JSON-able description of what determines the frames (scene, fps, dt): a folder
               holding an export with another key raises ExportConflict unless overwrite
    progress   tqdm bar on stderr with simulated time, steps per second and ETA
    on_frame   called as on_frame(sim) after each frame is taken (another exporter, e.g.
               flagsim.usd.Recorder.add_frame, records the same frames)

    Writes flag.pov, flag.ini, frames/flag_NNNNN.inc, export.json (and render/, .povray/).
    An interrupted call can be repeated: frames already written identically are kept.
    """
    if scene is None:
        scene = getattr(sim, "scene", None)  # a flagsim.Simulation knows its scene
    if dt is None:
        dt = scene.dt if scene is not None else sim.dt
    dt = float(dt)
    steps = frame_steps(float(seconds), float(fps), dt)
    width, height = int(width), int(height)
    for name, v in (("width", width), ("height", height)):
        if not 16 <= v <= 8192:
            raise ValueError(f"{name} should be in [16, 8192] pixels, got {v}")
    scenefiles.check_texture(texture)
    pole = scenefiles.scene_pole(scene)

    out = output_folder(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    key = {"fps": float(fps), "dt": dt} if key is None else key
    if not (out / MANIFEST).exists() and not (out / LOCK_NAME).exists():
        _prepare_folder(out, key, overwrite)  # a user's folder is refused before any lock file
    with ExportLock(out):
        old = _prepare_folder(out, key, overwrite)
        old_frames = old.get("frames", 0) if old is not None else 0
        if not isinstance(old_frames, int) or isinstance(old_frames, bool) or old_frames < 0:
            old_frames = 0  # a damaged count: every stale frame and picture goes
        _remove_stale(out, old_frames, len(steps))
        return _export_frames(
            sim,
            out,
            steps,
            dt,
            key,
            pole,
            width,
            height,
            texture,
            progress,
            povray_binary,
            fps,
            on_frame,
            scenefiles.solids_text(scene),
        )


def output_folder(out_dir) -> Path:
    """`out_dir` as a Path, or ValueError: an empty path (an unset $OUT) does not mean the current
    folder, and a file is not a folder."""
    if out_dir is None or not str(out_dir).strip():
        raise ValueError(f"out should be a folder path, got {str(out_dir)!r}")
    out = Path(out_dir).expanduser()
    if out.exists() and not out.is_dir():
        raise ValueError(f"out should be a folder, got a file: {out}")
    return out


def _export_frames(
    sim,
    out,
    steps,
    dt,
    key,
    pole,
    width,
    height,
    texture,
    progress,
    povray_binary,
    fps,
    on_frame,
    solids="",
):
    manifest = {
        "format": MANIFEST_FORMAT,
        "flagsim": __version__,
        "key": key,
        "fps": float(fps),
        "dt": dt,
        "frames": len(steps),
        "complete": False,
        "width": width,
        "height": height,
        "times": [s * dt for s in steps],
    }
    # The manifest first: from then on the folder is recognisably an export.
    scenefiles.write_text(out / MANIFEST, json.dumps(manifest, indent=1) + "\n")
    (out / scenefiles.FRAME_DIR).mkdir(exist_ok=True)
    (out / scenefiles.RENDER_DIR).mkdir(exist_ok=True)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            total=round(steps[-1] * dt, 6),
            unit="s",
            desc="simulating",
            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:.2f} s simulated "
            "[{elapsed}<{remaining}{postfix}]",
        )
    start_step = sim.step_count
    written = kept = 0
    facing = np.zeros(3)  # area-weighted normal summed over the frames: where the flag faces
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    t0 = time.perf_counter()
    step_time = 0.0
    try:
        for k, target in enumerate(steps):
            n = start_step + target - sim.step_count
            if n > 0:
                ts = time.perf_counter()
                sim.step(n)
                step_time += time.perf_counter() - ts
            positions, _, _, triangles = mesh_arrays(sim)
            positions = np.asarray(positions)
            lo = np.minimum(lo, positions.min(axis=0))
            hi = np.maximum(hi, positions.max(axis=0))
            facing += _area_normal(positions, triangles)
            path = out / scenefiles.frame_file(k)
            text = format_mesh2(sim, comment=f"flagsim frame {k}, t = {target * dt:.6f} s")
            if scenefiles.write_text(path, text):
                written += 1
            else:
                kept += 1
            if on_frame is not None:
                on_frame(sim)
            if bar is not None:
                bar.n = round(target * dt, 6)
                done = sim.step_count - start_step
                if step_time > 0:
                    bar.set_postfix_str(f"{done / step_time:,.0f} steps/s", refresh=False)
                bar.refresh()
    finally:
        if bar is not None:
            bar.close()

    view = scenefiles.frame_view(lo, hi, pole, facing=facing, aspect=width / height)
    scenefiles.write_static_files(
        out,
        view=view,
        pole=pole,
        texture=texture,
        width=width,
        height=height,
        final_frame=len(steps) - 1,
        final_clock=steps[-1] * dt,
        povray_binary=povray_binary,
        solids=solids,
    )
    manifest["complete"] = True
    manifest["texture"] = None if texture is None else Path(texture).name
    manifest["bounds"] = [lo.tolist(), hi.tolist()]
    scenefiles.write_text(out / MANIFEST, json.dumps(manifest, indent=1) + "\n")
    return ExportResult(
        out_dir=out,
        frames=len(steps),
        written=written,
        kept=kept,
        steps=sim.step_count - start_step,
        wall_seconds=time.perf_counter() - t0,
    )
