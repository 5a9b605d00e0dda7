"""The flapping alone (paper §4.3, Fig. 6): no air solver, no gravity, every mass pulled along +x.

Eq. 5 displaces the flag along its normals; the waves start at the middle of the pole edge and run
outwards on parabolas. This prints, every 0.25 s, how far the displacement pattern moved away
from the pole since the last print (eq. 5: speed x 0.25 s) and by how much the middle row leads
the top row (eq. 5: parabola / 4 flag lengths); with --png it also draws the flag's out-of-plane
displacement at four moments, like Fig. 6.

    python examples/flapping_demo.py [--mode displace|force|visual] [--seconds 2] [--png out.png]
"""

import argparse

import flagsim
import numpy as np


def pattern_shift(a, b, max_lag=9):
    """Columns by which the pattern b is pattern a moved along +x (least squares)."""
    cols = a.shape[1]
    err = {}
    for lag in range(-max_lag, max_lag + 1):
        d = b[:, lag:] - a[:, : cols - lag] if lag >= 0 else b[:, : cols + lag] - a[:, -lag:]
        err[lag] = float(np.mean(d**2))
    return min(err, key=err.get)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", default="displace", choices=["displace", "force", "visual"])
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--png", help="save four snapshots of the displacement here (matplotlib)")
    args = ap.parse_args()

    scene = flagsim.Scene.flapping_demo()
    scene.flapping.mode = args.mode
    sim = flagsim.Simulation(scene)
    rows, cols = scene.flag.rows, scene.flag.cols
    f = scene.flapping
    print(f"flapping_demo, mode '{args.mode}': stages {', '.join(sim.stages)}")
    print(
        f"eq. 5 expects: moved {f.speed * 0.25 * (cols - 1):.1f} columns per print, "
        f"middle row ahead by {f.parabola / 4 * (cols - 1):.1f} columns"
    )
    print("   t s | pattern moved, columns | middle row ahead of the top row, columns")

    def field():  # out-of-plane displacement of the drawn flag (the flag lies in z = 0)
        return np.asarray(sim.render_positions)[:, 2].reshape(rows, cols).copy()

    snapshots, previous = [], None
    every = round(0.25 / scene.dt)
    for _ in range(round(args.seconds / 0.25)):
        sim.step(every)
        z = field()
        moved = "" if previous is None else f"{pattern_shift(previous, z):+d}"
        lead = pattern_shift(z[:1], z[rows // 2 : rows // 2 + 1])
        print(f"{sim.time:6.2f} | {moved:>22} | {lead:+d}")
        previous = z
        snapshots.append((sim.time, z))
    print(
        "self-reported cost per step: "
        + ", ".join(f"{k} {1e6 * v / sim.step_count:.1f} us" for k, v in sim.timings.items())
    )

    if args.png:
        import matplotlib  # only when a picture is asked for

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        picks = snapshots[:: max(1, len(snapshots) // 4)][:4]
        fig, axes = plt.subplots(1, len(picks), figsize=(3.2 * len(picks), 2.6))
        lim = max(np.abs(z).max() for _, z in picks)
        for ax, (t, z) in zip(np.atleast_1d(axes), picks):
            ax.imshow(
                z,
                cmap="coolwarm",
                vmin=-lim,
                vmax=lim,
                origin="upper",
                extent=(0, scene.flag.width, -scene.flag.height, 0),
            )
            ax.set_title(f"t = {t:.2f} s")
            ax.set_xlabel("x from the pole, m")
        fig.suptitle("eq. 5 flapping: out-of-plane displacement (pole on the left)")
        fig.tight_layout()
        fig.savefig(args.png, dpi=120)
        print(f"wrote {args.png}")


if __name__ == "__main__":
    main()
