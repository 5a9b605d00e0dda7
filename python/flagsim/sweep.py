"""Sweeps: one scene under every combination of some settings, each combination one task
(simulate, export for POV-Ray, optionally render), run through an Executor: in this process, a
local process pool, or a Dask cluster (docs/distributed.md).

    import flagsim
    from flagsim.sweep import run_sweep
    rows = run_sweep(
        flagsim.Scene.paper(),
        {"air.wind": [[2, 0, 0], [8, 0, 1]], "flag.stretch_stiffness": [100, 1000]},
        "out/sweep", seconds=1, render=True,
    )

The command line is ``flagsim sweep SCENE --vary KEY=V1,V2,... [--vary ...] --out DIR``. A key
is a scene field as a TOML scene file names it (``air.wind``, ``flag.rows``, ``dt``) and is set
through the same code (flagsim.scene.apply_dict), so its errors name it the same way; a value is
a TOML value (``5``, ``0.01``, ``[2, 0, 0]``, ``true``, ``"implicit"``; a bare word is a string).

DIR holds:
  sweep.csv   the index: one row per combination, its settings, frames, the work done
              (export, render, kept), the files it returned to the head (0: written in place),
              and where it ran (worker, host, pid), the attempts it needed and how long it took
  sweep.json  what every combination shares (the scene, seconds, fps, the varied keys)
  NAME/       one export per combination, laid out as `flagsim run` lays it out (flag.pov,
              frames/, render/, flag.gif with --render); `flagsim render DIR/NAME` works there

NAME is the combination's settings, ``key=value`` joined by commas in --vary order
(``air.wind=2_0_0,flag.stretch_stiffness=100``): numbers as Python writes them (5.0 as 5), lists
of numbers joined by "_", booleans true/false, strings as they are. Names keep to letters,
digits and ``. _ + - = ,`` (valid on Linux, macOS and Windows); other characters become "_",
and such a name, one longer than 80 characters (cut to 64) or one equal to another but for
letter case gets "-" and 10 hex digits of a hash of its settings.

Each task is a pure function of its settings. A worker that sees DIR (the same machine or a
shared file system: it reads the head's lock record in DIR/.flagsim.lock) writes its folder
there, every file whole (temporary file, then rename); one that does not builds the folder in a
temporary folder of its own and returns its files, which the head writes, export.json first.
Only the head writes sweep.csv. Combinations whose folder is already complete with the same
settings are kept without simulating; an interrupted sweep resumes.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import re
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

from .povray import scenefiles

INDEX = "sweep.csv"
MANIFEST = "sweep.json"
MANIFEST_FORMAT = 1
#: the folder-name rules (module docstring)
NAME_MAX = 80
NAME_CUT = 64
_SAFE = re.compile(r"[A-Za-z0-9._+=,-]+")
RESULT_COLUMNS = ["frames", "rendered", "work", "returned"]
PLACEMENT_COLUMNS = ["attempts", "worker", "host", "pid", "seconds", "key"]
#: POV-Ray processes at once inside one task (each single-threaded, so a frame is the same
#: image on every worker): POV-Ray idles ~0.6 s per run, three overlap it (povray/render.py)
POVRAY_PER_TASK = 3


# ---- --vary ---------------------------------------------------------------------------------


def split_values(text: str) -> list[str]:
    """'1,[2, 3],"a,b"' -> ['1', '[2, 3]', '"a,b"']: commas inside brackets, braces or quotes
    do not split."""
    parts, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts]


def parse_value(text: str) -> Any:
    """A TOML value (5, 0.01, [2, 0, 0], true, "implicit"), or else the text as a string."""
    from .scene import _toml

    try:
        return _toml.loads(f"v = {text}")["v"]
    except _toml.TOMLDecodeError:
        return text


def parse_vary(spec: str) -> tuple[str, list[Any]]:
    """'KEY=V1,V2,...' -> (KEY, [V1, V2, ...]); ValueError naming what is wrong."""
    key, eq, values = spec.partition("=")
    key = key.strip()
    if (
        not eq
        or not key
        or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*", key)
    ):
        raise ValueError(
            f"--vary should be KEY=V1,V2,... with KEY a scene field such as air.wind or "
            f"flag.rows, got {spec!r}"
        )
    texts = split_values(values)
    if any(not t for t in texts):
        raise ValueError(f"--vary {key}: a value is empty in {values!r}")
    parsed = [parse_value(t) for t in texts]
    canon = [_canonical(v) for v in parsed]
    if len(set(canon)) != len(canon):
        raise ValueError(f"--vary {key}: a value is given twice in {values!r}")
    return key, parsed


def _canonical(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def combinations(vary: dict[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Every combination of the values, the first key varying slowest."""
    keys = list(vary)
    return [dict(zip(keys, values)) for values in itertools.product(*vary.values())]


# ---- scenes ---------------------------------------------------------------------------------


def _nested(key: str, value: Any) -> dict[str, Any]:
    out: Any = value
    for part in reversed(key.split(".")):
        out = {part: out}
    return out


def apply_settings(scene, settings: dict[str, Any]):
    """Set each KEY (air.wind, flag.rows, dt) of the Scene as a TOML file would, then check the
    rules that span fields; ValueError naming the setting."""
    from .scene import apply_dict

    for key, value in settings.items():
        try:
            apply_dict(scene, _nested(key, value), "")
        except ValueError as e:
            raise ValueError(f"--vary {key}={_value_text(value)}: {e}") from None
    try:
        scene.validate()
    except ValueError as e:
        shown = ", ".join(f"{k}={_value_text(v)}" for k, v in settings.items())
        raise ValueError(f"--vary {shown}: {e}") from None
    return scene


def build_scene(base: dict[str, Any], settings: dict[str, Any]):
    """The scene of a combination: the base scene (flagsim.scene.to_dict) with the settings."""
    from .scene import from_dict

    return apply_settings(from_dict(base), settings)


# ---- names ----------------------------------------------------------------------------------


def _value_text(value: Any) -> str:
    """CSV text of a value: strings as they are, others as JSON ([2, 0, 0], 5.0, true)."""
    return value if isinstance(value, str) else json.dumps(value)


def _name_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        text = repr(value)
        return text[:-2] if text.endswith(".0") else text
    if isinstance(value, str):
        return value
    if isinstance(value, list) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    ):
        return "_".join(_name_text(v) for v in value)
    return _canonical(value)


def settings_hash(settings: dict[str, Any]) -> str:
    return hashlib.sha256(_canonical(settings).encode()).hexdigest()[:10]


def folder_name(settings: dict[str, Any]) -> str:
    """The folder of a combination (rules in the module docstring), before the check against
    the other combinations' names (folder_names)."""
    text = ",".join(f"{k}={_name_text(v)}" for k, v in settings.items())
    safe = "_".join(_SAFE.findall(text))
    if safe == text and len(text) <= NAME_MAX and not text.endswith("."):
        return text
    return f"{safe[:NAME_CUT].rstrip('.')}-{settings_hash(settings)}"


def folder_names(combos: Iterable[dict[str, Any]]) -> list[str]:
    """folder_name of each combination; names equal but for letter case (one folder on macOS
    and Windows) get the hash too."""
    combos = list(combos)
    names = [folder_name(s) for s in combos]
    seen: dict[str, int] = {}
    for n in names:
        seen[n.casefold()] = seen.get(n.casefold(), 0) + 1
    return [
        f"{n}-{settings_hash(s)}" if seen[n.casefold()] > 1 else n for n, s in zip(names, combos)
    ]


# ---- tasks ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class SweepSpec:
    """What every task of a sweep shares (picklable, JSON-able: its hash is part of task keys)."""

    base: dict  # the base scene, flagsim.scene.to_dict
    source: dict  # where it came from (a built-in's name, a file's path and sha256)
    out: str  # the sweep folder, absolute, as the head sees it
    seconds: float
    fps: float
    width: int
    height: int
    render: bool
    overwrite: bool
    threads: int  # flagsim threads per task: the same on every worker, so the same bytes
    # the head's lock record on `out` (povray.lock.sees_folder): where the task may write, not
    # what it computes, so not part of its key
    share: dict | None = field(default=None, compare=False)


def export_key(spec: SweepSpec, scene) -> dict[str, Any]:
    """What a combination's frames depend on (export.json's key), as `flagsim run` writes it."""
    from . import __version__
    from .scene import to_dict

    return {
        "scene": {"source": spec.source, "scene": to_dict(scene), "flagsim": __version__},
        "fps": float(spec.fps),
        "dt": float(scene.dt),
    }


def run_task(case: dict[str, Any], spec: SweepSpec) -> dict[str, Any]:
    """One combination: simulate and export into OUT/NAME (or a temporary folder whose files are
    returned, for a worker that does not see OUT), render and assemble flag.gif if asked.
    Returns metadata only (and those files). ``case["have"]``, the head's look at the folder:
    "all" (nothing to do), "export" (frames complete, render them), "none"."""
    import logging

    from .povray.lock import sees_folder
    from .study.runner import FILES

    name = case["id"]
    log = logging.getLogger("flagsim.sweep")
    if case["have"] == "all":
        return {
            "frames": case["frames"],
            "rendered": _rendered(spec),
            "work": "kept",
            "returned": 0,
        }
    shared = spec.share is not None and sees_folder(spec.out, spec.share)
    log.info(
        "sweep task %s starts (%s)", name, "in the shared folder" if shared else "returns files"
    )
    if shared:
        return _build(case, spec, Path(spec.out) / name, skip_export=case["have"] == "export")
    with tempfile.TemporaryDirectory(prefix="flagsim-sweep-") as tmp:
        folder = Path(tmp) / name
        result = _build(case, spec, folder, skip_export=False)
        result[FILES] = _folder_files(folder, name)
        result["returned"] = len(result[FILES])
        return result


def _build(case, spec: SweepSpec, folder: Path, *, skip_export: bool) -> dict[str, Any]:
    import flagsim

    from . import povray

    work = []
    if not skip_export:
        scene = build_scene(spec.base, case["settings"])
        threads = flagsim.num_threads()
        flagsim.set_num_threads(spec.threads)
        try:
            povray.export(
                flagsim.Simulation(scene),
                folder,
                seconds=spec.seconds,
                fps=spec.fps,
                scene=scene,
                width=spec.width,
                height=spec.height,
                key=export_key(spec, scene),
                overwrite=spec.overwrite,
                progress=False,
            )
        finally:
            flagsim.set_num_threads(threads)
        work.append("export")
    frames = povray.read_manifest(folder)["frames"]
    if spec.render:
        with ThreadPoolExecutor(POVRAY_PER_TASK) as ex:
            result = povray.render(folder, executor=ex, threads=1, progress=False)
        povray.make_gif(result.images, folder / "flag.gif", spec.fps)
        work.append("render")
    return {"frames": frames, "rendered": _rendered(spec), "work": "+".join(work), "returned": 0}


def _rendered(spec: SweepSpec) -> str:
    return f"{spec.width}x{spec.height}" if spec.render else ""


def _folder_files(folder: Path, name: str) -> dict[str, bytes]:
    """The files of a finished combination folder for the head to write under OUT, export.json
    first (from then on the folder is recognisably a flagsim export), the lock and temporary
    files left out."""
    from .povray.export import MANIFEST as EXPORT_MANIFEST
    from .povray.lock import LOCK_NAME

    paths = sorted(
        p
        for p in folder.rglob("*")
        if p.is_file()
        and not p.name.startswith(LOCK_NAME)
        and not (p.name.endswith(".tmp") or ".tmp." in p.name)
    )
    paths.sort(key=lambda p: p.name != EXPORT_MANIFEST or p.parent != folder)
    return {f"{name}/{p.relative_to(folder).as_posix()}": p.read_bytes() for p in paths}


# ---- the head -------------------------------------------------------------------------------


def _have(folder: Path, key: dict, spec: SweepSpec, frames: int) -> str:
    """What a combination's folder already holds with these settings: "all", "export" or
    "none"; ExportConflict when it holds something else, or with spec.overwrite "replace"
    when that is an export of other settings."""
    from .povray.export import ExportConflict, read_manifest
    from .povray.render import _up_to_date

    if not folder.exists():
        return "none"
    try:
        manifest = read_manifest(folder)
    except ExportConflict:
        if spec.overwrite:
            return "replace"
        raise
    if manifest is None:
        if any(folder.iterdir()) and not spec.overwrite:
            raise ExportConflict(
                f"{folder} is not empty and holds no flagsim export; choose another --out"
            )
        return "none"
    if manifest.get("key") != key:
        if not spec.overwrite:
            raise ExportConflict(
                f"{folder} holds an export of other settings; choose another --out, or "
                f"--overwrite to replace it"
            )
        return "replace"
    complete = (
        manifest.get("complete")
        and manifest.get("frames") == frames
        and (folder / scenefiles.SCENE_FILE).is_file()
        and all((folder / scenefiles.frame_file(k)).is_file() for k in range(frames))
    )
    if not complete:
        return "none"
    if not spec.render:
        return "all"
    shared = [folder / scenefiles.SCENE_FILE]
    images_ok = all(
        _up_to_date(
            folder / scenefiles.render_file(k, frames - 1),
            shared + [folder / scenefiles.frame_file(k)],
            (spec.width, spec.height),
        )
        for k in range(frames)
    )
    gif = folder / "flag.gif"
    if images_ok and gif.is_file():
        return "all"
    return "export"


def _clear(folder: Path) -> None:
    """The frames, pictures and manifest of an export being replaced (only files flagsim
    names), so files of the old export cannot stay beside the new one's."""
    from .povray.export import MANIFEST as EXPORT_MANIFEST
    from .povray.export import _clear as clear_export

    clear_export(folder)
    (folder / "flag.gif").unlink(missing_ok=True)
    (folder / EXPORT_MANIFEST).unlink(missing_ok=True)


def _sweep_manifest(spec: SweepSpec, keys: list[str]) -> dict[str, Any]:
    from . import __version__

    return {
        "format": MANIFEST_FORMAT,
        "flagsim": __version__,
        "scene": {"source": spec.source, "scene": spec.base},
        "seconds": float(spec.seconds),
        "fps": float(spec.fps),
        "vary": keys,
    }


def _prepare(out: Path, manifest: dict, overwrite: bool) -> None:
    """OUT must be new, empty, or a sweep of the same scene, seconds, fps and varied keys
    (more values may be added); overwrite replaces one of other settings (its index is reset,
    each combination folder is replaced when its task runs)."""
    from .povray.export import ExportConflict
    from .povray.lock import LOCK_NAME
    from .study.report import write_text

    path = out / MANIFEST
    if path.is_file():
        try:
            old = json.loads(path.read_text(encoding="utf-8"))
        except ValueError:
            old = None
        if old != manifest:
            if not overwrite:
                raise ExportConflict(
                    f"{out} holds a sweep of another scene, --seconds, --fps or other --vary "
                    f"keys; choose another --out, or --overwrite to redo it"
                )
            (out / INDEX).unlink(missing_ok=True)
    else:
        foreign = sorted(p.name for p in out.iterdir() if not p.name.startswith(LOCK_NAME))
        if foreign:
            shown = ", ".join(foreign[:5]) + (", ..." if len(foreign) > 5 else "")
            raise ExportConflict(
                f"{out} is not empty ({shown}) and holds no flagsim sweep ({MANIFEST}); "
                f"choose another --out"
            )
    write_text(str(path), json.dumps(manifest, indent=1, sort_keys=True) + "\n")


def run_sweep(
    scene,
    vary: dict[str, Sequence[Any]],
    out,
    *,
    seconds: float = 4.0,
    fps: float = 25.0,
    width: int = 480,
    height: int = 360,
    render: bool = False,
    overwrite: bool = False,
    source: dict | None = None,
    threads: int = 1,
    jobs: int = 1,
    executor=None,
    progress: bool = True,
) -> list[dict[str, str]]:
    """Run every combination of ``vary`` ({key: [values]}) on ``scene`` into ``out``; returns
    the index rows (sweep.csv) in combination order.

    source     what the scene came from, for the exports' keys (default: {"scene": name})
    threads    flagsim threads per task (the same everywhere: identical bytes)
    jobs, executor  as the studies: 1 runs here, N a local process pool, an executor (a Dask
               client's, ``Client.get_executor()``) runs the tasks where it runs them
    Raises ValueError naming a bad key or value before any task runs, ExportConflict for a
    folder holding something else, and runner.TaskFailed naming the combinations that failed
    (the finished ones are in sweep.csv: running the same sweep again resumes).
    """
    from .povray.export import frame_steps, output_folder
    from .povray.lock import ExportLock
    from .scene import to_dict
    from .study import runner

    vary = {str(k): list(v) for k, v in dict(vary).items()}
    if not vary or any(not v for v in vary.values()):
        raise ValueError("vary should give at least one key with at least one value")
    if isinstance(threads, bool) or int(threads) < 1:
        raise ValueError(f"threads should be >= 1, got {threads}")
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not 16 <= int(v) <= 8192:
            raise ValueError(f"{name} should be in [16, 8192] pixels, got {v}")
    base = to_dict(scene)
    combos = combinations(vary)
    scenes = [build_scene(base, c) for c in combos]  # every bad key or value before any work
    frames = [len(frame_steps(float(seconds), float(fps), float(s.dt))) for s in scenes]
    names = folder_names(combos)
    out_path = output_folder(out).resolve()
    out_path.mkdir(parents=True, exist_ok=True)
    with ExportLock(out_path) as lock:
        spec = SweepSpec(
            base=base,
            source=source or {"scene": scene.name},
            out=str(out_path),
            seconds=float(seconds),
            fps=float(fps),
            width=int(width),
            height=int(height),
            render=bool(render),
            overwrite=bool(overwrite),
            threads=int(threads),
            share=lock.record,
        )
        _prepare(out_path, _sweep_manifest(spec, list(vary)), overwrite)
        columns = ["id", *vary, *RESULT_COLUMNS, *PLACEMENT_COLUMNS]
        index = str(out_path / INDEX)
        _drop_rows_short_of(index, columns, _rendered(spec))
        cases = []
        for name, settings, s, n in zip(names, combos, scenes, frames):
            have = _have(out_path / name, export_key(spec, s), spec, n)
            if have == "replace":  # --overwrite: the old export's frames and images go now
                _clear(out_path / name)
                have = "none"
            cases.append(
                {
                    "id": name,
                    **{k: _value_text(v) for k, v in settings.items()},
                    "settings": settings,
                    "frames": n,
                    "have": have,
                }
            )
        return runner.run_cases(
            cases,
            functools.partial(run_task, spec=spec),
            index,
            columns,
            jobs=jobs,
            executor=executor,
            progress=progress,
            desc="sweep",
            unit="task",
            files_dir=str(out_path),
        )


def _drop_rows_short_of(index: str, columns: list[str], rendered: str) -> None:
    """Rows of combinations not rendered as now asked leave the index, so they run again
    (their exports are kept: only the pictures are made)."""
    from .study.runner import _rewrite_clean, read_rows

    rows = read_rows(index)
    if not rows or list(rows[0]) != columns:
        return
    keep = [r for r in rows if not rendered or r["rendered"] == rendered]
    if len(keep) != len(rows):
        _rewrite_clean(index, columns, keep)
