"""The energy ledger from Python, the plausibility check, and a property test: a run of any scene
in the documented parameter ranges ends plausible or reported, never implausible."""

import math

import flagsim
import numpy as np
import pytest
from flagsim.study import stability
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

ENTRIES = (
    "gravity",
    "drag",
    "damping",
    "flap",
    "strain_limit",
    "pole",
    "solids",
    "self_collision",
    "pins",
    "edits",
    "integrator",
)


def total(sim):
    return sum(sim.energy().values())


def test_ledger_balances_every_stage_of_the_paper_scene():
    s = flagsim.Scene.paper()
    s.flapping.mode = "displace"
    s.self_collision.enabled = True
    sim = flagsim.Simulation(s)
    e0 = sim.energy()
    for _ in range(20):
        sim.step(10)
        ledger = sim.energy_ledger()
        assert tuple(ledger) == ENTRIES
        e = sim.energy()
        # E(t) - E(0) = every entry but gravity; kinetic + spring: every entry
        assert total(sim) - sum(e0.values()) == pytest.approx(
            sum(ledger.values()) - ledger["gravity"], abs=1e-12
        )
        assert (e["kinetic"] + e["spring"]) - (e0["kinetic"] + e0["spring"]) == pytest.approx(
            sum(ledger.values()), abs=1e-12
        )
        assert ledger["gravity"] == pytest.approx(-(e["gravity"] - e0["gravity"]), abs=1e-15)
    assert ledger["damping"] < 0 and ledger["integrator"] < 0 and ledger["flap"] != 0


def test_energy_scale_is_m_g_h_plus_half_m_u_squared():
    s = flagsim.Scene.paper()
    sim = flagsim.Simulation(s)
    m = float(np.sum(sim.node_mass))
    H = max(s.flag.width, s.flag.height)
    U = max([np.linalg.norm(v) for _, v in s.air.wind] + [f.max_speed for f in s.air.fans])
    assert sim.energy_scale == pytest.approx(m * 9.81 * H + 0.5 * m * U**2, rel=1e-12)
    s.gravity = (0.0, 0.0, 0.0)
    s.air.model = "none"
    assert flagsim.Simulation(s).energy_scale == pytest.approx(0.5 * m, rel=1e-12)  # 1 m/s


def test_edits_between_steps_show_as_edits():
    sim = flagsim.Simulation(flagsim.Scene.paper())
    sim.step(3)
    before, edits = total(sim), sim.energy_ledger()["edits"]
    v = sim.velocities.copy()
    v[-1] += (0.0, 0.0, 1.0)
    sim.velocities = v
    added = total(sim) - before
    sim.step()
    assert sim.energy_ledger()["edits"] - edits == pytest.approx(added, rel=1e-12)


def heavy_stiff_flag():
    """The plausibility issue's flag: 10 kg/m^2, k_s = 1e7 (soft default shear and bend),
    dt = 0.05, implicit, flapping off."""
    s = flagsim.Scene.paper()
    s.flag.areal_density = 10.0
    s.flag.stretch_stiffness = 1e7
    s.dt = 0.05
    s.flapping.mode = "off"
    return s


def hanging_flag(n):
    """The paper's flag meshed n x n in its 1.5 m/s uniform wind: no grid, no self-collision, no
    flapping."""
    s = flagsim.Scene.paper()
    s.air.model = "uniform"
    s.self_collision.enabled = False
    s.flapping.mode = "off"
    s.flag.rows = s.flag.cols = n
    return s


def test_an_implausible_step_raises_energy_and_leaves_the_state_as_it_was():
    s = heavy_stiff_flag()
    s.integrator.max_halvings = 0  # no shorter pieces to fall back on
    sim = flagsim.Simulation(s)
    with pytest.raises(flagsim.DivergenceError, match=r"integrator\.energy_tolerance") as info:
        for _ in range(40):
            x, v, ledger = sim.positions.copy(), sim.velocities.copy(), sim.energy_ledger()
            sim.step()
    assert info.value.cause == "energy" and info.value.step == sim.step_count
    assert "method = 'implicit'" not in str(info.value)  # it is implicit already
    np.testing.assert_array_equal(sim.positions, x)
    np.testing.assert_array_equal(sim.velocities, v)
    assert sim.energy_ledger() == ledger


def test_the_issues_cases_end_plausible():
    # k_s 1e6 with the paper's flapping held 5e4 J in a 66 g flag; the heavy stiff flag 3e5 J.
    s = flagsim.Scene.paper()
    s.flag.stretch_stiffness = 1e6
    s.flapping.mode = "displace"
    sim = flagsim.Simulation(s)
    sim.step(300)
    assert sim.energy()["spring"] < 0.05 and sim.max_strain() <= 0.12
    sim = flagsim.Simulation(heavy_stiff_flag())
    sim.step(20)
    assert sim.energy()["spring"] < 10.0 and sim.max_strain() <= 0.12


def test_a_flag_blown_back_round_its_pole_slides_on_it_and_makes_no_energy():
    # Wind onto the pole wraps the first free column ~108 degrees round it, its springs and
    # tethers to the pins running as chords through the pole at the strain limit. Strain limiting
    # used to pull those vertices along the chords into the pole and the pole to push them out
    # radially, rounds that left the springs more energy each time: 0.01-0.07 J a step from the
    # pole's stage, DivergenceError at step 88. Now the solve holds them on their contact planes
    # and strain limiting slides them along the surface: the pole's stage has nothing left to do.
    s = flagsim.Scene.paper()
    s.air.model = "uniform"
    s.air.wind = [(0.0, (-3.0, 0.0, 0.0))]
    s.flapping.mode = "off"
    s.self_collision.enabled = False
    sim = flagsim.Simulation(s)
    R = s.pole.radius
    wrapped = 0.0
    for _ in range(30):
        sim.step(10)
        x = sim.positions
        r = np.hypot(x[:, 0] - s.pole.base[0], x[:, 2] - s.pole.base[2])
        assert r.min() >= R * (1 - 1e-12)  # nothing inside the pole
        on_pole = r < 1.01 * R
        wrapped = max(wrapped, np.degrees(np.abs(np.arctan2(x[on_pole, 2], x[on_pole, 0]))).max())
    assert wrapped > 100  # it does wrap round the pole, past the chord's reach through it
    ledger = sim.energy_ledger()
    assert abs(ledger["pole"]) < 1e-3  # was 0.089 J net by step 88
    assert sim.max_strain() <= 0.12


def test_a_flag_hanging_at_its_strain_limit_is_not_counted_as_holding_what_it_never_kept():
    # The paper's flag meshed 32 x 32 in its 1.5 m/s wind (no grid, no flapping) hangs with its
    # top springs at the 10 % strain limit: each step the projection lifts what the solve lets
    # down, and the net the integrator and projections leave over 10 s exceeds the allowance
    # (0.07 against 0.06 J) although the flag holds under 0.01 J of kinetic and spring energy.
    # The run net check counts the net only as far as the flag can still hold it.
    s = hanging_flag(32)
    sim = flagsim.Simulation(s)
    sim.step(1000)
    ledger, e = sim.energy_ledger(), sim.energy()
    net = sum(ledger[k] for k in ("integrator", "strain_limit", "pole", "self_collision"))
    allowed = s.integrator.energy_tolerance * sim.energy_scale
    assert net > allowed  # the unbounded net would have raised
    assert e["kinetic"] + e["spring"] < 0.25 * allowed
    assert sim.max_strain() <= s.integrator.strain_limit + 0.02


def test_a_fine_hanging_flag_holds_its_strain_without_redoing_steps():
    # The paper's flag meshed 48 x 48 in its wind, with 3 strain-limiting sweeps: too few for the
    # springs alone to carry the sag back to the pole. With a tether to its nearest pin only,
    # each vertex could swing down about it; the strain crept to the promise (0.12) and 724 of
    # 400 steps were redone in pieces (the 128 x 128 bench flag's fall from 37.8 to 2.8 steps/s
    # with 50 sweeps, docs/energy.md). The tethers to the pole's two ends hold it: 0.103, none.
    s = hanging_flag(48)
    s.integrator.strain_limit_iterations = 3
    sim = flagsim.Simulation(s)
    worst, redone = 0.0, 0
    for _ in range(400):
        sim.step()
        worst = max(worst, sim.max_strain())
        redone += sim.last_step_stats["energy_halvings"]
    assert redone == 0
    assert worst <= s.integrator.strain_limit + 0.01


def test_energy_tolerance_and_ramp_are_validated_fields():
    s = flagsim.Scene.paper()
    with pytest.raises(ValueError, match=r"integrator\.energy_tolerance should be finite and >= 0"):
        s.integrator.energy_tolerance = -0.1
    with pytest.raises(ValueError, match=r"flapping\.ramp should be finite and >= 0"):
        s.flapping.ramp = math.nan
    s.integrator.energy_tolerance = 0.25
    s.flapping.ramp = 0.0
    back = flagsim.Scene.from_dict(s.to_dict())
    assert back.integrator.energy_tolerance == 0.25 and back.flapping.ramp == 0.0


# Documented ranges (docs/energy.md): stiffness 10..1e7 N/m, 1e-3..10 kg/m^2, wind 0..60 m/s,
# dt 5e-3..5e-2 s, every flapping mode and integrator. The adaptive explicit integrator's cost
# grows as sqrt(k / m) per step, so its draws keep k / density below 1e6 to stay within CI time
# (the stability study covers the corners).
@st.composite
def scene_cases(draw):
    integrator = draw(st.sampled_from(stability.INTEGRATORS))
    density = 10 ** draw(st.floats(-3, 1))
    k_max = min(7.0, math.log10(1e6 * density)) if integrator == "explicit_adaptive" else 7.0
    return dict(
        id="hypothesis",
        kind="matrix",
        integrator=integrator,
        flapping=draw(st.sampled_from(stability.FLAPPING)),
        k_s=10 ** draw(st.floats(1, max(1.0, k_max))),
        wind=draw(st.floats(0, 60)),
        dt=10 ** draw(st.floats(math.log10(5e-3), math.log10(5e-2))),
        density=density,
        duration=0.0,
    )


@settings(
    max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(scene_cases())
def test_every_run_in_the_documented_ranges_ends_plausible_or_reported(case):
    case["duration"] = 150 * case["dt"]  # a few hundred steps at most
    r = stability.run_case(case)
    assert r["outcome"] in ("plausible", "diverged"), (case, r)
    if case["integrator"] != "explicit":
        assert r["outcome"] == "plausible", (case, r)


def test_parameters_that_rule_out_a_plausible_run_are_rejected_before_any_step():
    s = flagsim.Scene.paper()
    s.integrator.max_strain = 0.1  # below what the strain limit promises: any step could raise
    with pytest.raises(
        ValueError,
        match=r"^integrator\.max_strain should be > " r"integrator\.strain_limit \+ 0\.02 = 0\.12",
    ):
        flagsim.Simulation(s)
    s.integrator.strain_limit = 0.0  # no promise, no conflict
    flagsim.Simulation(s)
