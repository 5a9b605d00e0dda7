"""mesh2 export: parse-back in POV-Ray's frame, winding vs normals, validation, atomic writes."""

import os
import re

import flagsim
import flagsim.povray as pov
import numpy as np
import pytest
from _standin import StandInSim


def parse_mesh2(text):
    """{'vertex_vectors': (N, 3), 'normal_vectors': (N, 3), 'uv_vectors': (N, 2),
    'face_indices': (T, 3)} read from mesh2 text, checking each block's declared count."""
    out = {"name": re.search(r"#declare\s+(\w+)\s*=\s*mesh2", text).group(1)}
    for block in ("vertex_vectors", "normal_vectors", "uv_vectors", "face_indices"):
        body = re.search(block + r"\s*\{([^}]*)\}", text).group(1)
        count = int(body.split(",", 1)[0])
        rows = [[float(x) for x in v.split(",")] for v in re.findall(r"<([^>]*)>", body)]
        assert len(rows) == count, block
        out[block] = np.array(rows)
    return out


@pytest.fixture(params=["paper", "standin"])
def moved_sim(request):
    """The paper's flag after 0.5 s in a wind turned 27 degrees out of its plane (so z varies),
    or the stand-in's travelling wave."""
    if request.param == "paper":
        from flagsim.scene import from_dict

        sim = flagsim.Simulation(
            from_dict({"base": "paper", "air": {"wind": [[0.0, [2.0, 0.0, 1.0]]]}})
        )
        sim.step(50)
        return sim
    sim = StandInSim(rows=11, cols=17, amplitude=0.4)
    sim.step(37)
    return sim


def test_parses_back_to_positions_after_undoing_handedness(tmp_path, moved_sim):
    sim = moved_sim
    assert np.abs(sim.positions[:, 2]).max() > 1e-3  # z matters: the flag has left its plane
    path = tmp_path / "flag.inc"
    pov.write_mesh2(sim, path)
    m = parse_mesh2(path.read_text())
    assert m["name"] == "FlagMesh"
    x = m["vertex_vectors"] * [1, 1, -1]  # undo z -> -z
    assert np.abs(x - sim.positions).max() < 1e-6
    assert np.abs(m["uv_vectors"] - sim.uv).max() < 1e-6
    assert np.abs(m["normal_vectors"] * [1, 1, -1] - sim.normals).max() < 1e-5
    assert m["face_indices"].shape == sim.triangles.shape
    # Each file face is the sim's face with two corners swapped (the mirror's winding flip).
    assert np.array_equal(m["face_indices"].astype(int), sim.triangles[:, [0, 2, 1]])


def test_winding_in_file_agrees_with_file_normals(tmp_path, moved_sim):
    sim = moved_sim
    pov.write_mesh2(sim, tmp_path / "f.inc")
    m = parse_mesh2((tmp_path / "f.inc").read_text())
    v, n, f = m["vertex_vectors"], m["normal_vectors"], m["face_indices"].astype(int)
    face = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    corner = n[f].sum(axis=1)
    cos = np.einsum("ij,ij->i", face, corner) / (
        np.linalg.norm(face, axis=1) * np.linalg.norm(corner, axis=1)
    )
    assert cos.min() > 0.5  # every face, not just on average


def test_render_positions_are_preferred_with_their_own_normals(tmp_path):
    sim = StandInSim(rows=5, cols=7)
    sim.render_positions = sim.positions + [0.0, 0.0, 0.1] * sim.uv[:, :1]  # a visual shear
    pov.write_mesh2(sim, tmp_path / "f.inc")
    m = parse_mesh2((tmp_path / "f.inc").read_text())
    assert np.abs(m["vertex_vectors"] * [1, 1, -1] - sim.render_positions).max() < 1e-6
    expected = pov.vertex_normals(sim.render_positions, sim.triangles)
    assert np.abs(m["normal_vectors"] * [1, 1, -1] - expected).max() < 1e-5
    sim.render_positions = None  # None: draw the simulated flag
    pov.write_mesh2(sim, tmp_path / "g.inc")
    g = parse_mesh2((tmp_path / "g.inc").read_text())
    assert np.abs(g["vertex_vectors"] * [1, 1, -1] - sim.positions).max() < 1e-6


def test_invalid_meshes_and_names_raise_value_errors(tmp_path):
    sim = StandInSim(rows=3, cols=3)
    sim.normals = sim.normals[:5]
    with pytest.raises(ValueError, match=r"normals should be 9 x 3 \(one per vertex\), got 5 x 3"):
        pov.write_mesh2(sim, tmp_path / "a.inc")
    sim = StandInSim(rows=3, cols=3)
    sim.positions[4, 2] = np.inf
    with pytest.raises(ValueError, match=r"positions should be finite, got inf at row 4"):
        pov.write_mesh2(sim, tmp_path / "a.inc")
    sim = StandInSim(rows=3, cols=3)
    for name in ("mesh2", "flag", "My Flag", 'A"B'):
        with pytest.raises(ValueError, match=r"name should be a POV-Ray identifier"):
            pov.write_mesh2(sim, tmp_path / "a.inc", name=name)
    assert os.listdir(tmp_path) == []


def test_write_is_atomic_and_failures_are_os_errors(tmp_path):
    sim = StandInSim(rows=4, cols=4)
    with pytest.raises(FileNotFoundError) as e:
        pov.write_mesh2(sim, tmp_path / "missing" / "f.inc")
    assert e.value.filename == str(tmp_path / "missing" / "f.inc")
    (tmp_path / "taken.inc").mkdir()  # rename over a folder fails after the whole write
    with pytest.raises(OSError):
        pov.write_mesh2(sim, tmp_path / "taken.inc")
    assert sorted(os.listdir(tmp_path)) == ["taken.inc"]  # no temporary file left behind
