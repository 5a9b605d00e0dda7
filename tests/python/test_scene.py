"""Scenes: validation on assignment, TOML loading, built-ins, pickling, lazy imports."""

import pickle
import subprocess
import sys

import flagsim
import numpy as np
import pytest

BAD_VALUES = [
    ("flag", "rows", 1, r"flag.rows should be >= 2, got 1"),
    ("flag", "cols", 0, r"flag.cols should be >= 2, got 0"),
    ("flag", "width", -1.0, r"flag.width should be in \(0, 1e\+06\] m, got -1"),
    ("flag", "height", float("nan"), r"flag.height should be in \(0, 1e\+06\] m, got nan"),
    ("flag", "areal_density", 0.0, r"flag.areal_density should be finite and > 0, got 0"),
    ("flag", "stretch_stiffness", -5.0, r"flag.stretch_stiffness should be finite and >= 0"),
    ("flag", "damping", float("inf"), r"flag.damping should be finite and >= 0, got inf"),
    (
        "flag",
        "pin",
        "left",
        r'flag.pin should be one of "pole", "grommets", "top", "none", got "left"',
    ),
    (
        "flag",
        "pinned_vertices",
        [0, 88],
        r"flag.pinned_vertices\[1\] should be a vertex index in \[0, 87\], got 88",
    ),
    ("flag", "origin", (0, float("nan"), 0), r"flag.origin should be finite"),
    (
        "drag",
        "model",
        "magic",
        r'drag.model should be one of "paper", "relative", "triangle", got "magic"',
    ),
    ("drag", "coefficient", -1.0, r"drag.coefficient should be finite and >= 0, got -1"),
    (
        "integrator",
        "method",
        "rk4",
        r'integrator.method should be one of "explicit", "implicit", got "rk4"',
    ),
    ("integrator", "safety", 1.5, r"integrator.safety should be in \(0, 1\], got 1.5"),
    ("integrator", "cg_tolerance", 0.0, r"integrator.cg_tolerance should be in \(0, 1\), got 0"),
    (
        "integrator",
        "preconditioner",
        "ilu",
        r'integrator.preconditioner should be one of "auto", "jacobi", "multigrid", "ssor", '
        r'got "ilu"',
    ),
    ("integrator", "max_strain", -1.0, r"integrator.max_strain should be finite and > 0"),
    ("air", "model", "wind", r'air.model should be one of "none", "uniform", "grid", got "wind"'),
    ("air", "density", -1.2, r"air.density should be finite and >= 0, got -1.2"),
    ("flag", "imperfection", -0.5, r"flag.imperfection should be finite and >= 0, got -0.5"),
    ("flag", "imperfection_seed", -1, r"flag.imperfection_seed should be in \[0, 4294967295\]"),
    (
        "air",
        "wind",
        [(1.0, (1, 0, 0)), (0.5, (2, 0, 0))],
        r"air.wind\[1\].time should be > the previous key's time 1",
    ),
    ("air", "wind", (1, 2), r"air.wind\[0\] should be a pair \(time, \(vx, vy, vz\)\)"),
    ("air", "wind", (float("inf"), 0, 0), r"air.wind\[0\].velocity should be finite"),
]


@pytest.mark.parametrize("section,key,value,message", BAD_VALUES)
def test_bad_values_raise_naming_the_parameter_and_change_nothing(section, key, value, message):
    scene = flagsim.Scene.paper()
    part = getattr(scene, section)
    before = getattr(part, key)
    # a value of the wrong type (not a pair where a keyframe goes) may be a TypeError
    with pytest.raises((ValueError, TypeError), match=message):
        setattr(part, key, value)
    assert getattr(part, key) == before


@pytest.mark.parametrize(
    "key,value,message",
    [
        ("dt", 0.0, r"dt should be finite and > 0, got 0"),
        ("dt", -0.01, r"dt should be finite and > 0, got -0.01"),
        ("gravity", (0, float("nan"), 0), r"gravity should be finite"),
        ("gravity", (0, 1), r"gravity should be a sequence of 3 numbers"),
    ],
)
def test_bad_top_level_values(key, value, message):
    scene = flagsim.Scene.paper()
    with pytest.raises(ValueError, match=message):
        setattr(scene, key, value)


def test_wind_accepts_constant_or_keyframes_and_reads_back_keyframes():
    air = flagsim.Scene.paper().air
    air.wind = (3, 0, 1)
    assert air.wind == [(0.0, (3.0, 0.0, 1.0))]
    air.wind = [(0, (1, 0, 0)), (2.5, (4, 0, 0))]
    assert air.wind == [(0.0, (1.0, 0.0, 0.0)), (2.5, (4.0, 0.0, 0.0))]


def test_wind_keyframes_are_interpolated_in_time():
    s = flagsim.Scene.paper()
    s.air.model = "uniform"
    s.air.wind = [(0.0, (0.0, 0.0, 0.0)), (1.0, (4.0, 0.0, 0.0))]
    sim = flagsim.Simulation(s)
    sim.step(25)
    assert sim.air_velocity([[0.0, 0.0, 0.0]])[0, 0] == pytest.approx(1.0)


def test_load_toml(tmp_path):
    f = tmp_path / "windy.toml"
    f.write_text("""
base = "paper"
dt = 0.005
gravity = [0.0, -9.0, 0.0]
[flag]
rows = 5
cols = 7
pin = "grommets"
[air]
wind = [[0.0, [1.0, 0.0, 0.0]], [2.0, [8.0, 0.0, 1.0]]]
[integrator]
method = "explicit"
""")
    s = flagsim.Scene.load(f)
    assert s.name == "windy" and s.dt == 0.005 and s.gravity == (0.0, -9.0, 0.0)
    assert (s.flag.rows, s.flag.cols, s.flag.pin) == (5, 7, "grommets")
    assert s.flag.height == flagsim.Scene.paper().flag.height  # from the base scene
    assert s.air.wind[1] == (2.0, (8.0, 0.0, 1.0))
    sim = flagsim.Simulation(s)
    assert sim.pinned.sum() == 2


@pytest.mark.parametrize(
    "text,message",
    [
        ("[flag]\nrowz = 3\n", r"unknown key 'rowz' in section \[flag\]; known keys: rows, cols"),
        ("colour = 'red'\n", r"unknown key 'colour' in the top level"),
        ("[flagg]\nrows = 3\n", r"unknown key 'flagg' in the top level"),
        ("[flag]\nrows = 1\n", r"flag.rows should be >= 2, got 1"),
        ("[flag]\nrows = 'eight'\n", r"flag.rows should be an integer, got 'eight'"),
        ("base = 'nope'\n", r"unknown scene 'nope'; built-in scenes are: paper"),
        ("[flag\n", r"not valid TOML"),
    ],
)
def test_load_toml_errors_name_key_and_section(tmp_path, text, message):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ValueError, match=message):
        flagsim.Scene.load(f)


def test_missing_file_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="scene file not found"):
        flagsim.Scene.load(tmp_path / "nope.toml")


def test_builtins_and_named():
    b = flagsim.Scene.builtins()
    assert "paper" in b and all(isinstance(d, str) and d for d in b.values())
    assert flagsim.Scene.named("paper").flag.rows == 8
    with pytest.raises(ValueError, match="unknown scene 'x'; built-in scenes are: paper"):
        flagsim.Scene.named("x")


def test_round_trip_through_dict_and_pickle():
    s = flagsim.Scene.paper()
    s.flag.rows = 9
    s.air.wind = [(0.0, (1.0, 0.0, 0.0)), (1.0, (2.0, 0.0, 0.0))]
    for t in (pickle.loads(pickle.dumps(s)), flagsim.Scene.from_dict(s.to_dict())):
        assert t.to_dict() == s.to_dict()
    assert "rows=9" in repr(s)


def test_import_loads_no_cli_plotting_or_rendering_library():
    # nor the optional viewer (polyscope) or USD (pxr): they load when used
    code = (
        "import sys, flagsim; flagsim.Simulation(flagsim.Scene.paper()).step(2); bad = [m for m in "
        "('matplotlib', 'tqdm', 'imageio', 'flagsim.cli', 'polyscope', 'pxr') "
        "if m in sys.modules]; print(','.join(bad))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_example_scene_files_load():
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[2] / "examples" / "scenes"
    files = sorted(root.glob("*.toml"))
    assert files
    for f in files:
        flagsim.Simulation(flagsim.Scene.load(f)).step(2)


def _droop_degrees(sim):
    """Angle from the pole edge to the free edge below the horizontal (mean of each column)."""
    x = sim.positions.reshape(sim.scene.flag.rows, sim.scene.flag.cols, 3)
    d = x[:, -1].mean(axis=0) - x[:, 0].mean(axis=0)
    return float(np.degrees(np.arctan2(-d[1], np.hypot(d[0], d[2]))))


def _still_paper(imperfection=None):
    s = flagsim.Scene.paper()
    s.air.wind = (0.0, 0.0, 0.0)
    s.air.fans = []
    if imperfection is not None:
        s.flag.imperfection = imperfection
    return s


def test_still_air_paper_flag_hangs_along_its_pole():
    # Issue 24 item 6: wind and fans off, the flag must not stay sticking out on the unstable
    # equilibrium of its mirror symmetry; a perfectly flat one does (the imperfection is what
    # breaks the symmetry, docs/design.md "Still air").
    hung = flagsim.Simulation(_still_paper())
    hung.step(1000)
    assert _droop_degrees(hung) > 60.0
    flat = flagsim.Simulation(_still_paper(imperfection=0.0))
    flat.step(1000)
    assert _droop_degrees(flat) < 10.0
    assert np.all(flat.positions[:, 2] == 0.0)  # nothing else breaks the symmetry


def test_imperfection_offsets_unpinned_masses_out_of_plane_within_its_bound():
    s = flagsim.Scene.paper()
    rest = flagsim.Simulation(_still_paper(imperfection=0.0)).positions.copy()
    sim = flagsim.Simulation(s)
    dz = sim.positions[:, 2] - rest[:, 2]
    pinned = np.arange(s.flag.rows) * s.flag.cols  # pin "pole": the first column
    assert np.all(dz[pinned] == 0.0)
    free = np.setdiff1d(np.arange(len(dz)), pinned)
    assert np.all(np.abs(dz) <= s.flag.imperfection)
    assert np.abs(dz[free]).max() > 0.5 * s.flag.imperfection
    assert np.all(sim.positions[:, :2] == rest[:, :2])
    again = flagsim.Simulation(s).positions
    assert again.tobytes() == sim.positions.tobytes()  # seeded: same bytes
    s.flag.imperfection_seed = 7
    assert not np.array_equal(flagsim.Simulation(s).positions, sim.positions)
