"""Render an export with POV-Ray, one process per frame, through a concurrent.futures.Executor.

The default executor is a local process pool (three single-threaded POV-Ray runs per core);
anything with the Executor interface (a Dask cluster's, a thread pool) can take its place without
touching this code: a frame is a picklable ``FrameJob`` and ``render_frame`` a module-level
function. A failed frame is retried once, then reported by number in ``RenderError``.

A frame job carries the record of the lock the head holds on the export (``share``): a worker
that reads the same record in the folder sees the head's folder (shared, or the same machine)
and renders into it; one that does not says so, and gets the job again with the files POV-Ray
reads (``inputs``), renders in a folder of its own and returns the image, which the head writes.
Images are reproducible: POV-Ray's time stamp and render-date comment are dropped, so a frame is
the same file whichever worker rendered it, and when.
"""

from __future__ import annotations

import os
import shutil
import socket
import struct
import subprocess
import tempfile
import time
import zlib
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, field, replace
from pathlib import Path

from . import scenefiles
from .export import read_manifest

DEBIAN_PACKAGE = "povray"


class PovrayNotFound(FileNotFoundError):
    """The POV-Ray binary is not installed (or not on PATH)."""


class RenderError(RuntimeError):
    """Some frames failed to render (after a retry); ``frames`` lists their numbers."""

    def __init__(self, message, frames=()):
        super().__init__(message)
        self.frames = list(frames)


class IncompleteExport(ValueError):
    """The folder is not a (complete) flagsim export."""


def find_povray(binary=None):
    """Path of the POV-Ray binary: ``binary``, $FLAGSIM_POVRAY or ``povray`` on PATH."""
    name = binary or os.environ.get("FLAGSIM_POVRAY") or "povray"
    path = shutil.which(name)
    if path is None:
        raise PovrayNotFound(
            f"POV-Ray ('{name}') is not installed or not on PATH: install the Debian package "
            f"'{DEBIAN_PACKAGE}' (sudo apt-get install {DEBIAN_PACKAGE}) or set FLAGSIM_POVRAY "
            f"to the povray binary"
        )
    return path


@dataclass
class FrameJob:
    frame: int
    out_dir: str  # the export folder; POV-Ray runs there with relative paths
    image: str  # relative path of the image to produce
    povray: str
    width: int
    height: int
    threads: int = 1
    antialias: float = 0.3  # POV-Ray +A threshold; 0 turns antialiasing off
    timeout: float = 600.0
    # the head's lock record on out_dir (lock.py): a worker whose out_dir/.flagsim.lock holds it
    # sees the head's folder; None: the worker does (a local pool)
    share: dict | None = None
    # what POV-Ray reads (relative path -> bytes), for a worker that does not see the folder
    inputs: dict | None = None


@dataclass
class FrameResult:
    frame: int
    ok: bool
    error: str = ""
    diagnostics: list = field(default_factory=list)  # POV-Ray warnings and errors, one per line
    seconds: float = 0.0
    image: bytes | None = None  # the PNG, from a worker that does not see the head's folder
    needs_inputs: bool = False  # that worker had no inputs: submit the job again with them


def povray_diagnostics(stderr):
    """Lines of POV-Ray's console output that are not its banner, its section rulers
    ("==== [Parsing...] ===") or "POV-Ray finished": with statistics, render and debug streams
    off (-GS -GR -GD), what is left are warnings and errors."""
    lines = stderr.splitlines()
    out = []
    in_banner = False
    for line in lines:
        s = line.strip()
        if s.startswith("Persistence of Vision(tm) Ray Tracer"):
            in_banner = True
            continue
        if s.startswith("==== [") and s.endswith("="):
            in_banner = False
            continue
        if in_banner or not s or s == "POV-Ray finished":
            continue
        out.append(s)
    return out


def povray_env(out_dir):
    """POV-Ray's environment: HOME is the export, where .povray/3.7 holds its user config and
    ini (see scenefiles.povray_home_files), and no POVINI overrides them."""
    env = dict(os.environ)
    env["HOME"] = str(out_dir)
    env.pop("POVINI", None)
    return env


def povray_command(job):
    cmd = [
        job.povray,
        f"+I{scenefiles.SCENE_FILE}",
        f"+O{job.image}",
        f"+W{job.width}",
        f"+H{job.height}",
        "+FN",
        "-D",
        "-P",
        "-V",
        "-GS",
        "-GR",
        "-GD",
        "+GW",
        "+GF",
        f"+WT{job.threads}",
        f"Declare=FRAME={job.frame}",
    ]
    cmd += [f"+A{job.antialias}"] if job.antialias > 0 else ["-A"]
    return cmd


def _povray_preexec():
    # In a single-threaded pool worker POV-Ray is tied to the worker's life. In the head, or in
    # a threaded worker (Dask's), preexec_fn is unsafe (fork after threads) and is not used:
    # there the process's own exit, or POV-Ray's frame timeout, ends it.
    import multiprocessing
    import threading

    if multiprocessing.parent_process() is None or threading.active_count() > 1:
        return None
    from .._pool import die_with_parent

    return die_with_parent


def render_frame(job):
    """Render one frame into a temporary image, renamed into place only when POV-Ray succeeded
    (so an image in render/ is always whole). Never raises for a POV-Ray failure: returns it.
    A worker that does not see the head's folder renders from ``job.inputs`` in a folder of its
    own and returns the image's bytes (or, without inputs, asks for them)."""
    from .lock import sees_folder

    t0 = time.perf_counter()
    exe = shutil.which(job.povray)
    if exe is None:
        return FrameResult(
            job.frame,
            False,
            f"POV-Ray ('{job.povray}') is not installed on {socket.gethostname()}: install "
            f"the Debian package '{DEBIAN_PACKAGE}' on every worker",
        )
    job = replace(job, povray=exe)
    if job.share is None or sees_folder(job.out_dir, job.share):
        return _render_in(job, Path(job.out_dir), t0)
    if job.inputs is None:
        return FrameResult(job.frame, False, needs_inputs=True)
    with tempfile.TemporaryDirectory(prefix="flagsim-frame-") as tmp:
        here = Path(tmp)
        files = {**scenefiles.povray_home_files(exe), **job.inputs}
        for rel, data in files.items():
            (here / rel).parent.mkdir(parents=True, exist_ok=True)
            (here / rel).write_bytes(data.encode() if isinstance(data, str) else data)
        (here / job.image).parent.mkdir(parents=True, exist_ok=True)
        result = _render_in(replace(job, out_dir=str(here)), here, t0)
        if result.ok:
            result.image = (here / job.image).read_bytes()
        return result


def _render_in(job, out, t0):
    final = out / job.image
    tmp_rel = str(Path(job.image).with_name(f".{Path(job.image).stem}.{os.getpid()}.tmp.png"))
    tmp = out / tmp_rel
    cmd = povray_command(replace(job, image=tmp_rel))
    try:
        proc = subprocess.run(
            cmd,
            cwd=out,
            env=povray_env(out),
            capture_output=True,
            text=True,
            errors="replace",
            timeout=job.timeout,
            check=False,
            preexec_fn=_povray_preexec(),
        )
    except (OSError, subprocess.TimeoutExpired) as e:
        tmp.unlink(missing_ok=True)
        return FrameResult(
            job.frame, False, f"{type(e).__name__}: {e}", seconds=time.perf_counter() - t0
        )
    diagnostics = povray_diagnostics(proc.stderr)
    if proc.returncode != 0 or not tmp.is_file():
        tmp.unlink(missing_ok=True)
        detail = "; ".join(diagnostics[-3:]) or "no output"
        return FrameResult(
            job.frame,
            False,
            f"povray exited with {proc.returncode}: {detail}",
            diagnostics,
            time.perf_counter() - t0,
        )
    try:
        reproducible_png(tmp)
        os.replace(tmp, final)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        return FrameResult(job.frame, False, f"{type(e).__name__}: {e}", diagnostics)
    return FrameResult(job.frame, True, "", diagnostics, time.perf_counter() - t0)


#: PNG chunks that say when and where an image was made, not what it shows: POV-Ray writes its
#: render time (tIME) and a "Render Date ... Platform ..." comment
_UNREPRODUCIBLE = (b"tIME", b"tEXtComment\0", b"iTXtComment\0", b"zTXtComment\0")


def reproducible_png(path):
    """Drop from a PNG file the chunks that record when and where it was rendered, so the same
    frame is the same bytes whoever renders it; other chunks and the pixels are untouched (a
    file that is not a PNG is left as it is)."""
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        return
    out, i = [data[:8]], 8
    while i + 12 <= len(data):
        (n,) = struct.unpack(">I", data[i : i + 4])
        chunk = data[i : i + 12 + n]
        if zlib.crc32(chunk[4:-4]) != struct.unpack(">I", chunk[-4:])[0]:
            return  # damaged: left for the reader to reject
        if not any(chunk[4:].startswith(tag) for tag in _UNREPRODUCIBLE):
            out.append(chunk)
        i += 12 + n
    Path(path).write_bytes(b"".join(out))


def png_size(path):
    """(width, height) from a PNG header, or None if it is not a PNG."""
    with open(path, "rb") as f:
        head = f.read(24)
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    return struct.unpack(">II", head[16:24])


def _up_to_date(image, sources, size):
    """Like make: the image exists, has the wanted size and is newer than what it shows."""
    if not image.is_file() or png_size(image) != size:
        return False
    t = image.stat().st_mtime_ns
    return all(t >= s.stat().st_mtime_ns for s in sources if s.exists())


def load_export(out_dir):
    """The manifest of a complete export in out_dir, or IncompleteExport saying what to do."""
    out = Path(out_dir)
    manifest = read_manifest(out)
    if manifest is None:
        raise IncompleteExport(
            f"{out} is not a flagsim export (no {out / 'export.json'}): make "
            f"one with  flagsim run SCENE --out {out}"
        )
    _check_manifest_fields(out / "export.json", manifest)
    missing = [
        k for k in range(manifest["frames"]) if not (out / scenefiles.frame_file(k)).is_file()
    ]
    if not manifest.get("complete") or missing or not (out / scenefiles.SCENE_FILE).is_file():
        what = f" (frames {_ranges(missing)} missing)" if missing else ""
        raise IncompleteExport(
            f"the export in {out} is incomplete{what}: run the same "
            f"flagsim run command again to resume it"
        )
    return manifest


def _check_manifest_fields(path, manifest):
    """The fields render reads, in their ranges, or ExportConflict naming the field."""
    from .export import MAX_FRAMES, ExportConflict

    def bad(field, expected):
        raise ExportConflict(
            f"{path}: {field} should be {expected}, got "
            f"{manifest.get(field)!r}; run the flagsim run command again with "
            f"--overwrite to replace this export"
        )

    frames = manifest.get("frames")
    if not isinstance(frames, int) or isinstance(frames, bool) or not 1 <= frames <= MAX_FRAMES:
        bad("frames", f"an integer in [1, {MAX_FRAMES}]")
    fps = manifest.get("fps")
    if not isinstance(fps, (int, float)) or isinstance(fps, bool) or not 0 < fps < 1e6:
        bad("fps", "a number in (0, 1e6)")
    for name in ("width", "height"):
        v = manifest.get(name)
        if not isinstance(v, int) or isinstance(v, bool) or not 16 <= v <= 8192:
            bad(name, "an integer in [16, 8192]")


def _ranges(numbers):
    """[1, 2, 3, 7] -> '1-3, 7'."""
    parts = []
    for n in sorted(numbers):
        if parts and n == parts[-1][1] + 1:
            parts[-1][1] = n
        else:
            parts.append([n, n])
    return ", ".join(f"{a}-{b}" if b > a else f"{a}" for a, b in parts)


@dataclass
class RenderResult:
    images: list  # Path of every frame's image, in frame order
    rendered: list  # frame numbers rendered by this call
    skipped: list  # frame numbers already up to date
    diagnostics: dict  # frame -> POV-Ray warning lines (empty when clean)
    wall_seconds: float


def _default_executor(jobs):
    from .._pool import worker_pool

    return worker_pool(jobs)  # workers (and their POV-Ray processes) die with this process


def render(
    out_dir,
    *,
    width=None,
    height=None,
    executor=None,
    jobs=None,
    threads=None,
    retries=1,
    antialias=0.3,
    progress=True,
    povray_binary=None,
    worker=render_frame,
    force=False,
):
    """Render every frame of the export in ``out_dir`` to render/frame_NNN.png, holding the
    folder's lock (ExportBusy while another process writes into it); see _render_frames."""
    from .lock import ExportLock

    if not Path(out_dir).is_dir():
        load_export(out_dir)  # the clear error for a folder that is not there
    with ExportLock(out_dir) as lock:
        return _render_frames(
            out_dir,
            width=width,
            height=height,
            executor=executor,
            jobs=jobs,
            threads=threads,
            retries=retries,
            antialias=antialias,
            progress=progress,
            povray_binary=povray_binary,
            worker=worker,
            force=force,
            share=lock.record,
        )


def _render_frames(
    out_dir,
    *,
    width,
    height,
    executor,
    jobs,
    threads,
    retries,
    antialias,
    progress,
    povray_binary,
    worker,
    force,
    share,
):
    """Render every frame of the export in ``out_dir`` to render/frame_NNN.png.

    width, height  default: the export's (export.json)
    executor       a concurrent.futures.Executor running ``worker(FrameJob)``; default a
                   process pool of ``jobs`` workers (default: three per core)
    threads        POV-Ray threads per frame; default the cores shared among the local pool's
                   workers, 1 on a Dask cluster (whose workers' cores this process cannot see)
    retries        a failed frame is submitted again this many times
    force          re-render frames whose images are up to date
    share          the head's lock record on the folder (FrameJob.share)
    Raises PovrayNotFound, IncompleteExport, or RenderError naming the frames that failed
    (after every other frame has been rendered).
    """
    from .. import _pool

    t0 = time.perf_counter()
    out = Path(out_dir).resolve()
    manifest = load_export(out)
    cluster = _pool.is_dask(executor)
    if cluster:  # each worker finds its own POV-Ray; this process need not have one
        povray = povray_binary or os.environ.get("FLAGSIM_POVRAY") or "povray"
        local_povray = shutil.which(povray)
    else:
        povray = local_povray = find_povray(povray_binary)
    width = int(width or manifest["width"])
    height = int(height or manifest["height"])
    for name, v in (("width", width), ("height", height)):
        if not 16 <= v <= 8192:
            raise ValueError(f"{name} should be in [16, 8192] pixels, got {v}")
    if threads is not None and (isinstance(threads, bool) or int(threads) < 1):
        raise ValueError(f"threads should be >= 1, got {threads}")
    # The private POV-Ray config follows the binary actually used (its include folders).
    for name, text in scenefiles.povray_home_files(local_povray).items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        scenefiles.write_text(out / name, text)
    (out / scenefiles.RENDER_DIR).mkdir(exist_ok=True)
    for p in (out / scenefiles.RENDER_DIR).glob(".*.tmp.png"):  # left by an interrupted render
        p.unlink(missing_ok=True)

    n = manifest["frames"]
    final = n - 1
    texture = manifest.get("texture")
    shared = [out / scenefiles.SCENE_FILE]
    if texture:
        shared.append(out / ("texture" + Path(texture).suffix.lower()))
    images = [out / scenefiles.render_file(k, final) for k in range(n)]
    todo = [
        k
        for k in range(n)
        if force
        or not _up_to_date(images[k], shared + [out / scenefiles.frame_file(k)], (width, height))
    ]
    skipped = [k for k in range(n) if k not in set(todo)]
    cores = os.cpu_count() or 1
    # POV-Ray 3.7 idles ~0.6 s per run in its polling loops (strace: 10-100 ms sleeps), longer
    # than a small frame takes to trace: three single-threaded workers per core overlap it.
    workers = max(1, min(jobs or 3 * cores, len(todo) or 1))
    if threads is None:
        threads = 1 if cluster else max(1, cores // workers)
    own_executor = executor is None and bool(todo)
    if own_executor:
        executor = _default_executor(workers)

    def job(k, with_inputs=False):
        inputs = None
        if with_inputs:
            inputs = {str(p.relative_to(out)): p.read_bytes() for p in shared}
            inputs[scenefiles.frame_file(k)] = (out / scenefiles.frame_file(k)).read_bytes()
        return FrameJob(
            frame=k,
            out_dir=str(out),
            image=scenefiles.render_file(k, final),
            povray=povray,
            width=width,
            height=height,
            threads=int(threads),
            antialias=antialias,
            share=share,
            inputs=inputs,
        )

    def key(k):  # a hash of what the image depends on: the job and its inputs' stamps
        sources = shared + [out / scenefiles.frame_file(k)]
        stamps = [(str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in sources]
        settings = {f: v for f, v in vars(job(k)).items() if f not in ("share", "inputs")}
        return _pool.task_key("frame", settings, stamps)

    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), unit="frame", desc="rendering")
    failed = {}
    diagnostics = {}
    rendered = []
    pending = {}

    def submit(k, attempt, with_inputs=False):
        try:
            task = job(k, with_inputs)
            name = key(k) if attempt == 0 and not with_inputs else None  # else pure=False
            pending[_pool.submit(executor, worker, task, key=name)] = (k, attempt, with_inputs)
            return True
        except Exception as e:  # a broken executor: the frame is failed, not dropped
            failed[k] = f"could not be submitted: {type(e).__name__}: {e}"
            return False

    try:
        for k in todo:
            if not submit(k, 0) and bar is not None:
                bar.update(1)
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                k, attempt, with_inputs = pending.pop(fut)
                try:
                    res = fut.result()
                except Exception as e:  # a worker or executor failure counts as a failed try
                    res = FrameResult(k, False, f"{type(e).__name__}: {e}")
                if res.needs_inputs and not with_inputs:  # a worker that cannot see `out`
                    if submit(k, attempt, with_inputs=True):
                        continue
                if res.ok and res.image is not None:  # rendered elsewhere: written here
                    scenefiles.write_bytes(images[k], res.image, only_if_changed=False)
                if res.diagnostics:
                    diagnostics[k] = res.diagnostics
                if res.ok:
                    rendered.append(k)
                elif attempt < retries:
                    if submit(k, attempt + 1, with_inputs):
                        continue
                else:
                    failed[k] = res.error
                if bar is not None:
                    bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        for fut in pending:  # interrupted: nothing more is queued for this run
            fut.cancel()
        if own_executor:
            executor.shutdown(wait=True, cancel_futures=True)
    if failed:
        first = min(failed)
        raise RenderError(
            f"{len(failed)} of {n} frames failed to render after "
            f"{retries + 1} tries: frames {_ranges(failed)} (frame {first}: "
            f"{failed[first]})",
            sorted(failed),
        )
    return RenderResult(
        images=images,
        rendered=sorted(rendered),
        skipped=skipped,
        diagnostics=diagnostics,
        wall_seconds=time.perf_counter() - t0,
    )


def _atomic_output(path):
    path = Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


def make_gif(images, path, fps):
    """Animated GIF (looping) of the images at fps, written whole or not at all."""
    import imageio.v3 as iio
    import numpy as np

    frames = np.stack([iio.imread(p)[..., :3] for p in images])
    tmp = _atomic_output(path)
    try:
        iio.imwrite(tmp, frames, extension=".gif", duration=1000.0 / fps, loop=0)
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return Path(path)


class FfmpegNotFound(FileNotFoundError):
    """MP4 output needs the ffmpeg binary."""


def make_mp4(out_dir, path, fps, final_frame, ffmpeg=None):
    """H.264 MP4 of render/frame_NNN.png with ffmpeg, written whole or not at all."""
    exe = shutil.which(ffmpeg or "ffmpeg")
    if exe is None:
        raise FfmpegNotFound(
            "MP4 output needs ffmpeg, which is not installed: install the "
            "Debian package 'ffmpeg' (sudo apt-get install ffmpeg), or make a "
            "GIF instead (--gif)"
        )
    out = Path(out_dir)
    digits = len(str(final_frame))
    tmp = _atomic_output(path)
    cmd = [
        exe,
        "-y",
        "-loglevel",
        "error",
        "-framerate",
        f"{fps:g}",
        "-start_number",
        "0",
        "-i",
        str(out / scenefiles.RENDER_DIR / f"frame_%0{digits}d.png"),
        "-vf",
        "pad=ceil(iw/2)*2:ceil(ih/2)*2",
        "-c:v",
        "libx264",
        "-pix_fmt",
        "yuv420p",
        "-f",
        "mp4",
        str(tmp),
    ]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise RenderError(f"ffmpeg failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return Path(path)
