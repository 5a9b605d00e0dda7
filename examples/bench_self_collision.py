"""How the self-collision stage's cost grows with the flag: 1k, 4k and 16k vertices.

A square flag on its pole, vertex spacing 1 cm (so the thickness, 3 mm, means the same at every
size), in a gusty 6 m/s wind with the implicit integrator; after 0.3 s of warm-up the
self_collision stage's time per step is measured over the next 0.5 s (sim.timings), three runs,
median. Prints a markdown table and the slope of log(cost) against log(vertices): 1 is linear.

    python examples/bench_self_collision.py [--threads 1] [--quick] [--csv out.csv]
"""
import argparse
import math
import statistics
import time

import numpy as np

import flagsim


def scene(n_side):
    s = flagsim.Scene.paper()
    s.name = f"self-collision {n_side}x{n_side}"
    s.air.model = "uniform"
    s.air.wind = [(0.0, (6.0, 0.0, 0.0)), (0.2, (6.0, 0.0, 2.0)), (0.4, (4.0, 0.0, -2.0)),
                  (0.6, (7.0, 0.0, 1.0)), (0.8, (5.0, 0.0, -1.0))]
    s.flag.rows = s.flag.cols = n_side
    s.flag.width = s.flag.height = 0.01 * (n_side - 1)
    s.pole.height = s.flag.height + 2.6
    s.flapping.mode = "off"  # the wind alone moves the flag: the same motion at every size
    s.self_collision.enabled = True
    s.self_collision.thickness = 0.003
    return s


def measure(n_side, warmup, seconds):
    s = scene(n_side)
    sim = flagsim.Simulation(s)
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
    return dict(vertices=n_side * n_side, seconds_per_step=per_step, step_wall=wall / steps,
                candidates_per_vertex=candidates / steps / (n_side * n_side))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one short run per size")
    ap.add_argument("--csv", help="also write the figures to this CSV file")
    args = ap.parse_args()
    flagsim.set_num_threads(args.threads)
    runs, warmup, seconds = (1, 0.1, 0.1) if args.quick else (args.runs, 0.3, 0.5)
    rows = []
    for n_side in (32, 64, 128):
        results = [measure(n_side, warmup, seconds) for _ in range(runs)]
        best = min(results, key=lambda r: r["seconds_per_step"])
        median = statistics.median(r["seconds_per_step"] for r in results)
        rows.append(dict(vertices=best["vertices"], min_ms=1e3 * best["seconds_per_step"],
                         median_ms=1e3 * median, us_per_vertex=1e6 * median / best["vertices"],
                         candidates_per_vertex=best["candidates_per_vertex"],
                         step_ms=1e3 * best["step_wall"]))
    n = np.log([r["vertices"] for r in rows])
    c = np.log([r["median_ms"] for r in rows])
    slope = float(np.polyfit(n, c, 1)[0])
    print(f"self-collision stage, {args.threads} thread(s), median of {runs} run(s)\n")
    print("| vertices | min ms/step | median ms/step | us/vertex | candidates/vertex | whole step ms |")
    print("|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['vertices']} | {r['min_ms']:.3f} | {r['median_ms']:.3f} | "
              f"{r['us_per_vertex']:.2f} | {r['candidates_per_vertex']:.1f} | {r['step_ms']:.2f} |")
    print(f"\nlog-log slope of cost against vertices: {slope:.3f}")
    if args.csv:
        with open(args.csv, "w") as f:
            f.write(",".join(rows[0]) + "\n")
            for r in rows:
                f.write(",".join(str(v) for v in r.values()) + "\n")
    return 0 if math.isfinite(slope) else 1


if __name__ == "__main__":
    raise SystemExit(main())
