"""Exporter: frame times independent of dt, whole files after a failure mid-write, resume."""

import json
import os
import resource
import signal

import flagsim.povray as pov
import numpy as np
import pytest
from _standin import StandInSim, standin_scene
from test_povray_mesh import parse_mesh2


def frame_files(out):
    return sorted(p.name for p in (out / "frames").iterdir())


@pytest.mark.parametrize("dt, fps", [(0.01, 25.0), (0.003, 25.0), (0.0025, 30.0)])
def test_frames_are_within_half_a_step_of_k_over_fps(tmp_path, dt, fps):
    sim = StandInSim(dt=dt)
    res = pov.export(sim, tmp_path, seconds=1.0, fps=fps, dt=dt, progress=False)
    assert res.frames == int(fps) + 1
    manifest = json.loads((tmp_path / "export.json").read_text())
    times = np.array(manifest["times"])
    assert np.abs(times - np.arange(res.frames) / fps).max() <= dt / 2 + 1e-12
    assert sim.step_count == round(1.0 / dt)
    # the frame file says which time it holds, and holds the state of that time
    m = parse_mesh2((tmp_path / "frames" / "flag_00007.inc").read_text())
    check = StandInSim(dt=dt)
    check.step(round(7 / (fps * dt)))
    assert np.abs(m["vertex_vectors"] * [1, 1, -1] - check.positions).max() < 1e-6


def test_fps_above_one_frame_per_step_is_rejected(tmp_path):
    with pytest.raises(ValueError, match=r"fps should be <= 1 / dt = 100"):
        pov.export(StandInSim(dt=0.01), tmp_path, seconds=1, fps=200, dt=0.01, progress=False)
    with pytest.raises(ValueError, match=r"seconds should be finite and >= 0, got -1"):
        pov.export(StandInSim(), tmp_path, seconds=-1, fps=25, dt=0.01, progress=False)


class FailingDisk(StandInSim):
    """Lowers the file-size limit once the simulation reaches `at_step`: the next frame's write
    then fails part-way with EFBIG, as a full disk or a crash mid-write would leave it."""

    def __init__(self, at_step, **kw):
        super().__init__(**kw)
        self.at_step = at_step
        self.limited = False

    def step(self, n=1):
        super().step(n)
        if self.step_count >= self.at_step and not self.limited:
            soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
            resource.setrlimit(resource.RLIMIT_FSIZE, (2000, hard))
            self.limited = True


def test_interrupted_export_leaves_whole_files_and_resumes(tmp_path):
    scene = standin_scene()
    out, ref = tmp_path / "out", tmp_path / "ref"
    pov.export(StandInSim(), ref, seconds=1.0, fps=10, scene=scene, progress=False)

    limits = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    try:
        with pytest.raises(OSError) as e:  # frame 6 is t = 0.6 s = step 60
            pov.export(
                FailingDisk(at_step=60), out, seconds=1.0, fps=10, scene=scene, progress=False
            )
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, limits)
        signal.signal(signal.SIGXFSZ, old_handler)
    assert e.value.errno == 27  # EFBIG: the write failed part-way through the file
    # Only whole frames 0-5, no partial frame 6, no temporary files anywhere.
    assert frame_files(out) == [f"flag_{k:05d}.inc" for k in range(6)]
    for k in range(6):
        parse_mesh2((out / "frames" / f"flag_{k:05d}.inc").read_text())
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]
    assert json.loads((out / "export.json").read_text())["complete"] is False
    with pytest.raises(pov.IncompleteExport, match=r"frames 6-10 missing.*again to resume"):
        pov.load_export(out)

    before = {k: os.stat(out / "frames" / f"flag_{k:05d}.inc").st_ino for k in range(6)}
    res = pov.export(StandInSim(), out, seconds=1.0, fps=10, scene=scene, progress=False)
    assert (res.kept, res.written) == (6, 5)
    assert before == {k: os.stat(out / "frames" / f"flag_{k:05d}.inc").st_ino for k in range(6)}
    for name in frame_files(ref):
        assert (out / "frames" / name).read_bytes() == (ref / "frames" / name).read_bytes()
    for name in ("flag.pov", "flag.ini"):
        assert (out / name).read_bytes() == (ref / name).read_bytes()
    assert pov.load_export(out)["complete"] is True


def test_other_settings_in_the_same_folder_conflict_unless_overwritten(tmp_path):
    pov.export(
        StandInSim(), tmp_path, seconds=0.5, fps=10, dt=0.01, key={"scene": "a"}, progress=False
    )
    with pytest.raises(pov.ExportConflict, match=r"holds an export of another scene"):
        pov.export(
            StandInSim(), tmp_path, seconds=0.5, fps=10, dt=0.01, key={"scene": "b"}, progress=False
        )
    res = pov.export(
        StandInSim(),
        tmp_path,
        seconds=0.2,
        fps=10,
        dt=0.01,
        key={"scene": "b"},
        overwrite=True,
        progress=False,
    )
    assert res.frames == 3 and frame_files(tmp_path) == [f"flag_{k:05d}.inc" for k in range(3)]


def test_master_scene_takes_the_pole_from_the_scene_in_povray_frame(tmp_path):
    scene = standin_scene()
    scene.pole.radius, scene.pole.base = 0.07, (0.0, -2.0, 0.25)
    pov.export(StandInSim(), tmp_path, seconds=0.1, fps=10, scene=scene, progress=False)
    text = (tmp_path / "flag.pov").read_text()
    assert "$" not in text  # every template field filled
    assert (
        "cylinder { <0.000000, -2.000000, -0.250000>, <0.000000, 0.600000, -0.250000>, "
        "0.070000 }" in text
    )
    assert '#include concat("frames/flag_", str(FRAME, -5, 0), ".inc")' in text
    ini = (tmp_path / "flag.ini").read_text()
    assert "Final_Frame=1" in ini and "Input_File_Name=flag.pov" in ini
    scene.pole.enabled = False
    pov.export(StandInSim(), tmp_path / "nopole", seconds=0.1, fps=10, scene=scene, progress=False)
    assert "cylinder" not in (tmp_path / "nopole" / "flag.pov").read_text()


def test_paper_flag_hoist_touches_the_drawn_pole(tmp_path):
    import re

    import flagsim
    from flagsim.povray import scenefiles

    sim = flagsim.Simulation(flagsim.Scene.paper())
    pov.export(sim, tmp_path, seconds=0.0, fps=10, progress=False)  # scene: sim.scene
    pole = scenefiles.scene_pole(sim.scene)  # scene.pole, or the default for a pole-pinned flag
    text = (tmp_path / "flag.pov").read_text()
    base, top, radius = re.search(r"cylinder \{ <([^>]*)>, <([^>]*)>, ([0-9.]+) \}", text).groups()
    base = np.array([float(c) for c in base.split(",")]) * [1, 1, -1]
    assert np.allclose(base, pole.base) and float(radius) == pytest.approx(pole.radius)
    hoist = sim.positions[sim.uv[:, 0] == 0.0]
    axis_distance = np.hypot(hoist[:, 0] - base[0], hoist[:, 2] - base[2])
    assert np.allclose(axis_distance, pole.radius, atol=1e-9)
    assert base[1] < hoist[:, 1].min() and hoist[:, 1].max() < base[1] + pole.height


def test_camera_faces_the_flag_from_its_plus_z_side_within_elevation_limits():
    from flagsim.povray.scenefiles import view_direction

    def angles(d):
        return np.degrees(np.arctan2(d[0], d[2])), np.degrees(np.arcsin(d[1]))

    # facing +z or -z (double-sided): 17 degrees to the right, 5 below
    for facing in ([0, 0, 1], [0, 0, -3], None, [0, 0, 0]):
        assert np.allclose(angles(view_direction(facing)), (17.0, -5.0))
    # a flag turned by the wind to face +x: the camera turns with it
    assert np.allclose(
        angles(view_direction([1, 0, 0.001])), (90.0 + 17.0 - 0.057, -5.0), atol=1e-2
    )
    # a banner blown flat faces up: seen from at most 40 degrees above
    assert np.isclose(angles(view_direction([0, 1, 0.2]))[1], 40.0)
    assert np.isclose(np.linalg.norm(view_direction([0.3, 0.4, 0.5])), 1.0)


def snapshot(folder):
    """Every file below `folder` (hidden ones too) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_a_folder_that_is_not_an_export_is_never_written(tmp_path, monkeypatch):
    # What `--out ~` or a careless folder holds: a user's pictures, scene, POV-Ray settings and
    # hidden files. Neither a plain export nor --overwrite may touch them.
    (tmp_path / "render").mkdir()
    (tmp_path / "render" / "frame_001.png").write_bytes(b"holiday picture")
    (tmp_path / "flag.pov").write_text("// my own scene\n")
    (tmp_path / ".povray" / "3.7").mkdir(parents=True)
    (tmp_path / ".povray" / "3.7" / "povray.conf").write_text("[File I/O Security]\n")
    (tmp_path / ".draft.tmp").write_text("unsaved\n")
    before = snapshot(tmp_path)
    created = []
    real_open = os.open

    def spy(path, flags, *a, **kw):  # the lock file is flagsim's only os.open(O_CREAT)
        if flags & os.O_CREAT:
            created.append(str(path))
        return real_open(path, flags, *a, **kw)

    monkeypatch.setattr(os, "open", spy)
    for overwrite in (False, True):
        with pytest.raises(
            pov.ExportConflict, match=r"is not empty \(.*\) and holds no flagsim " r"export"
        ):
            pov.export(
                StandInSim(),
                tmp_path,
                seconds=0.2,
                fps=10,
                dt=0.01,
                progress=False,
                overwrite=overwrite,
            )
        assert snapshot(tmp_path) == before  # nothing written, nothing deleted
        assert created == []  # refused before even a lock file was made


@pytest.mark.parametrize("out", ["", "   "])
def test_an_empty_output_path_is_an_error_not_the_current_folder(tmp_path, monkeypatch, out):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=r"out should be a folder path, got "):
        pov.export(StandInSim(), out, seconds=0.2, fps=10, dt=0.01, progress=False)
    assert list(tmp_path.iterdir()) == []


def test_an_output_path_that_is_a_file_is_an_error(tmp_path):
    f = tmp_path / "notes.txt"
    f.write_text("mine\n")
    with pytest.raises(ValueError, match=r"out should be a folder, got a file: .*notes\.txt"):
        pov.export(StandInSim(), f, seconds=0.2, fps=10, dt=0.01, progress=False)
    assert f.read_text() == "mine\n"


@pytest.mark.parametrize("manifest", ["[]", "{}", '"x"', "{not json", '{"key": 1, "frames": 1e9}'])
def test_overwrite_recovers_from_a_corrupt_manifest_and_keeps_the_users_files(tmp_path, manifest):
    key = {"scene": "a"}
    pov.export(StandInSim(), tmp_path, seconds=0.3, fps=10, dt=0.01, key=key, progress=False)
    (tmp_path / "notes.txt").write_text("keep me\n")
    (tmp_path / "render" / "poster.png").write_bytes(b"poster")
    (tmp_path / "export.json").write_text(manifest)
    if manifest.startswith('{"key"'):  # readable but damaged: another key, so a conflict
        match = r"holds an export of another scene"
    else:
        match = r"export\.json is not a flagsim export manifest"
    with pytest.raises(pov.ExportConflict, match=match):
        pov.export(StandInSim(), tmp_path, seconds=0.3, fps=10, dt=0.01, key=key, progress=False)
    res = pov.export(
        StandInSim(),
        tmp_path,
        seconds=0.3,
        fps=10,
        dt=0.01,
        key=key,
        overwrite=True,
        progress=False,
    )
    assert res.frames == 4 and pov.load_export(tmp_path)["complete"] is True
    assert (tmp_path / "notes.txt").read_text() == "keep me\n"
    assert (tmp_path / "render" / "poster.png").read_bytes() == b"poster"
    assert not (tmp_path / ".flagsim.lock").exists()


@pytest.mark.parametrize(
    "field, value",
    [("frames", 1_000_000_000), ("frames", "12"), ("fps", -1), ("width", 1.5), ("height", None)],
)
def test_render_names_a_damaged_manifest_field_without_reading_on(tmp_path, field, value):
    pov.export(StandInSim(), tmp_path, seconds=0.2, fps=10, dt=0.01, progress=False)
    m = json.loads((tmp_path / "export.json").read_text())
    m[field] = value
    (tmp_path / "export.json").write_text(json.dumps(m))
    with pytest.raises(pov.ExportConflict, match=rf"{field} should be .*--overwrite"):
        pov.load_export(tmp_path)


def test_cli_refuses_an_empty_out_in_one_line(capsys):
    from flagsim import cli

    assert cli.main(["run", "paper", "--out", "", "--seconds", "0.1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["flagsim: error: out should be a folder path, got ''"]
