"""Solid parts of the accuracy study (issue 23), against published results.

poiseuille  plane Poiseuille flow: uniform inflow into a no-slip channel of height H = 1 m
            (U = 1 m/s, nu = 0.1 m^2/s, Re_H = 10, length 4 H); the developed profile at 3/4 of
            the length against the analytic 6 U s (1 - s), RMS / U, as the grid is refined with
            dt = 0.5 h / U ("cfl": the whole method; the fractional step's splitting error at a
            no-slip wall is O(dt), so first order) or dt = 0.5 h / U * (8 h / H) ("dt~h^2": the
            spatial order of the walls' mirror, second).
cylinder    2-D flow past a circular cylinder at Re = U D / nu = 100 (D = 1 m, U = 1 m/s),
            extruded: 2 cells along its axis between free-slip walls, which a flow that does not
            vary along z cannot tell from a periodic axis. Domain 20 D x 16 D (x from -6 D,
            blockage D / 16 D = 6 %), uniform inflow, free-slip side walls, dt = 0.5 h / U, a
            transverse puff behind the cylinder at t = 0 to break the symmetry, 150 D / U of
            which the last half is measured. Strouhal number St = f D / U from the lift's
            upward mean crossings, against Williamson's fit St(Re) = -3.3265 / Re + 0.1816 +
            1.6e-4 Re (0.164 at Re = 100); mean drag coefficient against the published 1.32-1.34
            (1.33 taken). error = the larger of the two relative errors.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np

import flagsim

from .. import forces

RE = 100.0
ST_REF = -3.3265 / RE + 0.1816 + 1.6e-4 * RE  # Williamson 1996 (Annu. Rev. Fluid Mech. 28)
CD_REF = 1.33  # mean drag at Re = 100, published 1.32-1.34 (e.g. Park, Kwon, Choi 1998)
CD_RANGE = (1.32, 1.34)


# The CI-sized cylinder (tests/python/test_solids.py): 6 cells per diameter, 12 D x 8 D
# (blockage 12.5 %), 60 D / U; its bands there.
QUICK_CYLINDER = dict(length=12.0, width=8.0, upstream=3.0, duration=60.0)


def pressure_backend() -> str:
    """The fastest iterative pressure solve this build has."""
    try:
        flagsim.Fluid(resolution=(2, 2, 2), pressure="multigrid")
        return "multigrid"
    except ValueError:
        return "pcg"


def cases(quick: bool) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for adv in ("semi_lagrangian", "maccormack"):
        for refinement, sizes in (("cfl", (8, 16, 32, 64)), ("dt~h^2", (8, 16, 32))):
            for n in sizes[:2] if quick else sizes:
                out.append(
                    dict(
                        id=f"poiseuille-{adv}-{refinement}-{n}",
                        part="poiseuille",
                        method=adv,
                        advection=adv,
                        resolution=n,
                        refinement=refinement,
                        repeats=1,
                    )
                )
        # quick (CI) runs no cylinder: tests/python/test_solids.py runs QUICK_CYLINDER once
        for cpd in () if quick else (8, 12, 16):
            out.append(
                dict(
                    id=f"cylinder-{adv}-{cpd}",
                    part="cylinder",
                    method=adv,
                    advection=adv,
                    resolution=cpd,
                    refinement="cfl",
                    repeats=1,
                )
            )
    return out


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    if case["part"] == "poiseuille":
        return run_poiseuille(int(case["resolution"]), case["advection"], case["refinement"])
    domain = {k: float(case[k]) for k in ("length", "width", "upstream", "duration") if k in case}
    return run_cylinder(int(case["resolution"]), case["advection"], **domain)


def run_poiseuille(
    ny: int, advection: str, refinement: str = "cfl", pressure: str = "pcg"
) -> dict[str, Any]:
    H, U, nu = 1.0, 1.0, 0.1
    h = H / ny
    fluid = flagsim.Fluid(
        resolution=(4 * ny, ny, 1),
        cell_size=h,
        origin=(0, 0, 0),
        boundary="tunnel",
        pressure=pressure,
        viscosity=nu,
        wind=(U, 0, 0),
        walls={"y_min": "no_slip", "y_max": "no_slip"},
        advection=advection,
    )
    dt = 0.5 * h / U if refinement == "cfl" else 0.5 * h / U * (8 * h / H)
    steps = int(round(12.0 / dt))
    t0 = time.perf_counter()
    fluid.step(dt, steps)
    spp = (time.perf_counter() - t0) / steps
    s = (np.arange(ny) + 0.5) / ny
    err = float(np.sqrt(np.mean((fluid.u[3 * ny, :, 0] - 6 * U * s * (1 - s)) ** 2)) / U)
    return dict(
        dt=dt, steps=steps, error=err, seconds_per_step=spp, steps_per_second=1 / spp, state=""
    )


def cylinder_fluid(
    cells_per_diameter: int,
    advection: str,
    length: float = 20.0,
    width: float = 16.0,
    upstream: float = 6.0,
    pressure: str | None = None,
):
    """The cylinder case's air (D = 1 m, U = 1 m/s, Re = 100) and its time step."""
    D, U = 1.0, 1.0
    h = D / cells_per_diameter
    nx, ny = round(length / h), round(width / h)
    cyl = flagsim.ObstacleParams(
        shape="cylinder", center=(0.0, 0.0, h), radius=D / 2, axis=(0, 0, 1), length=10 * h
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # coarse grids are part of the study
        fluid = flagsim.Fluid(
            resolution=(nx, ny, 2),
            cell_size=h,
            origin=(-upstream * D, -width / 2 * D, 0.0),
            boundary="tunnel",
            pressure=pressure or pressure_backend(),
            viscosity=U * D / RE,
            wind=(U, 0, 0),
            advection=advection,
            obstacles=[cyl],
        )

    def puff(p):
        v = np.zeros_like(p)
        v[:, 0] = U
        v[:, 1] = 0.3 * U * np.exp(-((p[:, 0] - 1.5 * D) ** 2 + (p[:, 1] - 0.3 * D) ** 2) / 0.25)
        return v

    fluid.set_velocity(puff)
    return fluid, 0.5 * h / U


def run_cylinder(
    cells_per_diameter: int, advection: str, duration: float = 150.0, **domain
) -> dict[str, Any]:
    fluid, dt = cylinder_fluid(cells_per_diameter, advection, **domain)
    steps = int(round(duration / dt))
    t0 = time.perf_counter()
    hist = forces.force_history(fluid, dt, steps)
    spp = (time.perf_counter() - t0) / steps
    D, U, rho = 1.0, 1.0, fluid.density
    area = D * 2 * fluid.cell_size  # the cylinder's frontal area in the 2 cells of the grid
    after = duration / 2
    cd = float(hist.coefficients(rho, U, area)[hist.window(after), 0].mean())
    st = hist.shedding_frequency(axis=1, after=after) * D / U
    err = max(abs(st / ST_REF - 1), abs(cd / CD_REF - 1)) if math.isfinite(st) else math.nan
    return dict(
        dt=dt,
        steps=steps,
        error=err,
        strouhal=st,
        drag_coefficient=cd,
        pressure=fluid.pressure,
        seconds_per_step=spp,
        steps_per_second=1 / spp,
        state="" if math.isfinite(st) else "no shedding",
    )
