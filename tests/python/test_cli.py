"""The flagsim command: help, scenes, run (with and without rendering), and its user errors."""

import subprocess
import sys

import flagsim
import pytest
from _optional import needs_povray
from flagsim import cli


def flagsim_cmd(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_help_lists_commands_and_every_command_has_help(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for name in ("run", "render", "scenes", "study"):
        assert f"  {name}  " in out or f"  {name} " in out
    for name in cli.COMMANDS:
        with pytest.raises(SystemExit) as e:
            cli.main([name, "--help"])
        assert e.value.code == 0
        assert f"usage: flagsim {name}" in capsys.readouterr().out
    assert flagsim_cmd(capsys)[0] == 2  # no command: help on stderr, usage error
    code, _, err = flagsim_cmd(capsys, "fly")
    assert code == 2 and f"unknown command 'fly' (choose from {', '.join(cli.COMMANDS)})" in err


def test_scenes_lists_builtins_with_descriptions(capsys):
    code, out, _ = flagsim_cmd(capsys, "scenes")
    assert code == 0
    lines = [line for line in out.strip().splitlines() if line and not line.endswith(":")]
    listed = {**flagsim.Scene.builtins(), **flagsim.Scene.gallery()}
    assert "flag_row" in flagsim.Scene.gallery()  # the gallery's row of flags is listed
    assert len(lines) == len(listed)
    for name, summary in listed.items():
        assert any(line.split()[0] == name and line.endswith(summary) for line in lines)


def test_gallery_scene_runs_by_name(capsys, tmp_path):
    scene = flagsim.scene.resolve("flag_row")
    assert scene.name == "flag_row" and len(scene.flags) == 4
    code, _, err = flagsim_cmd(
        capsys, "run", "flag_row", "--seconds", "0.02", "--fps", "50", "--out", str(tmp_path / "o")
    )
    assert code == 0, err
    frame = (tmp_path / "o" / "frames" / "flag_00001.inc").read_text()
    assert f"vertex_vectors {{\n    {sum(f.rows * f.cols for f in scene.flags)}," in frame


def test_run_without_render_exports_frames(capsys, tmp_path):
    name = "paper"
    out = tmp_path / "out dir"
    code, stdout, err = flagsim_cmd(
        capsys, "run", name, "--seconds", "0.2", "--fps", "10", "--out", str(out), "--quiet"
    )
    assert code == 0, err
    assert stdout.strip() == str(out) and err == ""
    assert sorted(p.name for p in (out / "frames").iterdir()) == [
        "flag_00000.inc",
        "flag_00001.inc",
        "flag_00002.inc",
    ]
    assert (out / "flag.pov").is_file() and (out / "flag.ini").is_file()
    # the same command again resumes: every frame is kept
    code, _, err = flagsim_cmd(
        capsys, "run", name, "--seconds", "0.2", "--fps", "10", "--out", str(out)
    )
    assert code == 0 and "3 frames" in err and "0 written, 3 kept" in err


def test_unknown_scene_lists_the_known_ones(capsys, tmp_path):
    code, out, err = flagsim_cmd(capsys, "run", "no_such_scene", "--out", str(tmp_path / "o"))
    assert code == 2 and out == ""
    assert err.startswith(
        "flagsim: error: unknown scene 'no_such_scene': the built-in scenes "
        "are " + ", ".join(sorted(flagsim.Scene.builtins()))
    )
    assert "Traceback" not in err and not (tmp_path / "o").exists()


def test_bad_toml_key_is_reported_as_scene_load_reports_it(capsys, tmp_path):
    toml = tmp_path / "bad.toml"
    toml.write_text("[flag]\nrows = 8\ncolour = 'red'\n")
    with pytest.raises(ValueError) as direct:
        flagsim.Scene.load(str(toml))
    assert "colour" in str(direct.value) and "flag" in str(direct.value)
    code, _, err = flagsim_cmd(capsys, "run", str(toml), "--out", str(tmp_path / "o"))
    assert code == 2
    assert err == f"flagsim: error: {direct.value}\n"
    code, _, err = flagsim_cmd(
        capsys, "run", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "o")
    )
    assert code == 2 and "scene file" in err and "missing.toml' not found" in err


def test_bad_values_and_folders_are_user_errors(capsys, tmp_path):
    name = "paper"
    code, _, err = flagsim_cmd(capsys, "run", name, "--out", str(tmp_path), "--fps", "0")
    assert code == 2 and "fps should be finite and > 0, got 0.0" in err
    code, _, err = flagsim_cmd(
        capsys, "run", name, "--out", str(tmp_path), "--texture", str(tmp_path / "flag.bmp")
    )
    assert code == 2 and "texture should be an image file" in err
    code, _, err = flagsim_cmd(capsys, "render", str(tmp_path / "nothing"))
    assert code == 2 and "is not a flagsim export" in err and "Traceback" not in err
    # every command's bad input goes through the one funnel: one line, exit 2
    code, _, err = flagsim_cmd(capsys, "study", "stability", "--out", str(tmp_path), "--jobs", "0")
    assert code == 2 and err.strip() == "flagsim: error: --jobs should be >= 1, got 0"
    code, _, err = flagsim_cmd(
        capsys, "run", name, "--out", str(tmp_path / "o"), "--seconds", "1e308"
    )
    assert code == 2 and len(err.strip().splitlines()) == 1 and "seconds" in err


@pytest.mark.parametrize(
    "name, content",
    [
        ("flag.png", b"not a picture, just text\n"),  # text named .png
        ("flag.jpg", b"\x89PNG\r\n\x1a\n" + bytes(40)),  # a PNG named .jpg
        ("flag.gif", b""),  # empty
    ],
)
def test_a_texture_povray_cannot_read_is_rejected_before_any_work(
    capsys, tmp_path, monkeypatch, name, content
):
    import flagsim

    (tmp_path / name).write_bytes(content)
    built = []
    monkeypatch.setattr(flagsim, "Simulation", lambda *a, **k: built.append(a))
    out = tmp_path / "o"
    code, _, err = flagsim_cmd(
        capsys, "run", "paper", "--out", str(out), "--texture", str(tmp_path / name), "--render"
    )
    assert code == 2 and "does not start like one" in err and "Traceback" not in err
    assert built == [] and not out.exists()  # no simulation built, no folder made


def test_missing_povray_fails_before_simulating(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("FLAGSIM_POVRAY", "povray-not-installed")
    name = "paper"
    code, _, err = flagsim_cmd(capsys, "run", name, "--out", str(tmp_path / "o"), "--render")
    assert code == 1
    assert "install the Debian package 'povray'" in err
    assert not (tmp_path / "o").exists()


@needs_povray
def test_run_render_gif_prints_the_animation_path(capsys, tmp_path):
    import imageio.v3 as iio

    name = "paper"
    out = tmp_path / "anim"
    code, stdout, err = flagsim_cmd(
        capsys,
        "run",
        name,
        "--seconds",
        "0.1",
        "--fps",
        "20",
        "--out",
        str(out),
        "--render",
        "--gif",
        "--width",
        "64",
        "--height",
        "48",
        "--quiet",
        "--jobs",
        "3",
    )
    assert code == 0, err
    assert stdout.strip() == str(out / "flag.gif") and err == ""
    assert iio.imread(out / "flag.gif", index=None).shape[:3] == (3, 48, 64)


def test_python_dash_m_flagsim_and_lazy_imports():
    proc = subprocess.run(
        [sys.executable, "-m", "flagsim", "--help"], capture_output=True, text=True
    )
    assert proc.returncode == 0 and "usage: flagsim" in proc.stdout
    # python -m flagsim.study is `flagsim study` (study/__main__.py)
    proc = subprocess.run(
        [sys.executable, "-m", "flagsim.study", "--help"], capture_output=True, text=True
    )
    assert proc.returncode == 0 and proc.stdout.startswith("usage: flagsim study"), proc.stderr
    code = (
        "import sys, flagsim; a = 'flagsim.povray' in sys.modules; flagsim.povray.export; "
        "print(a, sorted(m for m in ('tqdm', 'imageio', 'matplotlib', 'flagsim.cli') "
        "if m in sys.modules))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.stdout.strip() == "False []", proc.stderr
