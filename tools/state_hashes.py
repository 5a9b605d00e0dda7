"""SHA-256 of the final state of reference runs: a refactoring that must not change results
("same bits before and after") prints the same lines before and after it. Bits depend on the
compiler and the SIMD path this CPU takes, so compare runs on one machine, never against numbers
from another.

usage: python tools/state_hashes.py [--steps N]
"""

import argparse
import hashlib

import flagsim


def paper_flat():
    """The paper scene with a perfectly flat flag: the pipeline variants below test code paths
    and keep the hashes they had before the paper scene's seeded imperfection (issue 24)."""
    s = flagsim.Scene.paper()
    s.flag.imperfection = 0.0
    return s


def scenes():
    yield "paper", flagsim.Scene.paper()
    for n in (32, 64):
        s = paper_flat()  # the paper's pipeline (grid air, self-collision, eq. 5)
        s.flag.rows = s.flag.cols = n
        yield f"flag{n}x{n}", s
    e = paper_flat()
    e.flag.rows = e.flag.cols = 32
    e.integrator.method = "explicit"
    e.integrator.adaptive = True
    yield "flag32x32-explicit", e
    yield "flapping_demo", flagsim.Scene.flapping_demo()
    for mode in ("force", "visual"):
        f = paper_flat()
        f.flapping.mode = mode
        yield f"paper-flap-{mode}", f
    yield "banner", flagsim.Scene.banner()


def fluids():
    """The air alone on its iterative backends (the scenes above use fft)."""
    import numpy as np

    def field(points):
        x, y, z = points.T
        return np.stack([2.0 + np.sin(3 * y) * np.cos(2 * z), np.sin(2 * x), np.cos(3 * x + y)], 1)

    for pressure in ("pcg", "multigrid"):
        for boundary, precision in (("tunnel", "double"), ("periodic", "float")):
            try:
                f = flagsim.Fluid(
                    resolution=(20, 12, 10),
                    cell_size=0.1,
                    origin=(0, 0, 0),
                    boundary=boundary,
                    pressure=pressure,
                    precision=precision,
                    advection="maccormack",
                    wind=(2.0, 0.0, 0.0),
                )
            except ValueError:  # a backend this build does not have
                continue
            f.set_velocity(field)
            yield f"air-{pressure}-{boundary}-{precision}", f


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=100)
    args = p.parse_args()
    for name, scene in scenes():
        sim = flagsim.Simulation(scene)
        sim.step(args.steps)
        h = hashlib.sha256()
        for a in (sim.positions, sim.velocities, sim.render_positions):
            h.update(a.tobytes())
        if sim.fluid is not None:
            for a in (sim.fluid.u, sim.fluid.v, sim.fluid.w):
                h.update(a.tobytes())
        print(f"{name:24s} {h.hexdigest()[:16]}")
    for name, fluid in fluids():
        fluid.step(0.01, args.steps // 5)
        h = hashlib.sha256()
        for a in (fluid.u, fluid.v, fluid.w):
            h.update(a.tobytes())
        print(f"{name:24s} {h.hexdigest()[:16]}")


if __name__ == "__main__":
    main()
