"""Benchmark flagsim and the engines a user would pick instead.

Workloads: the paper scene (as built in, and the full pipeline: grid air, self-collision,
flapping), the cloth alone at 8 x 11 .. 128 x 128 for each integrator with and without
self-collision, the air alone at 16^3 .. 128^3 for each advection scheme and pressure backend
(and the float grid, and the FFTW floor of an FFT projection), at 1 and 2 threads; with --peers
the same cloth in PyBullet, MuJoCo and pyPBD and the same air in the textbook numpy Stam FFT
solver.
Workloads needing a part this build lacks are skipped with a line saying so.

Each workload runs in its own process (its peak memory is its own): built outside the timing,
first steps dropped, runs grown until each lasts >= 1 s (--quick: 0.1 s), min and median of 3
runs, stage split from Simulation.timings, a speed probe (200 cloth steps, one thread) just
before and after (how far the machine's speed moved over the run). Writes results.csv (the
machine described in its '#' header lines), results.md, scaling.png (log-log cost against size,
slopes printed), peers.csv and results.json to --out; --docs PATH writes the report for the docs.
"""

from .command import configure, main, run

__all__ = ["configure", "main", "run"]
