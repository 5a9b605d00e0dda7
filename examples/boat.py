"""A flag on the mast of a boat rolling and pitching in the wind (the built-in `boat` scene).

flag.pin_motion moves the mast and the flag's pinned edge together: roll +-12 degrees about the
boat's length (4 s period), pitch +-5 degrees (3 s), heave 15 cm, in a 6 m/s wind with curl-noise
gusts. Every 0.5 s this prints the mast's lean, how far the flag's free corner is from the mast
and the work the moving pins did so far (the energy ledger's `pins`). With --out DIR the run is
exported for POV-Ray, the mast moving with the pins in every frame; add --render for a GIF.

    python examples/boat.py [--seconds 6] [--out out/boat [--render]]
"""

import argparse

import flagsim
import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--out", help="also export the run for POV-Ray into this folder")
    ap.add_argument("--render", action="store_true", help="render the export to boat.gif (POV-Ray)")
    ap.add_argument("--fps", type=int, default=15)
    args = ap.parse_args()

    scene = flagsim.Scene.boat()
    sim = flagsim.Simulation(scene)
    print(f"stages: {', '.join(sim.stages)}")
    print("   t s | mast lean, deg | free corner to mast, m | pins' work, J")

    def report(s):
        if s.step_count % round(0.5 / scene.dt):
            return
        R, t = s.pole_pose
        lean = np.degrees(np.arccos(np.clip(R[1, 1], -1.0, 1.0)))
        corner = s.positions[scene.flag.cols - 1]  # top free corner
        top = R @ (np.asarray(scene.pole.base) + (0, scene.pole.height, 0)) + t
        print(
            f"{s.time:6.2f} | {lean:14.1f} | {np.linalg.norm(corner - top):22.3f} |"
            f" {s.energy_ledger()['pins']:12.3f}"
        )

    if args.out:
        from flagsim import povray

        povray.export(
            sim, args.out, seconds=args.seconds, fps=args.fps, width=320, height=240,
            on_frame=report, overwrite=True,
        )  # fmt: skip
        if args.render:
            result = povray.render(args.out)
            print(povray.make_gif(result.images, f"{args.out}/boat.gif", args.fps))
    else:
        for _ in range(round(args.seconds / scene.dt)):
            sim.step()
            report(sim)


if __name__ == "__main__":
    main()
