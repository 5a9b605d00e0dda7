"""How the self-collision stage's cost grows with the flag: 1k, 4k and 16k vertices.

Square flags with a vertex spacing of 1 cm (so the thickness, 3 mm, means the same at every size),
implicit integrator, two workloads:
  fold  the flag's upper half folded 2 cm over its lower half (held) and dropped onto it: every
        vertex moves the same way at every size, about half of them in resting contact;
  wind  the flag on its pole in a gusty 6 m/s wind: what a user runs; a bigger flag whips faster
        at its fly, so it has more candidate pairs per vertex.
After a warm-up the self_collision stage's time per step is measured (sim.timings), three runs,
median. Prints markdown tables and the slope of log(cost) against log(vertices): 1 is linear.

    python examples/bench_self_collision.py [--threads 1] [--quick] [--csv out.csv]
"""

import argparse
import math
import statistics
import time

import flagsim
import numpy as np
from flagsim.testing.shapes import folded_onto_itself


def wind_scene(n_side):
    s = flagsim.Scene.paper()
    s.name = f"self-collision {n_side}x{n_side}"
    s.air.model = "uniform"
    s.air.wind = [
        (0.0, (6.0, 0.0, 0.0)),
        (0.2, (6.0, 0.0, 2.0)),
        (0.4, (4.0, 0.0, -2.0)),
        (0.6, (7.0, 0.0, 1.0)),
        (0.8, (5.0, 0.0, -1.0)),
    ]
    s.flag.rows = s.flag.cols = n_side
    s.flag.width = s.flag.height = 0.01 * (n_side - 1)
    s.pole.height = s.flag.height + 2.6
    s.flapping.mode = "off"  # the wind alone moves the flag: the same motion at every size
    s.self_collision.enabled = True
    s.self_collision.thickness = 0.003
    return s


def fold_scene(n_side):
    s = flagsim.Scene.paper()
    s.name = f"folded drop {n_side}x{n_side}"
    s.air.model = "none"
    s.pole.enabled = False
    s.flapping.mode = "off"
    s.flag.rows = s.flag.cols = n_side
    s.flag.width = s.flag.height = 0.01 * (n_side - 1)
    s.flag.bend_stiffness, s.flag.areal_density = 0.2, 0.5
    half = n_side // 2
    s.flag.pinned_vertices = [r * n_side + c for r in range(n_side) for c in range(half)]
    s.self_collision.enabled = True
    s.self_collision.thickness = 0.003
    return s


def measure(workload, n_side, warmup, seconds):
    s = (fold_scene if workload == "fold" else wind_scene)(n_side)
    sim = flagsim.Simulation(s)
    if workload == "fold":
        # the upper half 2 cm over the lower half, held by its pins, then dropped
        sim.positions = folded_onto_itself(sim, n_side, n_side, s.flag.width, height=0.02)
    sim.step(round(warmup / s.dt))
    before = dict(sim.timings)
    steps = round(seconds / s.dt)
    candidates = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
        candidates += sim.self_collision_stats["candidates"]
    wall = time.perf_counter() - t0
    after = sim.timings
    per_step = (after["self_collision"] - before["self_collision"]) / steps
    return dict(
        vertices=n_side * n_side,
        seconds_per_step=per_step,
        step_wall=wall / steps,
        candidates_per_vertex=candidates / steps / (n_side * n_side),
        candidates=candidates / steps,
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one short run per size")
    ap.add_argument("--csv", help="also write the figures to this CSV file")
    args = ap.parse_args()
    flagsim.set_num_threads(args.threads)
    runs, warmup, seconds = (1, 0.1, 0.1) if args.quick else (args.runs, 0.3, 0.3)
    out = []
    ok = True
    for workload in ("fold", "wind"):
        rows = []
        for n_side in (32, 64, 128):
            results = [measure(workload, n_side, warmup, seconds) for _ in range(runs)]
            best = min(results, key=lambda r: r["seconds_per_step"])
            median = statistics.median(r["seconds_per_step"] for r in results)
            rows.append(
                dict(
                    workload=workload,
                    vertices=best["vertices"],
                    min_ms=1e3 * best["seconds_per_step"],
                    median_ms=1e3 * median,
                    us_per_vertex=1e6 * median / best["vertices"],
                    candidates_per_vertex=best["candidates_per_vertex"],
                    us_per_candidate=1e6 * median / best["candidates"],
                    step_ms=1e3 * best["step_wall"],
                )
            )
        n = np.log([r["vertices"] for r in rows])
        slope = float(np.polyfit(n, np.log([r["median_ms"] for r in rows]), 1)[0])
        ok = ok and math.isfinite(slope)
        print(
            f"\n{workload}: self-collision stage, {args.threads} thread(s), median of {runs} "
            f"run(s)\n"
        )
        print(
            "| vertices | min ms/step | median ms/step | us/vertex | candidates/vertex | "
            "us/candidate | whole step ms |"
        )
        print("|---:|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            print(
                f"| {r['vertices']} | {r['min_ms']:.3f} | {r['median_ms']:.3f} | "
                f"{r['us_per_vertex']:.2f} | {r['candidates_per_vertex']:.1f} | "
                f"{r['us_per_candidate']:.3f} | {r['step_ms']:.2f} |"
            )
        print(f"\nlog-log slope of cost against vertices: {slope:.3f}")
        out += rows
    if args.csv:
        with open(args.csv, "w") as f:
            f.write(",".join(out[0]) + "\n")
            for r in out:
                f.write(",".join(str(v) for v in r.values()) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
