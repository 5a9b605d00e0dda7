"""A live viewer for a running simulation (polyscope, the optional extra ``flagsim[viewer]``).

    import flagsim, flagsim.viewer
    sim = flagsim.Simulation(flagsim.Scene.paper())
    flagsim.viewer.show(sim)                                   # a window; needs a display
    flagsim.viewer.screenshot(sim, "flag.png", frames=50)      # off-screen (EGL), no display

The window shows the flag with its texture, the pole and, on request, a horizontal slice of the
air; its panel plays, pauses, steps and resets the simulation, sets the wind, the flapping mode
and the integrator, and shows steps/s, simulated/wall time, the stage split and the energy
(docs/viewer.md). The controls live in Controller (controls.py, no polyscope), which the window
calls and tests drive directly. Importing this module loads neither polyscope nor OpenGL; they
load when a window or a picture is asked for.
"""

from __future__ import annotations

import numbers
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from .controls import KEYS, Controller, Stats

__all__ = [
    "KEYS",
    "Controller",
    "Offscreen",
    "ScreenshotResult",
    "Stats",
    "ViewerUnavailable",
    "probe_headless",
    "screenshot",
    "show",
]


PANEL_WIDTH = 330  # pixels: the control panel, on the right of the window


class ViewerUnavailable(RuntimeError):
    """The viewer cannot run here: polyscope is missing, or there is no display / no OpenGL."""


def _window():
    try:
        from . import window
    except ImportError as e:
        raise ViewerUnavailable(
            f"the viewer needs polyscope ({e}): pip install 'flagsim[viewer]'"
        ) from None
    return window


def __getattr__(name):
    if name == "Offscreen":
        return _window().Offscreen
    raise AttributeError(f"module 'flagsim.viewer' has no attribute {name!r}")


def _controller(sim):
    return sim if isinstance(sim, Controller) else Controller(sim)


def show(sim, *, texture=None, width=1280, height=720):
    """Open a window on ``sim`` (a flagsim.Simulation or a Controller) and run it in real time
    until the window is closed. Needs a display; ViewerUnavailable says why not."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ViewerUnavailable(
            "no display (DISPLAY and WAYLAND_DISPLAY are unset): the live window needs one; "
            "for a picture without a display use --screenshot (flagsim.viewer.screenshot)"
        )
    check_size(width, height)
    ctrl = _controller(sim)
    _window().show(ctrl, texture=texture, width=width, height=height)
    return ctrl


def check_size(width, height, *, panel=True):
    """ValueError unless width and height are pixel counts in [64, 8192] (with the panel, the
    width leaves the flag at least as much room as the panel takes)."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, numbers.Integral) or not 64 <= v <= 8192:
            raise ValueError(f"{name} should be an integer in [64, 8192] pixels, got {v!r}")
    if panel and width < 2 * PANEL_WIDTH:
        raise ValueError(f"width should be >= {2 * PANEL_WIDTH} pixels with the panel, got {width}")


# --- headless --------------------------------------------------------------------------------
_PROBE = """
import sys
import numpy as np, polyscope as ps
ps.set_use_prefs_file(False)
ps.set_verbosity(0)
ps.set_allow_headless_backends(True)
try:
    ps.init("openGL3_egl")
except Exception as e:
    sys.exit("probe: " + " ".join(str(e).split()))
ps.set_window_size(64, 48)
ps.register_surface_mesh("t", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]),
                         np.array([[0, 1, 2]]), color=(1.0, 0.0, 0.0))
img = ps.screenshot_to_buffer(False)
red = (img[..., 0].astype(int) - img[..., 1]) > 100
assert img.shape == (48, 64, 4) and red.any(), "nothing drawn"
"""
_probe_result = None


def probe_headless(timeout=120.0):
    """None when off-screen OpenGL (polyscope through EGL) draws here, else why not. Runs once
    per process, in a child process: a missing or broken driver may crash instead of failing
    (seen: a segmentation fault without libEGL)."""
    global _probe_result
    if _probe_result is not None:
        return _probe_result or None
    import importlib.util

    if importlib.util.find_spec("polyscope") is None:
        _probe_result = "polyscope is not installed: pip install 'flagsim[viewer]'"
        return _probe_result
    with tempfile.TemporaryDirectory() as cwd:
        try:
            r = subprocess.run(
                [sys.executable, "-c", _PROBE],
                cwd=cwd,
                capture_output=True,
                text=True,
                timeout=timeout,
            )
        except subprocess.TimeoutExpired:
            _probe_result = f"off-screen OpenGL (EGL) did not answer within {timeout:g} s"
            return _probe_result
    if r.returncode == 0:
        _probe_result = ""
        return None
    said = [line for line in (r.stderr + r.stdout).splitlines() if line.strip()]
    ours = [line[len("probe: ") :] for line in said if line.startswith("probe: ")]
    if ours:
        cause = ours[0]
    elif r.returncode < 0:
        cause = f"killed by signal {-r.returncode}"
    else:
        cause = said[-1] if said else f"exit status {r.returncode}"
    _probe_result = (
        f"off-screen OpenGL (EGL) does not work here ({cause}); on Debian install "
        f"libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri"
    )
    return _probe_result


@dataclass
class ScreenshotResult:
    path: Path
    frames: int  # frames drawn (the picture is the last)
    steps: int  # simulation steps taken
    wall_seconds: float  # the whole frame loop: stepping and drawing
    step_seconds: float  # stepping only
    fps: float  # frames per simulated second

    @property
    def frames_per_second(self):
        """Frames drawn per wall second."""
        return self.frames / self.wall_seconds if self.wall_seconds > 0 else 0.0

    @property
    def realtime_ratio(self):
        """Simulated / wall time of the frame loop (real time = 1.0)."""
        return self.frames / self.fps / self.wall_seconds if self.wall_seconds > 0 else 0.0

    @property
    def steps_per_second(self):
        return self.steps / self.step_seconds if self.step_seconds > 0 else 0.0


def check_png_path(path):
    """The screenshot's path as a Path, or ValueError: a .png file name that is not a folder."""
    if path is None or not str(path).strip():
        raise ValueError(f"screenshot should be a .png file path, got {str(path)!r}")
    p = Path(path).expanduser()
    if p.suffix.lower() != ".png":
        raise ValueError(f"screenshot should be a .png file, got '{p}'")
    if p.is_dir():
        raise ValueError(f"screenshot should be a file, got a folder: {p}")
    return p


def screenshot(
    sim,
    path,
    *,
    frames,
    fps=25.0,
    width=960,
    height=540,
    texture=None,
    panel=True,
    air=False,
    progress=False,
):
    """Draw ``frames`` frames of ``sim`` (a Simulation or a Controller) off-screen, one per
    1/fps simulated seconds (frame k after round(k / (fps dt)) steps, as `flagsim run` takes
    them), and write the last one to ``path`` (PNG, written whole or not at all).
    Returns a ScreenshotResult with the loop's timings; ViewerUnavailable when off-screen
    OpenGL does not work here."""
    from ..povray.export import frame_steps

    path = check_png_path(path)
    frames = int(frames)
    if frames < 1:
        raise ValueError(f"frames should be >= 1, got {frames}")
    for name, v in (("width", width), ("height", height)):
        if not 64 <= int(v) <= 8192:
            raise ValueError(f"{name} should be in [64, 8192] pixels, got {v}")
    if panel and int(width) < 2 * PANEL_WIDTH:
        raise ValueError(f"width should be >= {2 * PANEL_WIDTH} pixels with the panel, got {width}")
    ctrl = _controller(sim)
    steps = frame_steps(frames / float(fps), float(fps), float(ctrl.sim.scene.dt))[: frames + 1]
    reason = probe_headless()
    if reason:
        raise ViewerUnavailable(reason)
    ctrl.show_air = bool(air)
    ctrl.pause()  # a fixed-rate run: frames are taken by steps, not by the wall clock
    view = _window().Offscreen(ctrl, width=width, height=height, texture=texture, panel=panel)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=frames, unit="frame", desc="drawing")
    step_seconds = 0.0
    start = ctrl.sim.step_count
    t0 = previous = time.perf_counter()
    try:
        view.render()  # frame 0: the state as given
        for k in range(1, len(steps)):
            now = time.perf_counter()  # a frame's wall time: from the previous frame's start
            ctrl.step_frame(steps[k] - steps[k - 1], wall_seconds=now - previous)
            previous = now
            step_seconds += time.perf_counter() - now
            view.render()
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t0
    write_png(path, view.image())
    return ScreenshotResult(
        path=path,
        frames=len(steps) - 1,
        steps=ctrl.sim.step_count - start,
        wall_seconds=wall,
        step_seconds=step_seconds,
        fps=float(fps),
    )


def write_png(path, image):
    """Write an (H, W, 3) uint8 image as PNG, whole or not at all (temporary file, rename)."""
    import imageio.v3 as iio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.png")
    try:
        iio.imwrite(tmp, image)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
