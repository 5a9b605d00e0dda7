"""flagsim sweep without a cluster (issue 25): --vary parsing through the scene's own setters,
folder names, resume and the files a task hands to the head. The cluster runs are in
test_distributed.py. Dask is hidden here: the local path must not need it."""

import csv
import json
import os
import sys

import flagsim
import pytest
from _optional import needs_povray
from flagsim import cli, sweep
from flagsim.povray.lock import ExportLock
from flagsim.study import runner


@pytest.fixture(autouse=True)
def without_dask(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed: ImportError


def test_vary_values_are_toml_values_split_at_top_level_commas():
    assert sweep.parse_vary("air.wind=[2, 0, 0],[8,0,1]") == ("air.wind", [[2, 0, 0], [8, 0, 1]])
    assert sweep.parse_vary("dt=0.01,5e-3") == ("dt", [0.01, 0.005])
    assert sweep.parse_vary("integrator.method=implicit,'explicit'") == (
        "integrator.method",
        ["implicit", "explicit"],
    )
    assert sweep.parse_vary('name=a,"b,c",true') == ("name", ["a", "b,c", True])
    for bad, match in (
        ("air.wind", r"--vary should be KEY=V1,V2,\.\.\."),
        ("=1,2", r"--vary should be KEY=V1,V2"),
        ("flag.rows=4,,5", r"--vary flag.rows: a value is empty"),
        ("flag.rows=4,4.0,4", r"--vary flag.rows: a value is given twice"),
    ):
        with pytest.raises(ValueError, match=match):
            sweep.parse_vary(bad)


def test_settings_go_through_the_scene_setters_and_their_errors_name_the_key():
    scene = flagsim.Scene.paper()
    sweep.apply_settings(scene, {"air.wind": [8, 0, 1], "flag.rows": 5, "dt": 0.005})
    assert scene.air.wind == [(0.0, (8.0, 0.0, 1.0))] and scene.flag.rows == 5
    assert scene.dt == 0.005
    with pytest.raises(ValueError, match=r"^--vary flag\.rows=1: flag\.rows should be >= 2, got 1"):
        sweep.apply_settings(flagsim.Scene.paper(), {"flag.rows": 1})
    with pytest.raises(ValueError, match=r"^--vary flag\.k_s=300: unknown key 'k_s' in section"):
        sweep.apply_settings(flagsim.Scene.paper(), {"flag.k_s": 300})
    with pytest.raises(ValueError, match=r"^--vary air\.model=storm: air\.model should be"):
        sweep.apply_settings(flagsim.Scene.paper(), {"air.model": "storm"})


def test_folder_names_are_readable_safe_and_distinct():
    name = sweep.folder_name
    assert name({"air.wind": [5, 0, 0], "flag.stretch_stiffness": 300.0}) == (
        "air.wind=5_0_0,flag.stretch_stiffness=300"
    )
    assert name({"dt": 0.005, "integrator.adaptive": False}) == "dt=0.005,integrator.adaptive=false"
    assert name({"air.wind": [-8.5, 0, 1e-07]}) == "air.wind=-8.5_0_1e-07"
    # keyframes, characters no file system takes everywhere, and long names get a hash
    odd = [
        {"air.wind": [[0, [2, 0, 0]], [1, [8, 0, 1]]]},
        {"name": 'a/b:c*?"<>|\\'},
        {"name": "x" * 200},
        {"name": "ends with a dot."},
    ]
    for settings in odd:
        n = name(settings)
        assert n.endswith("-" + sweep.settings_hash(settings)) and len(n) <= sweep.NAME_MAX, n
        assert all(c.isalnum() or c in "._+=,-" for c in n), n
        assert not n.endswith(".")
    # names equal but for case (one folder on macOS and Windows) are told apart by their hashes
    combos = [{"name": "Flag"}, {"name": "flag"}, {"name": "other"}]
    names = sweep.folder_names(combos)
    assert len({n.casefold() for n in names}) == 3 and names[2] == "name=other"
    # distinct settings never share a folder, whatever their values
    combos = sweep.combinations(
        {"dt": [0.01, 0.005, 0.0025], "flag.rows": [5, 6], "x": ["a b", "a_b"]}
    )
    assert len(combos) == 12 and combos[0] == {"dt": 0.01, "flag.rows": 5, "x": "a b"}
    assert len({n.casefold() for n in sweep.folder_names(combos)}) == 12


def _sweep(capsys, out, *extra, rows="5,6"):
    code = cli.main(
        [
            "sweep",
            "paper",
            "--vary",
            "air.wind=[2,0,0],[8,0,1]",
            "--vary",
            f"flag.rows={rows}",
            "--seconds",
            "0.08",
            "--out",
            str(out),
            "--quiet",
            *extra,
        ]
    )
    return code, *capsys.readouterr()


def _rows(out):
    with open(out / sweep.INDEX, newline="") as f:
        return list(csv.DictReader(f))


def test_sweep_exports_every_combination_and_a_rerun_keeps_them(capsys, tmp_path):
    out = tmp_path / "sweep"
    code, stdout, err = _sweep(capsys, out)
    assert code == 0, err
    assert stdout.strip() == str(out)
    rows = _rows(out)
    names = [
        "air.wind=2_0_0,flag.rows=5",
        "air.wind=2_0_0,flag.rows=6",
        "air.wind=8_0_1,flag.rows=5",
        "air.wind=8_0_1,flag.rows=6",
    ]
    assert [r["id"] for r in rows] == names  # in combination order, whatever finished first
    assert [(r["air.wind"], r["flag.rows"]) for r in rows] == [
        ("[2, 0, 0]", "5"),
        ("[2, 0, 0]", "6"),
        ("[8, 0, 1]", "5"),
        ("[8, 0, 1]", "6"),
    ]
    for r, name in zip(rows, names):
        assert r["work"] == "export" and r["frames"] == "3" and r["attempts"] == "1"
        assert r["worker"] == "local" and r["returned"] == "0" and float(r["seconds"]) > 0
        manifest = json.loads((out / name / "export.json").read_text())
        scene = manifest["key"]["scene"]["scene"]
        assert manifest["complete"] and scene["flag"]["rows"] == int(r["flag.rows"])
        assert scene["air"]["wind"][0][1] == json.loads(r["air.wind"])
        assert sorted(p.name for p in (out / name / "frames").iterdir()) == [
            f"flag_0000{k}.inc" for k in range(3)
        ]
    # the flags differ: each combination really ran with its own settings
    texts = {(out / n / "frames" / "flag_00002.inc").read_text() for n in names}
    assert len(texts) == 4
    # the same command again resumes from the index: nothing runs
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*.inc")}
    assert _sweep(capsys, out)[0] == 0
    assert _rows(out) == rows
    # without the index, the folders that hold the same export are kept, not simulated again
    (out / sweep.INDEX).unlink()
    assert _sweep(capsys, out)[0] == 0
    kept = _rows(out)
    assert [r["work"] for r in kept] == ["kept"] * 4
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*.inc")} == before
    # more values for the same keys: only the new combinations run
    assert _sweep(capsys, out, rows="5,6,7")[0] == 0
    grown = _rows(out)
    assert [r["work"] for r in grown] == ["kept", "kept", "export", "kept", "kept", "export"]
    assert [r for r in grown if r["work"] == "kept"] == kept  # not run again
    # another key, another scene or other seconds: another sweep, refused in this folder
    for extra in (("--vary", "dt=0.01"), ("--seconds", "0.12")):
        code, _, err = _sweep(capsys, out, *extra)
        assert code == 2 and "holds a sweep of another scene, --seconds, --fps or other" in err


def test_sweep_input_errors_come_before_any_work(capsys, tmp_path):
    out = tmp_path / "s"
    for vary, message in (
        ("flag.k_s=100,300", "flagsim: error: --vary flag.k_s=100: unknown key 'k_s' in section"),
        ("flag.rows=1,5", "flagsim: error: --vary flag.rows=1: flag.rows should be >= 2, got 1"),
        ("dt=0.01,0.5", "flagsim: error: fps should be <= 1 / dt = 2"),
    ):
        code = cli.main(["sweep", "paper", "--vary", vary, "--out", str(out), "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and err.startswith(message), err
        assert not out.exists()
    code = cli.main(["sweep", "paper", "--vary", "dt=0.01", "--vary", "dt=0.02", "--out", str(out)])
    assert code == 2 and "--vary dt is given twice" in capsys.readouterr().err
    (out / "mine.txt").parent.mkdir(parents=True)
    (out / "mine.txt").write_text("a user's file")
    code = cli.main(["sweep", "paper", "--vary", "dt=0.01", "--out", str(out), "--seconds", "0"])
    err = capsys.readouterr().err
    assert code == 2 and "is not empty (mine.txt) and holds no flagsim sweep" in err
    code = cli.main(["sweep", "paper", "--vary", "dt=0.01", "--out", str(out), "--jobs", "2",
                     "--workers", "2"])  # fmt: skip
    assert code == 2 and "--jobs should not be given with --scheduler or --workers" in (
        capsys.readouterr().err
    )


def test_a_combination_that_keeps_failing_is_named_and_the_others_stay(capsys, tmp_path):
    out = tmp_path / "s"
    argv = ["sweep", "paper", "--vary", "integrator.method=explicit", "--seconds", "0.05"]
    argv += ["--out", str(out), "--quiet"]
    code = cli.main([*argv, "--vary", "integrator.adaptive=true,false"])
    err = capsys.readouterr().err
    # plain explicit steps above the stable step: Simulation refuses the scene in the task
    assert code == 1 and err.startswith(
        "flagsim: error: 1 of 2 sweep tasks failed (integrator.method=explicit,"
        "integrator.adaptive=false: ValueError: integrator.substeps should be >= "
    )
    assert "the 1 finished are in" in err and "run the same command again" in err
    rows = _rows(out)
    assert [r["id"] for r in rows] == ["integrator.method=explicit,integrator.adaptive=true"]
    # after dropping the failing value, the finished combination is not run again
    assert cli.main([*argv, "--vary", "integrator.adaptive=true"]) == 0
    assert _rows(out) == rows


def test_a_task_that_does_not_see_the_folder_returns_its_files(tmp_path):
    # the same task twice: once in the head's folder, once as a worker on another machine
    # would run it (another lock record in its folder of the same name): it then returns every
    # file, export.json first, and the head writes them: the same bytes.
    scene = flagsim.Scene.paper()
    settings = {"flag.rows": 5}
    spec_args = dict(
        base=flagsim.scene.to_dict(scene),
        source={"builtin": "paper"},
        seconds=0.05,
        fps=25.0,
        width=64,
        height=48,
        render=False,
        overwrite=False,
        threads=1,
    )
    case = {"id": "flag.rows=5", "settings": settings, "frames": 2, "have": "none"}
    here = tmp_path / "here"
    here.mkdir()
    with ExportLock(here) as lock:
        spec = sweep.SweepSpec(out=str(here), share=lock.record, **spec_args)
        assert sweep.run_task(dict(case), spec)["returned"] == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    foreign = {"pid": os.getpid() + 1, "host": "another-machine", "started": "x", "command": "y"}
    spec = sweep.SweepSpec(out=str(elsewhere), share=foreign, **spec_args)
    result = sweep.run_task(dict(case), spec)
    files = result.pop(runner.FILES)
    assert list(files)[0] == "flag.rows=5/export.json" and result["returned"] == len(files)
    assert not any(elsewhere.iterdir())  # the worker wrote nothing into the head's folder
    runner.write_files(str(elsewhere), files)
    made = sorted(p.relative_to(here) for p in here.rglob("*") if p.is_file())
    assert made == sorted(p.relative_to(elsewhere) for p in elsewhere.rglob("*") if p.is_file())
    for rel in made:
        assert (here / rel).read_bytes() == (elsewhere / rel).read_bytes(), rel
    with pytest.raises(ValueError, match="relative path inside its folder"):
        runner.write_files(str(elsewhere), {"../escape.txt": b"x"})


@needs_povray
def test_render_added_to_a_finished_sweep_renders_without_simulating_again(capsys, tmp_path):
    out = tmp_path / "s"
    argv = ["sweep", "paper", "--vary", "flag.rows=5", "--seconds", "0.04", "--out", str(out)]
    argv += ["--width", "64", "--height", "48", "--quiet"]
    assert cli.main(argv) == 0
    frame = out / "flag.rows=5" / "frames" / "flag_00001.inc"
    made = frame.stat().st_mtime_ns
    capsys.readouterr()
    assert cli.main([a for a in argv if a != "--quiet"] + ["--render"]) == 0
    err = capsys.readouterr().err
    # one bar, the head's, over tasks: the task (as on a worker) draws none of its own
    assert "sweep: 100%" in err and "1/1" in err
    assert "simulating" not in err and "rendering" not in err
    (row,) = _rows(out)
    assert row["work"] == "render" and row["rendered"] == "64x48"
    assert frame.stat().st_mtime_ns == made
    images = sorted((out / "flag.rows=5" / "render").glob("frame_*.png"))
    assert len(images) == 2 and (out / "flag.rows=5" / "flag.gif").is_file()
    assert cli.main([*argv, "--render"]) == 0  # and then it is done
    assert _rows(out) == [row]
