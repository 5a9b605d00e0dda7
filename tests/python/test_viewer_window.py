"""The viewer drawn off-screen (polyscope through EGL, software GL here): the flag's colours are
where the camera projects the flag, a wind change changes the picture, and `flagsim view
--screenshot` writes a PNG. Where no off-screen OpenGL works the tests say so and skip (fail
under CI, which installs it); the probe runs once, in a child process, as a broken driver may
crash instead of failing."""

import os

import flagsim
import numpy as np
import pytest
from _optional import missing, require
from flagsim import cli, viewer

WIDTH, HEIGHT = 480, 360


@pytest.fixture(scope="module")
def gl():
    require(viewer.probe_headless())


def run(ctrl, offscreen, frames, steps_per_frame=4):
    for _ in range(frames):
        ctrl.step_frame(steps_per_frame, wall_seconds=0.04)
        offscreen.render()
    return offscreen.image()


def red(image):
    """The built-in flag's red under any shading: red well above green and blue."""
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (r > 80) & (r > 2 * g) & (r > 2 * b)


def flag_mask(pixels, triangles, shape):
    """Pixels whose centre lies inside a projected triangle."""
    mask = np.zeros(shape, dtype=bool)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    px, py = cols + 0.5, rows + 0.5
    for a, b, c in pixels[triangles]:
        lo = np.floor(np.minimum(np.minimum(a, b), c)).astype(int)
        hi = np.ceil(np.maximum(np.maximum(a, b), c)).astype(int) + 1
        sl = (slice(max(lo[1], 0), max(hi[1], 0)), slice(max(lo[0], 0), max(hi[0], 0)))
        x, y = px[sl], py[sl]
        d = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1])
        if abs(d) < 1e-12:
            continue
        l1 = ((b[1] - c[1]) * (x - c[0]) + (c[0] - b[0]) * (y - c[1])) / d
        l2 = ((c[1] - a[1]) * (x - c[0]) + (a[0] - c[0]) * (y - c[1])) / d
        mask[sl] |= (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
    return mask


def grow(mask, n):
    """The mask dilated by n pixels (a square neighbourhood)."""
    out = mask.copy()
    for _ in range(n):
        m = out.copy()
        m[1:] |= out[:-1]
        m[:-1] |= out[1:]
        m[:, 1:] |= out[:, :-1]
        m[:, :-1] |= out[:, 1:]
        out = m
    return out


def test_the_flag_is_drawn_where_the_camera_projects_it(gl):
    sim = flagsim.Simulation(flagsim.Scene.paper())
    ctrl = viewer.Controller(sim)
    off = viewer.Offscreen(ctrl, width=WIDTH, height=HEIGHT, panel=False)
    image = run(ctrl, off, 25)  # 1 s of the paper scene
    assert image.shape == (HEIGHT, WIDTH, 3) and image.dtype == np.uint8
    pixels = off.project(ctrl.sim.render_positions)
    inside = flag_mask(pixels, np.asarray(sim.triangles), image.shape[:2])
    covered = inside.mean()
    assert 0.05 < covered < 0.9  # the camera frames the flag: a good part of the picture
    drawn = red(image)
    core = ~grow(~inside, 2)  # away from the silhouette, where a pixel may be either
    # the flag's red (its white cross covers ~30 %) fills the projected flag ...
    assert drawn[core].mean() > 0.55
    # ... and nowhere else: no red outside it
    assert drawn[~grow(inside, 2)].mean() < 1e-3
    # the cross: points of the white bar (u = 0.36) project onto light pixels
    uv = np.asarray(sim.uv)
    bar = (np.abs(uv[:, 0] - 0.36) < 0.03) & (np.abs(uv[:, 1] - 0.5) > 0.2)
    for c, r in pixels[bar].astype(int):
        if core[r, c]:
            assert image[r, c].min() > 120, (r, c, image[r, c])


def test_every_flag_of_a_scene_of_several_is_drawn(gl):
    # The gallery's row of four flags: each flag's projection is filled with its red, and the
    # camera frames them all.
    sim = flagsim.Simulation(flagsim.scene.resolve("flag_row"))
    ctrl = viewer.Controller(sim)
    off = viewer.Offscreen(ctrl, width=WIDTH, height=HEIGHT, panel=False)
    image = run(ctrl, off, 5)
    drawn = red(image)
    for i, f in enumerate(ctrl.sim.flags):
        pixels = off.project(f.render_positions)
        inside = flag_mask(pixels, np.asarray(f.triangles), image.shape[:2])
        core = ~grow(~inside, 2)
        assert core.sum() > 50, f"flag {i} is (nearly) out of the picture"
        assert drawn[core].mean() > 0.5, f"flag {i}"


def test_turning_the_wind_changes_the_picture(gl):
    # Three runs from the same start: two identical ones give the same picture (the drawing is
    # deterministic), the one with the wind turned a quarter turn after 1 s (+x -> +z, towards
    # the camera, which stands on the flag's +z side) does not: the flag streams towards the
    # camera, seen nearly end-on, and its picture shrinks to where the new state projects.
    pictures, areas = [], []
    for turn in (False, False, True):
        ctrl = viewer.Controller(flagsim.Simulation(flagsim.Scene.paper()))
        off = viewer.Offscreen(ctrl, width=WIDTH, height=HEIGHT, panel=False)
        run(ctrl, off, 25)
        if turn:
            ctrl.set_wind(direction=90.0)
        pictures.append(run(ctrl, off, 38))  # 1.5 s more
        areas.append(red(pictures[-1]).sum())
        inside = flag_mask(
            off.project(ctrl.sim.render_positions),
            np.asarray(ctrl.sim.triangles),
            pictures[-1].shape[:2],
        )
        assert red(pictures[-1])[~grow(inside, 2)].mean() < 1e-3
    assert np.array_equal(pictures[0], pictures[1])
    changed = red(pictures[0]) != red(pictures[2])
    assert changed.sum() > 0.5 * areas[0]
    assert areas[2] < 0.6 * areas[0]


def test_view_screenshot_writes_the_last_frame_as_png(gl, tmp_path, capsys):
    import imageio.v3 as iio

    out = tmp_path / "shots" / "view.png"
    code = cli.main(["view", "paper", "--screenshot", str(out), "--frames", "5", "--quiet"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    assert stdout.strip() == str(out) and err == ""
    image = iio.imread(out)
    assert image.shape[:2] == (540, 960) and red(image).sum() > 1000
    assert os.listdir(out.parent) == ["view.png"]  # no temporary file left behind
    # the panel is drawn on the right: its pixels differ from a picture without it
    plain = tmp_path / "plain.png"
    code = cli.main(
        ["view", "paper", "--screenshot", str(plain), "--frames", "5", "--no-panel", "-q"]
    )
    assert code == 0
    right = slice(960 - viewer.PANEL_WIDTH, 960)
    assert np.mean(iio.imread(plain)[:, right] != image[:, right]) > 0.2


def test_view_refuses_bad_input_before_any_work(tmp_path, capsys):
    code = cli.main(["view", "paper", "--screenshot", str(tmp_path / "a.jpg")])
    assert code == 2 and "screenshot should be a .png file" in capsys.readouterr().err
    code = cli.main(["view", "paper", "--screenshot", str(tmp_path / "a.png"), "--frames", "0"])
    assert code == 2 and "--frames should be >= 1, got 0" in capsys.readouterr().err
    code = cli.main(["view", "nowhere", "--screenshot", str(tmp_path / "a.png")])
    assert code == 2 and "unknown scene 'nowhere'" in capsys.readouterr().err
    code = cli.main(["view", "paper", "--frames", "0"])
    assert code == 2 and "--frames applies to --screenshot only" in capsys.readouterr().err
    code = cli.main(["view", "paper", "--screenshot", str(tmp_path / "a.png"), "--width", "500"])
    assert code == 2 and "width should be >= 660 pixels with the panel, got 500" in (
        capsys.readouterr().err
    )
    assert list(tmp_path.iterdir()) == []


def test_the_live_window_without_a_display_says_what_to_do(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code = cli.main(["view", "paper"])
    err = capsys.readouterr().err
    assert code == 1 and "no display" in err and "--screenshot" in err


def test_view_help_lists_every_keyboard_shortcut(capsys):
    with pytest.raises(SystemExit):
        cli.main(["view", "--help"])
    out = capsys.readouterr().out
    for key, what, _, _ in viewer.KEYS:
        assert f"  {key:<6} {what}" in out


def test_a_texture_is_mapped_by_uv_with_its_top_row_at_the_top(gl, tmp_path):
    # top half blue, bottom half green: the flag's top (v = 1) must be drawn blue, as POV-Ray
    # maps the same image (image_map: the picture's top at v = 1)
    import imageio.v3 as iio

    image = np.zeros((64, 64, 3), dtype=np.uint8)
    image[:32, :, 2] = 255
    image[32:, :, 1] = 255
    iio.imwrite(tmp_path / "two.png", image)
    sim = flagsim.Simulation(flagsim.Scene.paper())
    ctrl = viewer.Controller(sim)
    off = viewer.Offscreen(
        ctrl, width=WIDTH, height=HEIGHT, texture=tmp_path / "two.png", panel=False
    )
    picture = run(ctrl, off, 5)
    pixels = off.project(ctrl.sim.render_positions).astype(int)
    uv = np.asarray(sim.uv)
    inside = flag_mask(off.project(ctrl.sim.render_positions), sim.triangles, picture.shape[:2])
    core = ~grow(~inside, 3)
    rgb = picture.astype(int)
    blue = (rgb[..., 2] > 2 * rgb[..., 1]) & (rgb[..., 2] > 60)
    green = (rgb[..., 1] > 2 * rgb[..., 2]) & (rgb[..., 1] > 60)
    top, bottom = uv[:, 1] > 0.75, uv[:, 1] < 0.25
    checked = 0
    for (c, r), t, b in zip(pixels, top, bottom):
        if core[r, c] and (t or b):
            assert (blue if t else green)[r, c], (r, c, picture[r, c])
            checked += 1
    assert checked > 10
    assert not red(picture).any()


def test_every_shortcut_names_keys_polyscope_has():
    # the live window looks them up by name (polyscope.imgui.ImGuiKey_<name>); a typo would only
    # show when the window runs
    require(missing("polyscope", "viewer"))
    import polyscope.imgui as psim

    for _, _, _, names in viewer.KEYS:
        for name in names:
            assert isinstance(getattr(psim, "ImGuiKey_" + name), psim.ImGuiKey)
