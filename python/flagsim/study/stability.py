"""`flagsim study stability`: does every integrator stay physically plausible on stiff and extreme
cases?

A matrix over spring stiffness, wind speed, time step, areal density, flapping mode and
integrator, plus pathological cases. Each case ends in exactly one outcome (docs/energy.md):
  plausible    ran to the end, finite, its energy ledger balanced (the run made no more energy
               than integrator.energy_tolerance x the energy scale beyond its stages' work) and
               its strain within what the scene's strain limit promises
  diverged     reported: DivergenceError raised with the state restored (cause named), or the
               scene rejected before any step with a ValueError naming the parameter (cause
               "rejected: <parameter>")
  implausible  ran to the end with finite numbers, yet fails the ledger or the strain test:
               must never happen
  nonfinite    some output is not finite without an error: must never happen
"""

from __future__ import annotations

import itertools
import math
import time
from typing import Any

import numpy as np

import flagsim

INTEGRATORS = ("explicit", "explicit_adaptive", "implicit")
FLAPPING = ("off", "displace", "force")
OUTCOMES = ("plausible", "diverged", "implausible", "nonfinite")
FULL = dict(
    k_s=(1e1, 1e3, 1e5, 1e7),
    wind=(0.0, 2.0, 10.0, 30.0, 60.0, 100.0),
    dt=(1e-4, 1e-3, 1e-2, 5e-2),
    density=(1e-3, 1e-1, 10.0),
    flapping=FLAPPING,
)
REDUCED = dict(
    k_s=(1e1, 1e7), wind=(0.0, 100.0), dt=(1e-3, 5e-2), density=(1e-3, 10.0), flapping=("off",)
)
# The reduced set's flapping cases: displace and force at k_s 1e5..1e7 in the paper's wind and a
# storm, light and heavy, at the paper's dt and 5x it.
REDUCED_FLAPPING = dict(
    k_s=(1e5, 1e7),
    wind=(2.0, 30.0),
    dt=(1e-2, 5e-2),
    density=(0.15, 10.0),
    flapping=("displace", "force"),
)
PATHOLOGICAL = (
    "coincident_masses",
    "strip_2xN",
    "fine_128x192",
    "wind_reversal_at_pole",
    "gust_30ms",
    "long_run_1000s",
    "blown_into_pole",
    "wrapped_round_pole",
    "self_collision",
    "heavy_stiff_flapping",
)
# Strain a scene with integrator.strain_limit = s promises: (1 + s + this) x rest length; the
# check stage holds every step to it (kStrainLimitSlack, csrc/cloth/params.h).
STRAIN_SLACK = flagsim._core.STRAIN_LIMIT_SLACK

COLUMNS = [
    "id",
    "kind",
    "integrator",
    "flapping",
    "k_s",
    "wind",
    "dt",
    "density",
    "duration",
    "outcome",
    "cause",
    "steps",
    "max_strain",
    "strain_promise",
    "energy_min",
    "energy_max",
    "energy_scale",
    "unexplained",
    "worst_step_unexplained",
    "ledger_error",
    "max_substeps",
    "max_cg_iterations",
    "energy_halvings",
    "wall_s",
]


def matrix_cases(axes: dict[str, tuple], duration: float) -> list[dict[str, Any]]:
    cases = []
    for k, w, dt, rho, flap, integ in itertools.product(
        axes["k_s"], axes["wind"], axes["dt"], axes["density"], axes["flapping"], INTEGRATORS
    ):
        cases.append(
            dict(
                id=f"m-{integ}-{flap}-k{k:g}-w{w:g}-dt{dt:g}-rho{rho:g}",
                kind="matrix",
                integrator=integ,
                flapping=flap,
                k_s=k,
                wind=w,
                dt=dt,
                density=rho,
                duration=duration,
            )
        )
    return cases


def pathological_cases(reduced: bool) -> list[dict[str, Any]]:
    """All pathological cases; the reduced (CI) set leaves out the 128 x 192 flag, whose explicit
    run alone takes minutes on 2 cores (the full study and docs/reports/stability.md include it)."""
    cases = []
    for name in PATHOLOGICAL:
        if reduced and name == "fine_128x192":
            continue
        for integ in INTEGRATORS:
            duration = {
                "long_run_1000s": 20.0 if reduced else 1000.0,
                "fine_128x192": 0.1,
                "wrapped_round_pole": 2.0,  # it used to diverge at 0.88 s
            }.get(name, 0.5 if reduced else 2.0)
            k, rho, flap = 100.0, 0.15, "off"
            if name == "heavy_stiff_flapping":  # the matrix's heavy, stiff corner, flapping into
                k, rho, flap = 1e7, 10.0, "displace"  # the pole in a gust
            cases.append(
                dict(
                    id=f"p-{name}-{integ}",
                    kind=name,
                    integrator=integ,
                    flapping=flap,
                    k_s=k,
                    wind=2.0,
                    dt=0.01,
                    density=rho,
                    duration=duration,
                )
            )
    return cases


def _integrator(scene: flagsim.Scene, name: str) -> None:
    scene.integrator.method = "implicit" if name == "implicit" else "explicit"
    scene.integrator.adaptive = name == "explicit_adaptive"


def build_scene(case: dict[str, Any]) -> tuple[flagsim.Scene, Any]:
    """Scene for a case, and an optional function preparing the simulation's initial state."""
    s = flagsim.Scene.paper()
    kind = case["kind"]
    k = float(case["k_s"])
    s.flag.stretch_stiffness, s.flag.shear_stiffness, s.flag.bend_stiffness = k, k / 5, k / 20
    s.flag.areal_density = float(case["density"])
    s.dt = float(case["dt"])
    s.air.model = "uniform"  # the matrix varies the wind itself; the grid is not under test here
    s.flapping.mode = case["flapping"]  # eq. 5's amplitude grows with wind speed: 1 m at 100 m/s
    w = float(case["wind"])
    direction = np.array([1.0, 0.0, 0.3]) / math.hypot(1.0, 0.3)
    s.air.wind = tuple(w * direction)
    _integrator(s, case["integrator"])
    prepare = None
    if kind == "coincident_masses":

        def prepare(sim):  # two neighbouring masses at one point: a spring of zero length
            x = sim.positions.copy()
            x[2] = x[1]
            sim.positions = x
    elif kind == "strip_2xN":
        s.flag.rows, s.flag.cols = 2, 40
        s.flag.height, s.flag.width = 0.05, 1.0
    elif kind == "fine_128x192":
        s.flag.rows, s.flag.cols = 128, 192
    elif kind == "wind_reversal_at_pole":
        s.air.wind = [(0.0, (8.0, 0.0, 1.0)), (0.3, (8.0, 0.0, 1.0)), (0.35, (-8.0, 0.0, -1.0))]
    elif kind == "gust_30ms":
        s.air.wind = [(0.0, (0.0, 0.0, 0.0)), (0.1, (0.0, 0.0, 0.0)), (0.12, (30.0, 0.0, 5.0))]
    elif kind == "long_run_1000s":  # conservative: no air, no damping; energy drift is the test
        s.air.model = "none"
        s.flag.damping = 0.0
        s.flag.imperfection = 0.0  # flat: it swings in its plane, never folding onto the pole
    elif kind in ("blown_into_pole", "heavy_stiff_flapping"):
        # wind from the fly end: the flag folds back around its pole and presses on it
        s.air.wind = [(0.0, (2.0, 0.0, 0.5)), (0.1, (2.0, 0.0, 0.5)), (0.15, (-20.0, 0.0, 3.0))]
    elif kind == "wrapped_round_pole":  # a steady wind onto the pole wraps the flag round it, the
        s.air.wind = (-3.0, 0.0, 0.0)  # first free column's springs as chords through the pole
    elif kind == "self_collision":  # folded onto itself by a reversing gust, self-collision on
        s.self_collision.enabled = True
        s.air.wind = [(0.0, (6.0, 0.0, 1.0)), (0.2, (6.0, 0.0, 1.0)), (0.25, (-12.0, 0.0, -2.0))]
    return s, prepare


def strain_promise(scene: flagsim.Scene) -> float:
    """Largest spring strain the scene promises: its strain limit (with STRAIN_SLACK), or, with
    strain limiting off, integrator.max_strain (beyond which a step raises)."""
    limit = scene.integrator.strain_limit
    return limit + STRAIN_SLACK if limit > 0 else scene.integrator.max_strain


_PROJECTIONS = ("strain_limit", "pole", "self_collision")


def unexplained(ledger: dict[str, float], since: dict[str, float]) -> float:
    """Energy no stage's work explains from the ledger `since` to `ledger`, J: the positive part
    of the integrator remainder's change plus that of the projections' (strain limiting, pole,
    self-collision) together; the check stage's measure for a step (EnergyLedger in
    csrc/scene/simulation.h)."""

    def change(*keys):
        return sum(ledger[k] - since[k] for k in keys)

    return max(change("integrator"), 0.0) + max(change(*_PROJECTIONS), 0.0)


def net_unexplained(
    ledger: dict[str, float], since: dict[str, float], holdable: float | None = None
) -> float:
    """The same without the split, J: what the run still holds of what it made (a projection's
    gain that the next solve took out again does not count here; it does in each step). With
    `holdable` (sim.holdable_energy(): the flag's kinetic and spring energy and its rise, relative
    to its pins once they moved), bounded by it, as the check stage's run measure is
    (Simulation::check_energy)."""
    net = sum(ledger[k] - since[k] for k in ("integrator",) + _PROJECTIONS)
    return net if holdable is None else min(net, holdable)


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    """Pure function of the case: same settings, same result (apart from wall_s).

    Every step is followed by a read of the energy ledger: `unexplained` is the most energy the
    run held beyond its stages' work (`net_unexplained` from the start, docs/energy.md) and
    `worst_step_unexplained` the most that one step made (`unexplained`, the check's measure),
    both in J; `ledger_error` is the largest |E(t) - E(0) - sum of the ledger| seen, J. Both
    must stay within integrator.energy_tolerance x the energy scale.
    """
    scene, prepare = build_scene(case)
    try:
        sim = flagsim.Simulation(scene)
    except ValueError as err:  # parameters that make a plausible run impossible, named up front
        return dict(
            outcome="diverged",
            cause=f"rejected: {str(err).split(' should')[0]}",
            steps=0,
            max_strain="",
            strain_promise=f"{strain_promise(scene):.6g}",
            energy_min="",
            energy_max="",
            energy_scale="",
            unexplained="",
            worst_step_unexplained="",
            ledger_error="",
            max_substeps=0,
            max_cg_iterations=0,
            energy_halvings=0,
            wall_s="0",
        )
    if prepare:
        prepare(sim)
    steps = max(1, round(float(case["duration"]) / scene.dt))
    chunk = max(1, steps // 200)  # energy, strain and the ledger's balance sampled ~200 times
    e0 = sum(sim.energy().values())  # the range includes the start: dissipation shows
    l0 = sim.energy_ledger()  # edits made by `prepare`
    e_min, e_max, strain, subs, cgs, halvings = e0, e0, 0.0, 0, 0, 0
    most = worst_step = ledger_error = 0.0
    outcome, cause = "plausible", ""
    t0 = time.perf_counter()
    done = 0
    try:
        while done < steps:
            n = min(chunk, steps - done)
            for _ in range(n):
                before = sim.energy_ledger()
                sim.step()
                st = sim.last_step_stats
                subs = max(subs, st["substeps"])
                cgs = max(cgs, st["cg_iterations"])
                halvings = max(halvings, st["energy_halvings"])
                now = sim.energy_ledger()
                worst_step = max(worst_step, unexplained(now, before))
                most = max(most, net_unexplained(now, l0, sim.holdable_energy()))
            done += n
            e = sum(sim.energy().values())
            ledger = sim.energy_ledger()
            ledger_error = max(
                ledger_error,
                abs(
                    e
                    - e0
                    - sum(v for k, v in ledger.items() if k not in ("gravity", "edits"))
                    + sum(v for k, v in l0.items() if k not in ("gravity", "edits"))
                ),
            )
            e_min, e_max = min(e_min, e), max(e_max, e)
            strain = max(strain, sim.max_strain())
            if not _all_finite(sim, e):
                outcome, cause = "nonfinite", "non-finite output without DivergenceError"
                break
    except flagsim.DivergenceError as err:
        outcome, cause = "diverged", err.cause
        if not _all_finite(sim, sum(sim.energy().values())):
            outcome, cause = "nonfinite", "state not restored after DivergenceError"
    promise = strain_promise(scene)
    scale = sim.energy_scale
    if outcome == "plausible":
        why = []
        if strain > promise:
            why.append(f"strain {strain:.3g} > promised {promise:.3g}")
        allowed = scene.integrator.energy_tolerance * scale
        if most > allowed:
            why.append(
                f"unexplained energy {most:.3g} J > "
                f"{scene.integrator.energy_tolerance:g} x scale {scale:.3g} J"
            )
        if worst_step > allowed:
            why.append(
                f"a step made {worst_step:.3g} J unexplained > "
                f"{scene.integrator.energy_tolerance:g} x scale {scale:.3g} J"
            )
        if ledger_error > 1e-9 * (scale + max(abs(e_min), abs(e_max))):
            why.append(f"ledger off by {ledger_error:.3g} J")
        if why:
            outcome, cause = "implausible", "; ".join(why)
    return dict(
        outcome=outcome,
        cause=cause,
        steps=sim.step_count,
        max_strain=f"{strain:.6g}",
        strain_promise=f"{promise:.6g}",
        energy_min=f"{e_min:.6g}",
        energy_max=f"{e_max:.6g}",
        energy_scale=f"{scale:.6g}",
        unexplained=f"{most:.6g}",
        worst_step_unexplained=f"{worst_step:.6g}",
        ledger_error=f"{ledger_error:.3g}",
        max_substeps=subs,
        max_cg_iterations=cgs,
        energy_halvings=halvings,
        wall_s=f"{time.perf_counter() - t0:.4g}",
    )


def _all_finite(sim: flagsim.Simulation, energy: float) -> bool:
    return bool(
        np.isfinite(sim.positions).all()
        and np.isfinite(sim.velocities).all()
        and np.isfinite(sim.normals).all()
        and math.isfinite(energy)
    )


def cases(reduced: bool) -> list[dict[str, Any]]:
    axes = REDUCED if reduced else FULL
    # 0.2 s of simulated time per matrix case: 20 steps at the largest dt, 2,000 at the smallest;
    # an explicit run at k_s = 1e7 and 1e-3 kg/m^2 already takes ~4e5 substeps for it.
    duration = 0.05 if reduced else 0.2
    flapping = matrix_cases(REDUCED_FLAPPING, duration) if reduced else []
    return matrix_cases(axes, duration) + flapping + pathological_cases(reduced)


def summarize(
    rows: list[dict[str, str]], by: tuple[str, ...] = ("integrator",)
) -> dict[tuple[str, ...], dict[str, int]]:
    """Counts of each outcome per value of the `by` columns."""
    out: dict[tuple[str, ...], dict[str, int]] = {}
    for r in rows:
        d = out.setdefault(tuple(r[c] for c in by), dict.fromkeys(OUTCOMES, 0))
        d[r["outcome"]] += 1
    return out


def _count_row(label: str, c: dict[str, int]) -> str:
    return f"| {label} | " + " | ".join(str(c[o]) for o in OUTCOMES) + " |"


def headline(rows: list[dict[str, str]]) -> str:
    """One sentence for the README: counts over the whole study."""
    total = summarize(rows, by=())[()]
    per = summarize(rows)
    parts = ", ".join(
        f"{i} {per[(i,)]['plausible']} of {sum(per[(i,)].values())} plausible"
        for i in INTEGRATORS
        if (i,) in per
    )
    return (
        f"{len(rows)} cases: {parts}; {total['implausible']} implausible and "
        f"{total['nonfinite']} non-finite; every other case raised DivergenceError."
    )


def write_report(rows: list[dict[str, str]], path: str, machine: str) -> None:
    head = "| {} | " + " | ".join(OUTCOMES) + " |"
    rule = "|---|" + "---:|" * len(OUTCOMES)
    lines = [
        "# Stability study",
        "",
        "Generated by `flagsim study stability`; rerun it to regenerate this page.",
        "",
        f"Machine: {machine}",
        "",
        "Each case runs the paper's flag (8 x 11 masses, pinned to the pole, gravity, paper "
        "drag, uniform wind along (1, 0, 0.3)) with the settings of its row; springs: "
        "stretch k_s, shear k_s/5, bend k_s/20; strain limit 10 %, energy tolerance 0.1 "
        "(the defaults). Outcomes (docs/energy.md):",
        "",
        "- **plausible**: ran to the end, finite, the energy ledger balanced (to 1e-9 of "
        "the energy scale m g H + m U^2/2; no step, and not the run as a whole, made more "
        "than integrator.energy_tolerance x that scale beyond the stages' work) and strain "
        f"within the scene's promise (strain limit + {STRAIN_SLACK:g});",
        "- **diverged** (reported): DivergenceError raised with the state restored, cause "
        "given; or the scene rejected before any step (ValueError naming the parameter, "
        "cause `rejected: <parameter>`);",
        "- **implausible**: finite but failing the ledger or the strain test (must never "
        "happen);",
        "- **nonfinite**: non-finite output without an error (must never happen).",
        "",
        "`unexplained`: the most energy the run held beyond its stages' work (net integrator "
        "remainder + strain limiting + pole + self-collision since the start), J; `energy "
        "halvings`: the most halvings one step needed, of the step or of an implicit piece, "
        "before it was plausible.",
        "",
        "## Counts",
        "",
        headline(rows),
        "",
        head.format("integrator"),
        rule,
    ]
    for (integ,), c in sorted(summarize(rows).items(), key=lambda kv: INTEGRATORS.index(kv[0][0])):
        lines.append(_count_row(integ, c))
    lines += [
        "",
        "Per integrator and flapping mode:",
        "",
        head.format("integrator, flapping"),
        rule,
    ]
    by_flap = summarize(rows, by=("integrator", "flapping"))
    for integ, flap in itertools.product(INTEGRATORS, FLAPPING):
        if (integ, flap) in by_flap:
            lines.append(_count_row(f"{integ}, {flap}", by_flap[(integ, flap)]))
    causes: dict[str, int] = {}
    for r in rows:
        if r["outcome"] != "plausible":
            key = f"{r['integrator']}: {r['outcome']} ({r['cause']})"
            causes[key] = causes.get(key, 0) + 1
    if causes:
        lines += ["", "Causes: " + ", ".join(f"{k} x {v}" for k, v in sorted(causes.items()))]
    lines += [
        "",
        "## Pathological cases",
        "",
        "| case | integrator | flapping | outcome | cause | max strain | energy range (J) | "
        "unexplained (J) | energy scale (J) | max substeps | energy halvings | wall (s) |",
        "|---|---|---|---|---|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r["kind"] != "matrix":
            lines.append(
                f"| {r['kind']} | {r['integrator']} | {r['flapping']} | {r['outcome']} | "
                f"{r['cause']} | {r['max_strain']} | {r['energy_min']} .. "
                f"{r['energy_max']} | {r['unexplained']} | {r['energy_scale']} | "
                f"{r['max_substeps']} | {r['energy_halvings']} | {r['wall_s']} |"
            )
    lines += [
        "",
        "## Matrix",
        "",
        "| integrator | flapping | k_s (N/m) | wind (m/s) | dt (s) | density (kg/m^2) | "
        "outcome | cause | max strain | unexplained (J) | max substeps | energy halvings | "
        "wall (s) |",
        "|---|---|---:|---:|---:|---:|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r["kind"] == "matrix":
            lines.append(
                f"| {r['integrator']} | {r['flapping']} | {r['k_s']} | {r['wind']} | "
                f"{r['dt']} | {r['density']} | {r['outcome']} | {r['cause']} | "
                f"{r['max_strain']} | {r['unexplained']} | {r['max_substeps']} | "
                f"{r['energy_halvings']} | {r['wall_s']} |"
            )
    from .report import write_text

    write_text(path, "\n".join(lines) + "\n")
