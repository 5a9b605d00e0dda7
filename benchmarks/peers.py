"""The same cloth in the engines a user would pick instead: PyBullet, MuJoCo and pyPBD.

Each peer builds the flag of ``cloth_spec(rows, cols)``: the paper scene's flag (0.81 x 0.54 m,
0.15 kg/m^2, pole-side column pinned, dt = 0.01 s, gravity -9.81 m/s^2 along y) meshed with
rows x cols vertices, with the closest stiffness its model offers:

* PyBullet: deformable mass-spring soft body loaded from a generated OBJ (springs along the
  triangle edges at flagsim's stretch stiffness, bending springs at its bend stiffness), the
  pole column anchored to the world. Its solver is unstable for this cloth at one substep, so the
  smallest stable number of substeps (1, 2, 4, ... 64, each tried for 1 s of simulated time or
  20 s of wall time but at least 20 steps, outside the timing) is used and reported. A try that
  short can pass a count at which the cloth blows up later, so every peer's cloth is checked
  again after the timed runs and a torn one (strain >= ``TORN_STRAIN``) fails its row. No wind
  (PyBullet soft bodies have no air model).
* MuJoCo: a 2-D flexcomp grid with shell elasticity (``elastic2d="both"``), Young's modulus x
  thickness = flagsim's stretch stiffness (a square spring lattice's 2-D modulus is its spring
  stiffness), pole column pinned, ``integrator="discrete"`` (MuJoCo 4 integrates flex elasticity
  implicitly only there), wind and air density from the scene (``<option wind density>``).
* pyPBD: a regular triangle model with XPBD distance constraints at flagsim's stretch stiffness
  and XPBD isometric bending, pinned by zero mass. No wind. At its default 5 substeps this cloth
  tears from 32 x 32 up (strain 0.6 to 3.7), so, as for PyBullet, the smallest stable count of
  5, 10, 20, 40, 80 is used and reported.

Peer modules are imported only inside these functions; one that is not installed is reported,
never an error.
"""

from __future__ import annotations

import importlib.util
import os
import tempfile
import time
from typing import Any, Callable

import numpy as np

#: name -> (import name, display name, pip name)
PEERS = {
    "pybullet": ("pybullet", "PyBullet", "pybullet"),
    "mujoco": ("mujoco", "MuJoCo", "mujoco"),
    "pypbd": ("pypbd", "pyPBD", "pypbd"),
}


def peer_available(name: str) -> tuple[bool, str]:
    module, display, pip = PEERS[name]
    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        found = False
    if found:
        return True, ""
    return False, (
        f"{display} is not installed (pip install {pip}; make bench-deps installs every peer)"
    )


def cloth_spec(rows: int, cols: int) -> dict[str, Any]:
    """The paper scene's flag at rows x cols, as plain numbers every peer can read."""
    from .engines import plain_paper_scene

    s = plain_paper_scene()
    wind = s.air.wind[0][1] if s.air.model != "none" else (0.0, 0.0, 0.0)
    return {
        "rows": rows,
        "cols": cols,
        "width": s.flag.width,
        "height": s.flag.height,
        "origin": tuple(s.flag.origin),
        "areal_density": s.flag.areal_density,
        "k_stretch": s.flag.stretch_stiffness,
        "k_shear": s.flag.shear_stiffness,
        "k_bend": s.flag.bend_stiffness,
        "damping": s.flag.damping,
        "dt": s.dt,
        "gravity": tuple(s.gravity),
        "wind": tuple(wind),
        "air_density": s.air.density,
    }


def flag_mesh(spec: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) rest positions (vertex r * cols + c, r = 0 top, c = 0 pole side) and (T, 3)
    triangles, laid out as flagsim lays out its flag."""
    R, C = spec["rows"], spec["cols"]
    ox, oy, oz = spec["origin"]
    c, r = np.meshgrid(np.arange(C), np.arange(R))
    x = np.stack(
        [
            ox + c.ravel() * spec["width"] / (C - 1),
            oy - r.ravel() * spec["height"] / (R - 1),
            np.full(R * C, oz),
        ],
        axis=1,
    )
    tris = []
    for i in range(R - 1):
        for j in range(C - 1):
            a, b, cc, d = i * C + j, i * C + j + 1, (i + 1) * C + j, (i + 1) * C + j + 1
            tris += [(a, cc, d), (a, d, b)]
    return x, np.asarray(tris, dtype=np.int64)


def pole_pins(spec: dict[str, Any]) -> list[int]:
    return [r * spec["cols"] for r in range(spec["rows"])]


#: Structural strain beyond which a peer's cloth counts as torn apart (its solver went unstable),
#: not merely stretched: flagsim's own strain limit is 0.1, and a stable peer stays below ~0.05.
TORN_STRAIN = 0.5


def structural_strain(spec: dict[str, Any], x: np.ndarray) -> float:
    """Largest |l - L| / L over the horizontal and vertical edges of positions x (N, 3)."""
    R, C = spec["rows"], spec["cols"]
    g = x.reshape(R, C, 3)
    dx, dy = spec["width"] / (C - 1), spec["height"] / (R - 1)
    h = np.linalg.norm(g[:, 1:] - g[:, :-1], axis=2) / dx
    v = np.linalg.norm(g[1:] - g[:-1], axis=2) / dy
    return float(max(np.abs(h - 1).max(), np.abs(v - 1).max()))


class PeerStepper:
    """Base: subclasses set self.spec and implement positions() and step(n)."""

    spec: dict[str, Any]
    notes: str = ""

    def positions(self) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def ok(self) -> bool:
        """Finite and not torn apart: a blown-up cloth's steps/s would be a figure for nothing."""
        x = self.positions()
        return bool(np.isfinite(x).all() and structural_strain(self.spec, x) < TORN_STRAIN)

    def step(self, n: int) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _smallest_stable(self, counts: tuple[int, ...], load: Callable[[int], None]) -> int:
        """The first substep count in `counts` whose cloth, built afresh by load(n), holds for a
        try (1 s of simulated time, or 20 s of wall time but at least 20 steps), outside the
        timing; load(n) is called once more for the chosen n so the timed runs start from rest.
        A try can pass a count whose cloth blows up later: ok() is checked again after the timed
        runs, and a torn cloth fails its row."""
        for n in counts:
            load(n)
            if self._stable(round(1.0 / self.spec["dt"]), budget=20.0, min_steps=20):
                load(n)
                return n
        raise RuntimeError(f"the cloth is unstable at every substep count up to {counts[-1]}")

    def _stable(self, steps: int, budget: float, min_steps: int) -> bool:
        """Passes ok() for `steps` steps, or for as many as `budget` seconds allow but at least
        `min_steps` (checked every 5 steps and at the end)."""
        t0 = time.perf_counter()
        for k in range(1, steps + 1):
            self.step(1)
            last = k == steps or (k >= min_steps and time.perf_counter() - t0 > budget)
            if (k % 5 == 0 or last) and not self.ok():
                return False
            if last:
                break
        return True

    def info(self) -> dict[str, Any]:
        strain = structural_strain(self.spec, self.positions())
        return {
            "notes": f"{self.notes}; max strain {strain:.2g} after the runs",
            "max_strain": strain,
        }

    def close(self) -> None:
        """Release what the engine holds (the worker process simply exits instead)."""


class PyBulletCloth(PeerStepper):
    SUBSTEPS = (1, 2, 4, 8, 16, 32, 64)

    def __init__(self, spec: dict[str, Any]):
        import pybullet

        self.p = pybullet
        self.spec = spec
        x, tris = flag_mesh(spec)
        self._dir = tempfile.TemporaryDirectory(prefix="flagsim-bench-")
        self.obj = os.path.join(self._dir.name, "flag.obj")
        with open(self.obj, "w", encoding="ascii") as f:
            f.writelines(f"v {a:.9g} {b:.9g} {c:.9g}\n" for a, b, c in x)
            f.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in tris)
        self.client = pybullet.connect(pybullet.DIRECT)
        # Every try reloads the cloth (about 2 minutes at 128 x 128 in PyBullet 3.2.7). A bisection
        # over SUBSTEPS was tried: it took 16 at 128 x 128, where a 20 s try ran only ~5 steps,
        # and that cloth blew up in the timed runs (max strain 2.1); this upward search's 32 held.
        # A try now runs at least 20 steps whatever they cost (~80 s there).
        try:
            n = self._smallest_stable(self.SUBSTEPS, self._load)
        finally:
            self._dir.cleanup()  # loaded: PyBullet keeps no reference to the file
        self.notes = f"mass-spring, {n} substep{'s' if n > 1 else ''} (smallest stable), no wind"

    def _load(self, substeps: int) -> None:
        p, s = self.p, self.spec
        p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=self.client)
        p.setGravity(*s["gravity"], physicsClientId=self.client)
        p.setTimeStep(s["dt"], physicsClientId=self.client)
        p.setPhysicsEngineParameter(numSubSteps=substeps, physicsClientId=self.client)
        mass = s["areal_density"] * s["width"] * s["height"]
        self.body = p.loadSoftBody(
            self.obj,
            basePosition=[0, 0, 0],
            scale=1,
            mass=mass,
            useNeoHookean=0,
            useMassSpring=1,
            useBendingSprings=1,
            springElasticStiffness=s["k_stretch"],
            springDampingStiffness=s["damping"],
            springBendingStiffness=s["k_bend"],
            useSelfCollision=0,
            useFaceContact=0,
            frictionCoeff=0.0,
            collisionMargin=0.001,
            physicsClientId=self.client,
        )
        for i in pole_pins(s):
            p.createSoftBodyAnchor(self.body, i, -1, -1, physicsClientId=self.client)

    def step(self, n: int) -> None:
        step = self.p.stepSimulation
        for _ in range(n):
            step(physicsClientId=self.client)

    def positions(self) -> np.ndarray:
        _, verts = self.p.getMeshData(
            self.body, -1, flags=self.p.MESH_DATA_SIMULATION_MESH, physicsClientId=self.client
        )
        return np.asarray(verts, dtype=float)

    def close(self) -> None:
        self.p.disconnect(physicsClientId=self.client)


class MujocoCloth(PeerStepper):
    def __init__(self, spec: dict[str, Any]):
        import mujoco

        self.mj = mujoco
        self.spec = spec
        R, C = spec["rows"], spec["cols"]
        W, H = spec["width"], spec["height"]
        ox, oy, oz = spec["origin"]
        thickness = 1e-3  # m; only young * thickness (N/m) matters for a membrane
        wind = " ".join(f"{w:g}" for w in spec["wind"])
        # flexcomp grid vertex (ix, iy) has index ix * R + iy, iy upwards from the bottom row:
        # the pole column ix = 0 is vertices 0 .. R-1.
        pins = " ".join(str(i) for i in range(R))
        xml = f"""<mujoco model="flagsim-bench cloth">
  <option timestep="{spec['dt']:g}" gravity="{' '.join(f'{g:g}' for g in spec['gravity'])}"
          wind="{wind}" density="{spec['air_density']:g}" integrator="discrete"/>
  <worldbody>
    <flexcomp name="flag" type="grid" dim="2" count="{C} {R} 1"
              spacing="{W / (C - 1):.9g} {H / (R - 1):.9g} 1"
              pos="{ox + W / 2:.9g} {oy - H / 2:.9g} {oz:.9g}"
              mass="{spec['areal_density'] * W * H:.9g}" radius="0.001">
      <contact contype="0" conaffinity="0" selfcollide="none"/>
      <elasticity young="{spec['k_stretch'] / thickness:.9g}" poisson="0.2"
                  thickness="{thickness:g}"
                  elastic2d="both" damping="1e-4"/>
      <pin id="{pins}"/>
    </flexcomp>
  </worldbody>
</mujoco>"""
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        # flex order (ix * R + iy, iy from the bottom) -> flagsim order (r * C + c, r from the top)
        c, r = np.meshgrid(np.arange(C), np.arange(R))
        self.order = (c * R + (R - 1 - r)).ravel()
        self.notes = (
            "flex shell (elastic2d), discrete integrator, wind from the MJCF option "
            "wind and density"
        )

    def step(self, n: int) -> None:
        self.mj.mj_step(self.model, self.data, nstep=n)

    def info(self) -> dict[str, Any]:
        out = super().info()
        warned = {
            self.mj.mjtWarning(i).name.replace("mjWARN_", "").lower(): int(w.number)
            for i, w in enumerate(self.data.warning)
            if w.number > 0
        }
        if warned:
            out["notes"] += "; MuJoCo warnings: " + ", ".join(
                f"{k} x{v}" for k, v in warned.items()
            )
        return out

    def positions(self) -> np.ndarray:
        return np.asarray(self.data.flexvert_xpos, dtype=float)[self.order]


class PbdCloth(PeerStepper):
    #: 5 is pyPBD's default, at which this flag tears from 32 x 32 up (strain 0.6 to 3.7).
    SUBSTEPS = (5, 10, 20, 40, 80)

    def __init__(self, spec: dict[str, Any]):
        import pypbd

        self.pbd = pypbd
        self.spec = spec
        n = self._smallest_stable(self.SUBSTEPS, self._load)
        self.notes = f"XPBD distance + isometric bending, {n} substeps (smallest stable), no wind"

    def _load(self, substeps: int) -> None:
        """A fresh simulation (initDefault drops the previous model) with `substeps` substeps."""
        pypbd, spec = self.pbd, self.spec
        R, C = spec["rows"], spec["cols"]
        sim = pypbd.Simulation.getCurrent()
        sim.initDefault()
        self.sim = sim
        self.model = sim.getModel()
        # addRegularTriangleModel lays vertex r * C + c at (c dx, r dy, 0): flip y (and z) so row
        # 0 is the top, as in flagsim.
        tri = self.model.addRegularTriangleModel(
            C, R, list(spec["origin"]), np.diag([1.0, -1.0, -1.0]), [spec["width"], spec["height"]]
        )
        pd = self.model.getParticles()
        self.pd = pd
        m = spec["areal_density"] * spec["width"] * spec["height"] / pd.size()
        for i in range(pd.size()):
            pd.setMass(i, m)
        for i in pole_pins(spec):
            pd.setMass(i, 0.0)
        # 4 = XPBD distance constraints (stiffness N/m); 3 = XPBD isometric bending
        k = spec["k_stretch"]
        self.model.addClothConstraints(tri, 4, k, k, k, k, 0.3, 0.3, False, False)
        self.model.addBendingConstraints(tri, 3, spec["k_bend"])
        pypbd.TimeManager.getCurrent().setTimeStepSize(spec["dt"])
        self.ts = sim.getTimeStep()
        self.ts.setValueUInt(pypbd.TimeStepController.NUM_SUB_STEPS, substeps)

    def step(self, n: int) -> None:
        step, model = self.ts.step, self.model
        for _ in range(n):
            step(model)

    def positions(self) -> np.ndarray:
        pd = self.pd
        return np.asarray([pd.getPosition(i) for i in range(pd.size())], dtype=float)


def make(name: str, rows: int, cols: int) -> PeerStepper:
    spec = cloth_spec(rows, cols)
    if name == "pybullet":
        return PyBulletCloth(spec)
    if name == "mujoco":
        return MujocoCloth(spec)
    if name == "pypbd":
        return PbdCloth(spec)
    raise ValueError(f"peer should be one of {', '.join(PEERS)}, got {name!r}")
