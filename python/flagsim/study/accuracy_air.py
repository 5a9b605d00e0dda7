"""Air parts of the accuracy study: Taylor-Green vortex (air alone) and the coupled paper scene.

Both need the Stable Fluids solver (`flagsim.Fluid`); without it they contribute no cases.
Taylor-Green: u = U sin(kx) cos(ky) e^(-2 nu k^2 t), v = -U cos(kx) sin(ky) e^(-2 nu k^2 t), w = 0
on a periodic box of side L = 1 m (k = 2 pi / L), an exact solution of eq. 1-2, run to t = T;
error = RMS over cell centres of the sampled velocity. Two refinements: "cfl" (dt proportional to
h: the whole method, where advect-then-project splitting makes both schemes first order in time)
and "dt~h^2" (time error negligible: the spatial order, where semi-Lagrangian's per-step
interpolation error accumulates as h^2/dt and MacCormack's as h^3/dt).
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

import numpy as np

import flagsim

from .common import set_method, state_result

U, L, NU, T_END, CFL = 1.0, 1.0, 0.01, 0.25, 0.5


def available() -> bool:
    return hasattr(flagsim, "Fluid")


def cases(quick: bool) -> list[dict[str, Any]]:
    if not available():
        return []
    out: list[dict[str, Any]] = []
    sizes = (8, 16) if quick else (8, 16, 32, 64)
    for adv in ("semi_lagrangian", "maccormack"):
        for p in ("fft", "pcg") if flagsim.has_fftw() else ("pcg",):
            tols = (1e-8,) if p == "fft" or quick else (1e-4, 1e-6, 1e-8)
            for tol in tols:
                for n in sizes:
                    out.append(
                        dict(
                            id=f"air-{adv}-{p}-{tol:g}-{n}",
                            part="air",
                            method=adv,
                            advection=adv,
                            pressure=p,
                            tolerance=tol,
                            resolution=n,
                            refinement="cfl",
                            repeats=1 if quick else 3,
                        )
                    )
        for n in sizes:  # spatial order: fft (or pcg without FFTW) at its tightest tolerance
            p = "fft" if flagsim.has_fftw() else "pcg"
            out.append(
                dict(
                    id=f"air-{adv}-{p}-h2-{n}",
                    part="air",
                    method=adv,
                    advection=adv,
                    pressure=p,
                    tolerance=1e-8,
                    resolution=n,
                    refinement="dt~h^2",
                    repeats=1,
                )
            )
    if _paper_has_grid():
        res = (8, 16) if quick else (8, 16, 32)
        dts = (0.02, 0.01) if quick else (0.02, 0.01, 0.005, 0.0025)
        for m in ("implicit", "explicit_adaptive"):
            for n in res:
                for dt in dts:
                    out.append(
                        dict(
                            id=f"coupled-{m}-{n}-{dt:g}",
                            part="coupled",
                            method=m,
                            resolution=n,
                            dt=dt,
                            repeats=1,
                        )
                    )
        ref = (24, 0.005) if quick else (48, 0.00125)
        out.append(
            dict(
                id="coupled-reference",
                part="coupled-reference",
                method="implicit",
                resolution=ref[0],
                dt=ref[1],
                repeats=1,
            )
        )
    return out


def _paper_has_grid() -> bool:
    return available() and flagsim.Scene.paper().air.model == "grid"


def taylor_green(points: np.ndarray, t: float = 0.0) -> np.ndarray:
    k = 2 * math.pi / L
    decay = math.exp(-2 * NU * k * k * t)
    x, y = points[:, 0], points[:, 1]
    return np.stack(
        [
            U * np.sin(k * x) * np.cos(k * y) * decay,
            -U * np.cos(k * x) * np.sin(k * y) * decay,
            np.zeros_like(x),
        ],
        axis=1,
    )


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    if case["part"] == "air":
        return _run_tg(case)
    return _run_coupled(case)


def _run_tg(case: dict[str, Any]) -> dict[str, Any]:
    n = int(case["resolution"])
    h = L / n
    nz = 4
    dt = CFL * h / U if case.get("refinement", "cfl") == "cfl" else CFL * h * h * 8 / (U * L)
    steps = max(1, round(T_END / dt))
    dt = T_END / steps
    times, err = [], math.nan
    for _ in range(int(case.get("repeats", 1))):
        fluid = flagsim.Fluid(
            resolution=(n, n, nz),
            cell_size=h,
            origin=(0.0, 0.0, 0.0),
            boundary="periodic",
            viscosity=NU,
            density=1.2,
            advection=case["advection"],
            pressure=case["pressure"],
            **({"pcg_tolerance": float(case["tolerance"])} if case["pressure"] == "pcg" else {}),
        )
        fluid.set_velocity(lambda p: taylor_green(p, 0.0))
        t0 = time.perf_counter()
        for _ in range(steps):
            fluid.step(dt)
        times.append((time.perf_counter() - t0) / steps)
        c = (np.arange(n) + 0.5) * h
        X, Y, Z = np.meshgrid(c, c, (np.arange(nz) + 0.5) * h, indexing="ij")
        pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
        diff = fluid.sample(pts) - taylor_green(pts, fluid.time)
        err = float(np.sqrt((diff**2).sum(axis=1).mean()))
    spp = float(np.median(times))
    return dict(dt=dt, steps=steps, error=err, seconds_per_step=spp, steps_per_second=1 / spp)


def coupled_scene(method: str, resolution: int, dt: float) -> flagsim.Scene:
    s = flagsim.Scene.paper()
    n0 = s.air.resolution
    size = [r * s.air.cell_size for r in n0]
    s.air.cell_size = size[0] / resolution
    s.air.resolution = [max(2, round(sz / s.air.cell_size)) for sz in size]
    s.dt = dt
    s.flapping.mode = "off"  # the coupled comparison: flapping off
    s.integrator.cg_tolerance = 1e-10
    set_method(s, method)
    return s


def _run_coupled(case: dict[str, Any]) -> dict[str, Any]:
    dt = float(case["dt"])
    steps = round(1.0 / dt)
    sim = flagsim.Simulation(coupled_scene(case["method"], int(case["resolution"]), dt))
    t0 = time.perf_counter()
    try:
        sim.step(steps)
    except flagsim.DivergenceError as e:
        return dict(dt=dt, steps=sim.step_count, state=f"diverged: {e.cause}")
    spp = (time.perf_counter() - t0) / steps
    return dict(
        dt=dt,
        steps=steps,
        seconds_per_step=spp,
        steps_per_second=1 / spp,
        **state_result(case["id"], sim.positions.copy()),
    )


def fill_state_errors(rows: list[dict[str, str]], state_dir: str) -> None:
    ref = [r for r in rows if r["part"] == "coupled-reference" and r["state"].endswith(".npy")]
    if not ref:
        return
    reference = np.load(os.path.join(state_dir, ref[0]["state"]))
    for r in rows:
        if r["part"] == "coupled" and r["state"].endswith(".npy"):
            x = np.load(os.path.join(state_dir, r["state"]))
            r["error"] = repr(float(np.sqrt(((x - reference) ** 2).sum(axis=1).mean())))
