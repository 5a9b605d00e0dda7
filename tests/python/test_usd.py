"""USD export (flagsim.usd, usd-core): a round trip through pxr gives back the simulation's
frames (time samples, frame rate, points and normals to float32, topology, uv, the pole), USD's
own validators find nothing wrong, and the file is written whole or not at all."""

import os

import flagsim
import flagsim.usd
import numpy as np
import pytest
from _optional import missing, require
from flagsim import cli
from flagsim.povray.export import frame_steps

require(missing("pxr", "usd"))
from pxr import Usd, UsdGeom, UsdValidation  # noqa: E402

SECONDS, FPS = 0.4, 25.0


def reference_frames(scene, seconds, fps):
    """(render positions, render normals) of every frame, stepped here as `flagsim run` does."""
    sim = flagsim.Simulation(scene)
    frames = []
    for target in frame_steps(seconds, fps, scene.dt):
        sim.step(target - sim.step_count)
        frames.append((np.array(sim.render_positions), np.array(sim.render_normals)))
    return sim, frames


def validation_errors(stage):
    """Every error and warning of all the validators usd-core registers."""
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    return [
        f"{e.GetName()}: {e.GetMessage()}"
        for e in context.Validate(stage)
        if e.GetType()
        in (UsdValidation.ValidationErrorType.Error, UsdValidation.ValidationErrorType.Warn)
    ]


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_round_trip_gives_back_the_simulated_frames(tmp_path, suffix):
    scene = flagsim.Scene.paper()
    path = tmp_path / f"flag{suffix}"
    result = flagsim.usd.write(flagsim.Simulation(scene), path, seconds=SECONDS, fps=FPS)
    sim, frames = reference_frames(scene, SECONDS, FPS)
    assert result.frames == len(frames) == 11 and result.steps == 40
    assert result.bytes == path.stat().st_size

    stage = Usd.Stage.Open(str(path))
    assert validation_errors(stage) == []
    # stage metadata: frame rate, time range, units, up axis, default prim
    assert stage.GetTimeCodesPerSecond() == FPS and stage.GetFramesPerSecond() == FPS
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 10)
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert stage.GetDefaultPrim().GetPath() == "/flagsim"

    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/flagsim/flag"))
    points, normals, extent = mesh.GetPointsAttr(), mesh.GetNormalsAttr(), mesh.GetExtentAttr()
    for attr in (points, normals, extent):
        assert attr.GetTimeSamples() == list(range(11))
    eps = np.finfo(np.float32).eps
    for k, (x, n) in enumerate(frames):
        p = np.asarray(points.Get(k))
        assert p.dtype == np.float32 and p.shape == x.shape
        # float32 rounding of the simulated positions: half an ulp
        assert np.all(np.abs(p - x) <= 0.5 * eps * np.maximum(np.abs(x), 1e-30))
        np.testing.assert_array_equal(p, x.astype(np.float32))
        np.testing.assert_array_equal(np.asarray(normals.Get(k)), n.astype(np.float32))
        np.testing.assert_array_equal(np.asarray(extent.Get(k)), [p.min(axis=0), p.max(axis=0)])
    # the frames are the simulation's: not all alike
    assert np.abs(np.asarray(points.Get(10)) - np.asarray(points.Get(0))).max() > 0.01

    # topology and uv, written once
    tri = np.asarray(sim.triangles)
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * len(tri)
    np.testing.assert_array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), tri.ravel())
    assert mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.rightHanded
    assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.vertex
    assert str(st.GetTypeName()) == "texCoord2f[]"
    np.testing.assert_array_equal(np.asarray(st.Get()), np.asarray(sim.uv, dtype=np.float32))
    # right-handed winding: at rest the triangles face +z, as sim.normals
    p0 = np.asarray(points.Get(0), dtype=float)
    face = np.cross(p0[tri[:, 1]] - p0[tri[:, 0]], p0[tri[:, 2]] - p0[tri[:, 0]])
    assert np.all(face[:, 2] > 0)

    # the pole: a cylinder along y from its base up
    pole = UsdGeom.Cylinder(stage.GetPrimAtPath("/flagsim/pole"))
    assert pole.GetAxisAttr().Get() == UsdGeom.Tokens.y
    assert pole.GetRadiusAttr().Get() == pytest.approx(scene.pole.radius)
    assert pole.GetHeightAttr().Get() == pytest.approx(scene.pole.height)
    world = pole.ComputeLocalToWorldTransform(0)
    base = np.asarray(scene.pole.base) + [0.0, scene.pole.height / 2, 0.0]
    np.testing.assert_allclose(np.asarray(world.ExtractTranslation()), base)


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "flag.usdc"
    path.write_bytes(b"the file from before")

    def fail(*args):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        flagsim.usd.write(flagsim.Simulation(flagsim.Scene.paper()), path, seconds=0.1)
    assert path.read_bytes() == b"the file from before"
    assert os.listdir(tmp_path) == ["flag.usdc"]


def test_bad_paths_and_rates_are_refused_before_simulating(tmp_path):
    sim = flagsim.Simulation(flagsim.Scene.paper())
    with pytest.raises(ValueError, match=r"usd should be a \.usd, \.usda, \.usdc file"):
        flagsim.usd.write(sim, tmp_path / "flag.abc", seconds=1)
    (tmp_path / "dir.usd").mkdir()
    with pytest.raises(ValueError, match="usd should be a file, got a folder"):
        flagsim.usd.write(sim, tmp_path / "dir.usd", seconds=1)
    with pytest.raises(ValueError, match="fps should be finite and > 0"):
        flagsim.usd.write(sim, tmp_path / "flag.usdc", seconds=1, fps=0)
    assert sim.step_count == 0 and sorted(os.listdir(tmp_path)) == ["dir.usd"]


def test_run_usd_writes_the_frames_of_the_export(tmp_path, capsys):
    usd_only = tmp_path / "only.usdc"
    code = cli.main(["run", "paper", "--seconds", "0.2", "--usd", str(usd_only), "-q"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert out.strip() == str(usd_only) and err == ""
    # with --out too: the POV-Ray export and the USD file hold the same frames, and the USD
    # file is the same bytes as without the export (one simulation, deterministic)
    both = tmp_path / "both.usdc"
    code = cli.main(
        ["run", "paper", "--seconds", "0.2", "--out", str(tmp_path / "pov"), "--usd", str(both)]
    )
    assert code == 0
    assert both.read_bytes() == usd_only.read_bytes()
    frames = sorted((tmp_path / "pov" / "frames").iterdir())
    stage = Usd.Stage.Open(str(both))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/flagsim/flag")).GetPointsAttr()
    assert len(points.GetTimeSamples()) == len(frames) == 6
    assert "wrote 6 frames to" in capsys.readouterr().err
    # bad combinations are usage errors
    code = cli.main(["run", "paper", "--seconds", "0.2"])
    assert code == 2 and "give --out DIR" in capsys.readouterr().err
    code = cli.main(["run", "paper", "--usd", str(tmp_path / "x.usdc"), "--render"])
    assert code == 2 and "--render needs --out DIR" in capsys.readouterr().err
    code = cli.main(["run", "paper", "--usd", str(tmp_path / "x.obj")])
    assert code == 2 and "usd should be a .usd, .usda, .usdc file" in capsys.readouterr().err
