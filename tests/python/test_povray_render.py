"""Rendering with the real POV-Ray: no warnings, the flag where the camera says, the driver's
retry and failure reporting, GIF assembly, clear errors for missing programs."""

import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import flagsim
import flagsim.povray as pov
import numpy as np
import pytest
from _optional import needs_povray
from _standin import StandInSim, standin_scene
from test_povray_mesh import parse_mesh2


def red_mask(img):
    """Pixels of the built-in flag's red (0.72, 0.03, 0.05): nothing else in the scene is."""
    rgb = img[..., :3].astype(float) / 255.0
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (r > 0.25) & (r > 2.5 * g) & (r > 2.5 * b)


def project(points, text, width, height):
    """Pixel coordinates of POV-Ray-frame points through flag.pov's perspective camera."""

    def vec(name):
        return np.array(
            [float(c) for c in re.search(name + r" <([^>]*)>", text).group(1).split(",")]
        )

    loc, look = vec("location"), vec("look_at")
    angle = float(re.search(r"angle ([0-9.]+)", text).group(1))
    d = (look - loc) / np.linalg.norm(look - loc)
    right = np.cross([0.0, 1.0, 0.0], d)
    right /= np.linalg.norm(right)
    up = np.cross(d, right)
    rel = points - loc
    depth = rel @ d
    half_w = np.tan(np.radians(angle) / 2)
    half_h = half_w * height / width
    px = (0.5 + (rel @ right) / depth / (2 * half_w)) * width
    py = (0.5 - (rel @ up) / depth / (2 * half_h)) * height
    return np.stack([px, py], axis=1)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """The paper's flag in a wind turned out of its plane, exported into a folder whose name has
    spaces and POV-Ray syntax in it, four frames rendered at 80x60 by the default (process pool)
    driver."""
    from flagsim.scene import from_dict

    out = tmp_path_factory.mktemp("render") / 'my out; #declare "x'
    sim = flagsim.Simulation(
        from_dict({"base": "paper", "air": {"wind": [[0.0, [2.0, 0.0, 1.0]]]}})
    )
    pov.export(sim, out, seconds=0.3, fps=10, width=80, height=60, progress=False)
    result = pov.render(out, progress=False)
    return out, result


@needs_povray
def test_render_is_clean_and_the_flag_covers_its_projected_area(rendered):
    import imageio.v3 as iio

    out, result = rendered
    assert result.rendered == [0, 1, 2, 3] and result.diagnostics == {}
    img = iio.imread(result.images[3])
    assert img.shape[:2] == (60, 80)
    text = (out / "flag.pov").read_text()
    m = parse_mesh2((out / "frames" / "flag_00003.inc").read_text())
    xy = project(m["vertex_vectors"], text, 80, 60)
    f = m["face_indices"].astype(int)
    a, b, c = xy[f[:, 0]], xy[f[:, 1]], xy[f[:, 2]]
    cross = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    flag_share = 0.5 * np.abs(cross).sum() / (80 * 60)
    red = red_mask(img)
    # The built-in flag is red but for a white cross covering 29% of it.
    assert 0.03 < flag_share < 0.9
    assert 0.75 * 0.71 * flag_share < red.mean() < 1.15 * 0.71 * flag_share  # measured: 0.91
    # Red pixels lie where the camera projects the flag (with a pixel of slack) ...
    rows, cols = np.nonzero(red)
    lo, hi = xy.min(axis=0) - 1.5, xy.max(axis=0) + 1.5
    inside = (
        (cols + 0.5 >= lo[0])
        & (cols + 0.5 <= hi[0])
        & (rows + 0.5 >= lo[1])
        & (rows + 0.5 <= hi[1])
    )
    assert inside.mean() > 0.98
    # ... and not mirrored: the hoist (u = 0) projects to the left of the fly (u = 1).
    u = m["uv_vectors"][:, 0]
    assert xy[u < 0.01, 0].mean() < xy[u > 0.99, 0].mean()


@needs_povray
def test_povray_stderr_has_no_warnings_and_the_check_would_see_them(rendered, tmp_path):
    out, _ = rendered
    job = pov.FrameJob(
        frame=1,
        out_dir=str(out),
        image="render/check.png",
        povray=pov.find_povray(),
        width=80,
        height=60,
    )
    from flagsim.povray.render import povray_command, povray_env

    cmd = povray_command(job)
    proc = subprocess.run(cmd, cwd=out, env=povray_env(out), capture_output=True, text=True)
    assert proc.returncode == 0
    assert pov.povray_diagnostics(proc.stderr) == []
    assert "warning" not in proc.stderr.lower() and "error" not in proc.stderr.lower()
    assert "Persistence of Vision" in proc.stderr  # the banner is there: stderr was captured
    # Without the export's private configuration, POV-Ray complains, and the check sees it.
    env = dict(povray_env(out), HOME=str(tmp_path))
    proc = subprocess.run(cmd, cwd=out, env=env, capture_output=True, text=True)
    assert any("user configuration file" in line for line in pov.povray_diagnostics(proc.stderr))
    # A scene without assumed_gamma draws a parse warning, and the check sees that too.
    (out / "nogamma.pov").write_text(
        "#version 3.7;\ncamera { location -5*z look_at 0 }\n" "sphere { 0, 1 pigment { rgb 1 } }\n"
    )
    proc = subprocess.run(
        [cmd[0], "+Inogamma.pov", "+Orender/ng.png", *cmd[3:]],
        cwd=out,
        env=povray_env(out),
        capture_output=True,
        text=True,
    )
    assert any("assumed_gamma" in line for line in pov.povray_diagnostics(proc.stderr))


@needs_povray
def test_up_to_date_frames_are_kept_and_a_gif_is_assembled(rendered):
    import imageio.v3 as iio

    out, first = rendered
    again = pov.render(out, progress=False)
    assert again.rendered == [] and again.skipped == [0, 1, 2, 3]
    (out / "frames" / "flag_00002.inc").touch()  # a changed frame is rendered again
    os.utime(out / "frames" / "flag_00002.inc", ns=(2**62, 2**62))
    assert pov.render(out, progress=False, executor=ThreadPoolExecutor(2)).rendered == [2]
    gif = pov.make_gif(first.images, out / "flag.gif", fps=10)
    frames = iio.imread(gif, index=None)
    assert frames.shape[:3] == (4, 60, 80)
    assert iio.immeta(gif, index=0).get("duration") == 100  # ms per frame at 10 fps


@needs_povray
def test_a_worker_that_does_not_see_the_folder_asks_for_inputs_and_returns_the_image(
    rendered, tmp_path
):
    # A frame job names the head's lock record; a worker whose folder of that name holds no such
    # record (another machine) asks for the inputs, then renders them in a folder of its own and
    # returns the image: the same bytes as the image rendered in place. Images carry no render
    # time, so rendering a frame again gives the same file.
    from flagsim.povray import scenefiles
    from flagsim.povray.render import render_frame

    out, first = rendered
    record = {"pid": -1, "host": "another-machine", "started": "then", "command": "flagsim"}
    job = pov.FrameJob(
        frame=2,
        out_dir=str(out),
        image="render/elsewhere.png",
        povray="povray",
        width=80,
        height=60,
        share=record,
    )
    asked = render_frame(job)
    assert asked.needs_inputs and not asked.ok and not (out / job.image).exists()
    inputs = {
        name: (out / name).read_bytes()
        for name in (scenefiles.SCENE_FILE, scenefiles.frame_file(2))
    }
    done = render_frame(replace(job, inputs=inputs))
    assert done.ok and not (out / job.image).exists(), done.error
    in_place = render_frame(replace(job, image="render/again.png", share=None))
    assert in_place.ok and in_place.image is None
    assert done.image == (out / "render/again.png").read_bytes() == first.images[2].read_bytes()
    assert b"tIME" not in done.image and b"Render Date" not in done.image


def fake_worker(job):
    """Writes a correct-size PNG, but frame 1 fails on its first try and frame 2 always fails."""
    import imageio.v3 as iio

    marker = os.path.join(job.out_dir, f"tried_{job.frame}")
    first_try = not os.path.exists(marker)
    open(marker, "a").close()
    if job.frame == 2 or (job.frame == 1 and first_try):
        return pov.FrameResult(job.frame, False, "povray exited with 1: Parse Error: boom")
    iio.imwrite(
        os.path.join(job.out_dir, job.image), np.zeros((job.height, job.width, 3), np.uint8)
    )
    return pov.FrameResult(job.frame, True)


def test_failed_frame_is_retried_once_then_reported_by_number(tmp_path):
    pov.export(
        StandInSim(), tmp_path, seconds=0.3, fps=10, dt=0.01, width=32, height=24, progress=False
    )
    with ThreadPoolExecutor(2) as ex:
        with pytest.raises(
            pov.RenderError,
            match=r"1 of 4 frames failed to render after 2 "
            r"tries: frames 2 \(frame 2: povray exited "
            r"with 1: Parse Error: boom\)",
        ) as e:
            pov.render(
                tmp_path,
                executor=ex,
                worker=fake_worker,
                progress=False,
                povray_binary=sys.executable,
            )
    assert e.value.frames == [2]
    assert sorted(p.name for p in (tmp_path / "render").iterdir()) == [
        "frame_0.png",
        "frame_1.png",
        "frame_3.png",
    ]


def test_missing_povray_and_ffmpeg_name_the_debian_package(tmp_path, monkeypatch):
    monkeypatch.setenv("FLAGSIM_POVRAY", "povray-not-installed")
    with pytest.raises(pov.PovrayNotFound, match=r"install the Debian package 'povray'"):
        pov.find_povray()
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(pov.FfmpegNotFound, match=r"install the Debian package 'ffmpeg'"):
        pov.make_mp4(tmp_path, tmp_path / "a.mp4", 25, 10)


def test_a_folder_without_an_export_is_refused(tmp_path):
    with pytest.raises(pov.IncompleteExport, match=r"is not a flagsim export.*flagsim run"):
        pov.render(tmp_path, progress=False)


@needs_povray
def test_texture_image_is_mapped_upright_with_the_hoist_at_the_pole(tmp_path):
    import imageio.v3 as iio

    image = np.zeros((40, 60, 3), np.uint8)
    image[...] = (20, 40, 220)  # blue ...
    image[:20, :30] = (220, 20, 20)  # ... but the top hoist-side quarter is red
    iio.imwrite(tmp_path / "my flag.png", image)
    out = tmp_path / "out"
    pov.export(
        StandInSim(amplitude=0.05),
        out,
        seconds=0.0,
        fps=10,
        scene=standin_scene(),
        width=80,
        height=60,
        texture=tmp_path / "my flag.png",
        progress=False,
    )
    assert (out / "texture.png").read_bytes() == (tmp_path / "my flag.png").read_bytes()
    assert 'image_map { png "texture.png" interpolate 2 }' in (out / "flag.pov").read_text()
    result = pov.render(out, progress=False, executor=ThreadPoolExecutor(1))
    assert result.diagnostics == {}
    rgb = iio.imread(result.images[0])[..., :3].astype(float)
    red = (rgb[..., 0] > 2.5 * rgb[..., 1]) & (rgb[..., 0] > 2.5 * rgb[..., 2])
    blue = (rgb[..., 2] > 3.0 * rgb[..., 0]) & (rgb[..., 2] > 2.0 * rgb[..., 1])  # not the sky
    rows_r, cols_r = np.nonzero(red)
    rows_b, cols_b = np.nonzero(blue)
    assert red.sum() > 100 and 2 * red.sum() < blue.sum() < 5 * red.sum()  # 1/4 red, 3/4 blue
    assert rows_r.mean() < rows_b.mean() - 3 and cols_r.mean() < cols_b.mean() - 3
