"""Render Scene.emergent() (eq. 5 off: two-way coupling, curl-noise turbulence, the pole a solid
of the air) with the camera of the eq. 5 demo, docs/images/paper.gif (`flagsim run paper
--seconds 4 --fps 12.5 --render --gif --width 320 --height 240`), so the README can show them
side by side (docs/coupling.md).

usage: python examples/emergent_demo.py [--seconds 4] [--fps 12.5] [--width 320 --height 240]
                                        [--out out/emergent_demo] [--images docs/images] [--paper]

Both scenes are exported to OUT/<name> (flagsim.povray.export, which sets each camera from its
flag's motion); the paper's master scene (camera, pole, lights) is then copied over the
emergent one's before POV-Ray renders it into IMAGES/emergent.gif. --paper renders the paper's
too (IMAGES/paper.gif). Needs POV-Ray (make demo installs it).
"""

import argparse
import shutil
import warnings
from pathlib import Path

import flagsim
import flagsim.povray as pov
from flagsim.povray import scenefiles


def export(name, a, out):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the emergent pole is coarser than its wake needs
        sim = flagsim.Simulation(flagsim.Scene.named(name))
    r = pov.export(
        sim,
        out / name,
        seconds=a.seconds,
        fps=a.fps,
        width=a.width,
        height=a.height,
        key={"scene": name, "seconds": a.seconds, "fps": a.fps},
        overwrite=True,
    )
    print(f"{name}: {r.steps} steps in {r.wall_seconds:.1f} s")
    return out / name


def render(folder, gif, fps):
    result = pov.render(folder)
    pov.make_gif(result.images, gif, fps=fps)
    print(f"{gif}: {gif.stat().st_size / 1e6:.2f} MB")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seconds", type=float, default=4.0, help="simulated seconds (default 4)")
    ap.add_argument("--fps", type=float, default=12.5, help="frames per second (default 12.5)")
    ap.add_argument("--width", type=int, default=320, help="pixels (default 320)")
    ap.add_argument("--height", type=int, default=240, help="pixels (default 240)")
    ap.add_argument("--out", default="out/emergent_demo", help="export folders go here")
    ap.add_argument("--images", default="docs/images", help="the GIFs go here")
    ap.add_argument("--paper", action="store_true", help="render the eq. 5 demo's GIF too")
    a = ap.parse_args(argv)
    out, images = Path(a.out), Path(a.images)
    images.mkdir(parents=True, exist_ok=True)
    paper = export("paper", a, out)
    emergent = export("emergent", a, out)
    shutil.copyfile(paper / scenefiles.SCENE_FILE, emergent / scenefiles.SCENE_FILE)
    render(emergent, images / "emergent.gif", a.fps)
    if a.paper:
        render(paper, images / "paper.gif", a.fps)


if __name__ == "__main__":
    main()
