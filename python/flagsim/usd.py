"""USD export (usd-core, the optional extra ``flagsim[usd]``): the flag as a UsdGeom.Mesh with
time-sampled points, normals and extent, one sample per frame, and the pole as a
UsdGeom.Cylinder, for Blender, Houdini and any other USD reader.

    import flagsim, flagsim.usd
    sim = flagsim.Simulation(flagsim.Scene.paper())
    flagsim.usd.write(sim, "flag.usdc", seconds=4, fps=25)

The stage (decisions a reader relies on):
  /flagsim        Xform, the default prim, kind "component"
  /flagsim/flag   Mesh: triangles (faceVertexCounts 3), right-handed winding (counter-clockwise
                  seen from +z at rest, as sim.triangles), subdivisionScheme "none" (a cloth
                  mesh with its own normals, not a subdivision cage), doubleSided; points,
                  normals ("vertex") and extent time-sampled, float32; primvars:st the
                  texture coordinates (texCoord2f, "vertex", u = 0 at the pole, v = 1 at the
                  top); displayColor the built-in flag's red
  /flagsim/pole   Cylinder along Y (radius, height of scene.pole), translated to its centre
  several flags   flag i > 0 is /flagsim/flag_<i>, its pole /flagsim/pole_<i> (flag 0 keeps the
                  names above), each mesh with its own points, normals and extent
  upAxis "Y"      flagsim's own frame is right-handed and y-up, USD's default: points are written
                  as simulated, so they equal sim.render_positions to float32 rounding. Blender
                  (z-up) turns a Y-up stage upright on import; Houdini is y-up itself.
  metersPerUnit 1 flagsim works in metres.
  time codes      frame k is time code k; timeCodesPerSecond = framesPerSecond = fps, so time
                  code k is t = k / fps (the frame is the state after round(k / (fps dt)) steps,
                  within dt / 2 of it, as `flagsim run` takes frames); startTimeCode 0,
                  endTimeCode the last frame.

The file is written whole or not at all: the stage is built in memory and exported to a
temporary file beside the target, then renamed over it.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SUFFIXES = (".usd", ".usda", ".usdc")
ROOT = "/flagsim"


class UsdUnavailable(RuntimeError):
    """usd-core (the pxr package) is not installed."""


def _pxr():
    try:
        from pxr import Gf, Kind, Sdf, Usd, UsdGeom, Vt
    except ImportError as e:
        raise UsdUnavailable(
            f"USD export needs usd-core ({e}): pip install 'flagsim[usd]'"
        ) from None
    return Gf, Kind, Sdf, Usd, UsdGeom, Vt


def require():
    """Raise UsdUnavailable now (before any simulating) when usd-core is missing."""
    _pxr()


def check_path(path):
    """The output path as a Path, or ValueError: a .usd, .usda or .usdc file, not a folder."""
    if path is None or not str(path).strip():
        raise ValueError(f"usd should be a file path, got {str(path)!r}")
    p = Path(path).expanduser()
    if p.suffix.lower() not in SUFFIXES:
        raise ValueError(f"usd should be a {', '.join(SUFFIXES)} file, got '{p}'")
    if p.is_dir():
        raise ValueError(f"usd should be a file, got a folder: {p}")
    return p


class Recorder:
    """A USD stage in memory that takes one frame at a time: add_frame(sim) after each frame's
    steps, then save(path). The topology, uv and pole are written once, from `sim` as given.

    fps    frames per second of the time codes
    scene  supplies the pole (default sim.scene)
    """

    def __init__(self, sim, *, fps, scene=None):
        from .povray import scenefiles
        from .povray.mesh import flags_of

        Gf, Kind, Sdf, Usd, UsdGeom, Vt = _pxr()
        self._Gf, self._Vt = Gf, Vt
        self.fps = float(fps)
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps should be finite and > 0, got {fps}")
        self.frames = 0
        stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, UsdGeom.LinearUnits.meters)
        stage.SetTimeCodesPerSecond(self.fps)
        stage.SetFramesPerSecond(self.fps)
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(0)
        root = UsdGeom.Xform.Define(stage, ROOT)
        stage.SetDefaultPrim(root.GetPrim())
        Usd.ModelAPI(root.GetPrim()).SetKind(Kind.Tokens.component)

        self._attrs = []  # per flag: (points, normals, extent) attributes
        for i, flag in enumerate(flags_of(sim)):
            self._attrs.append(self._define_flag(stage, f"{ROOT}/{_suffixed('flag', i)}", flag))
        scene = scene if scene is not None else getattr(sim, "scene", None)
        poles = _flag_poles(scene)
        for i, pole in enumerate(poles):
            if pole is not None and scenefiles.pole_enabled(pole):
                self._define_pole(stage, f"{ROOT}/{_suffixed('pole', i)}", pole)
        self.stage = stage

    def _define_flag(self, stage, path, flag):
        from .povray import scenefiles
        from .povray.mesh import mesh_arrays

        Gf, Kind, Sdf, Usd, UsdGeom, Vt = _pxr()
        _, _, uv, triangles = mesh_arrays(flag)
        triangles = np.asarray(triangles)
        mesh = UsdGeom.Mesh.Define(stage, path)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(triangles)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(triangles.astype(np.int32).ravel()))
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateDoubleSidedAttr(True)
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
        )
        st.Set(Vt.Vec2fArray.FromNumpy(np.asarray(uv, dtype=np.float32)))
        mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(
            Vt.Vec3fArray([Gf.Vec3f(*scenefiles.FLAG_RED)])
        )
        return mesh.CreatePointsAttr(), mesh.CreateNormalsAttr(), mesh.CreateExtentAttr()

    def _define_pole(self, stage, path, pole):
        Gf, Kind, Sdf, Usd, UsdGeom, Vt = _pxr()
        r, h = float(pole.radius), float(pole.height)
        cyl = UsdGeom.Cylinder.Define(stage, path)
        cyl.CreateAxisAttr(UsdGeom.Tokens.y)
        cyl.CreateRadiusAttr(r)
        cyl.CreateHeightAttr(h)
        cyl.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-r, -h / 2, -r), Gf.Vec3f(r, h / 2, r)]))
        centre = np.asarray(pole.base, dtype=float) + [0.0, h / 2, 0.0]
        cyl.AddTranslateOp().Set(Gf.Vec3d(*centre))
        cyl.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(
            Vt.Vec3fArray([Gf.Vec3f(0.80, 0.80, 0.82)])
        )

    def add_frame(self, sim):
        """Take sim's current geometry (mesh_arrays: the render geometry) as the next frame."""
        from .povray.mesh import flags_of, mesh_arrays

        Gf, Vt = self._Gf, self._Vt
        k = self.frames
        for (points, normals_attr, extent), flag in zip(self._attrs, flags_of(sim)):
            positions, normals, _, _ = mesh_arrays(flag)
            p = np.asarray(positions, dtype=np.float32)
            points.Set(Vt.Vec3fArray.FromNumpy(p), k)
            normals_attr.Set(Vt.Vec3fArray.FromNumpy(np.asarray(normals, dtype=np.float32)), k)
            lo, hi = p.min(axis=0), p.max(axis=0)
            extent.Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]), k)
        self.frames += 1
        self.stage.SetEndTimeCode(max(self.frames - 1, 0))

    def save(self, path):
        """Write the stage to `path` (its suffix picks the format: .usdc and .usd binary crate,
        .usda text), whole or not at all. Returns the file size in bytes."""
        path = check_path(path)
        if self.frames == 0:
            raise ValueError("a USD file needs at least one frame, got none (call add_frame)")
        path.parent.mkdir(parents=True, exist_ok=True)
        # The temporary name keeps the suffix: USD picks the file format by it.
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
        try:
            if not self.stage.GetRootLayer().Export(os.fspath(tmp)):
                raise OSError(f"USD could not write {tmp}")
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
        return path.stat().st_size


def _suffixed(name, i):
    """Flag 0's prims keep their one-flag names (/flagsim/flag, /flagsim/pole); flag i > 0 gets
    name_<i>."""
    return name if i == 0 else f"{name}_{i}"


def _flag_poles(scene):
    """The pole of each flag (index = flag), or [scene_pole] for a scene without flags."""
    from .povray import scenefiles

    specs = getattr(scene, "flags", None) if scene is not None else None
    if specs and len(specs) > 1:
        return [s.pole for s in specs]
    return [scenefiles.scene_pole(scene)]


@dataclass
class UsdResult:
    path: Path
    frames: int
    steps: int
    bytes: int
    wall_seconds: float  # simulating and writing
    write_seconds: float  # building and saving the stage only


def write(sim, path, *, seconds, fps=25.0, scene=None, progress=False):
    """Simulate ``seconds`` of ``sim`` and write it to ``path`` as USD: frame k is the state
    after round(k / (fps dt)) steps from sim's current step (as `flagsim run` takes frames).
    Returns a UsdResult; UsdUnavailable without usd-core, ValueError for bad arguments."""
    from .povray.export import frame_steps

    path = check_path(path)
    if scene is None:
        scene = getattr(sim, "scene", None)
    dt = float(scene.dt if scene is not None else sim.dt)
    steps = frame_steps(float(seconds), float(fps), dt)
    t0 = time.perf_counter()
    recorder = Recorder(sim, fps=fps, scene=scene)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(steps), unit="frame", desc="simulating")
    start = sim.step_count
    write_seconds = time.perf_counter() - t0
    try:
        for target in steps:
            n = start + target - sim.step_count
            if n > 0:
                sim.step(n)
            tw = time.perf_counter()
            recorder.add_frame(sim)
            write_seconds += time.perf_counter() - tw
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    tw = time.perf_counter()
    size = recorder.save(path)
    write_seconds += time.perf_counter() - tw
    return UsdResult(
        path=path,
        frames=recorder.frames,
        steps=sim.step_count - start,
        bytes=size,
        wall_seconds=time.perf_counter() - t0,
        write_seconds=write_seconds,
    )
