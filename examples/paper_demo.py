"""Simulate the paper's flag (Okamoto et al. §5) for 5 s; print steps per second and extent."""

import time

import flagsim

scene = flagsim.Scene.paper()
sim = flagsim.Simulation(scene)
steps = round(5.0 / scene.dt)
t0 = time.perf_counter()
sim.step(steps)
elapsed = time.perf_counter() - t0
lo, hi = sim.positions.min(axis=0), sim.positions.max(axis=0)
print(
    f"scene '{scene.name}': {sim.time:.2f} s simulated in {steps} steps, "
    f"{steps / elapsed:,.0f} steps per second (stages: {', '.join(sim.stages)})"
)
extent = (f"{axis} [{low:+.3f}, {high:+.3f}] m" for axis, low, high in zip("xyz", lo, hi))
print("flag extent: " + "  ".join(extent))
