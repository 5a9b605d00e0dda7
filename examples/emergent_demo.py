"""Render the eq. 5 demo (Scene.paper(): waves painted by eq. 5) and Scene.emergent() (eq. 5 off:
two-way coupling, curl-noise turbulence, the pole a solid of the air) with one camera, as two
GIFs to compare side by side (the README shows them; docs/coupling.md).

usage: python examples/emergent_demo.py [--seconds 4] [--fps 12.5] [--width 320 --height 240]
                                        [--out out/emergent_demo] [--images docs/images]

Each scene is exported to OUT/<name> (flagsim.povray.export); the camera is then set from the
union of both exports' bounds (so both flags stay in the picture) and written into both master
scenes before POV-Ray renders them. Needs POV-Ray (make demo installs it).
"""

import argparse
import warnings
from pathlib import Path

import flagsim
import flagsim.povray as pov
import numpy as np
from flagsim.povray import scenefiles

SCENES = ("paper", "emergent")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seconds", type=float, default=4.0, help="simulated seconds (default 4)")
    ap.add_argument("--fps", type=float, default=12.5, help="frames per second (default 12.5)")
    ap.add_argument("--width", type=int, default=320, help="pixels (default 320)")
    ap.add_argument("--height", type=int, default=240, help="pixels (default 240)")
    ap.add_argument("--out", default="out/emergent_demo", help="export folders go here")
    ap.add_argument("--images", default="docs/images", help="the GIFs go here")
    a = ap.parse_args(argv)
    out, images = Path(a.out), Path(a.images)
    images.mkdir(parents=True, exist_ok=True)
    for name in SCENES:
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
    manifests = [pov.read_manifest(out / name) for name in SCENES]
    lo = np.min([m["bounds"][0] for m in manifests], axis=0)
    hi = np.max([m["bounds"][1] for m in manifests], axis=0)
    pole = scenefiles.scene_pole(flagsim.Scene.paper())  # the same pole in both scenes
    view = scenefiles.frame_view(lo, hi, pole, aspect=a.width / a.height)
    for name, m in zip(SCENES, manifests):
        scenefiles.write_static_files(
            out / name,
            view=view,
            pole=pole,
            texture=None,
            width=a.width,
            height=a.height,
            final_frame=m["frames"] - 1,
            final_clock=m["times"][-1],
        )
        result = pov.render(out / name)
        gif = images / f"{name}_flag.gif"
        pov.make_gif(result.images, gif, fps=a.fps)
        print(f"{gif}: {gif.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
