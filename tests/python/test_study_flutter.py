"""flagsim study flutter: its estimators on signals with known answers, the free-flag formula
against a hand value, and the quick study end to end (finite, physically ordered)."""

import csv
import math

import flagsim
import numpy as np
import pytest
from flagsim import cli
from flagsim.study import flutter

DT = 0.01


@pytest.mark.parametrize("f", [0.8, 1.5, 2.37, 6.1, 13.3])
def test_peak_frequency_recovers_a_sine_between_bins(f):
    rng = np.random.default_rng(1)
    t = np.arange(2000) * DT  # 20 s: five 4 s segments, 0.25 Hz bins
    z = 0.04 * np.sin(2 * np.pi * f * t + 0.3) + 0.2 + 0.004 * rng.standard_normal(len(t))
    assert flutter.peak_frequency(z, DT) == pytest.approx(f, abs=0.01)


def test_peak_frequency_of_a_still_signal_is_nan_and_bad_input_is_named():
    assert math.isnan(flutter.peak_frequency(np.full(500, 0.3), DT))
    with pytest.raises(ValueError, match="dt should be > 0"):
        flutter.peak_frequency(np.zeros(100), 0.0)
    with pytest.raises(ValueError, match="signal should be finite"):
        flutter.peak_frequency(np.array([0.0, np.nan] * 10), DT)
    with pytest.raises(ValueError, match="signal should be a 1-D array"):
        flutter.peak_frequency(np.zeros((10, 2)), DT)


def test_peak_to_peak_of_a_sine_is_twice_its_amplitude():
    t = np.arange(1000) * DT
    assert flutter.peak_to_peak(0.07 * np.sin(2 * np.pi * 2 * t) - 1) == pytest.approx(
        0.14, rel=1e-3
    )


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_travelling_wave_recovers_a_known_wave_length_and_speed(direction):
    # z = a(x) sin(2 pi f t - k x): crests move at f lambda towards +x (or -x when k < 0); the
    # amplitude grows from the pinned edge, whose point does not move at all
    f, lam = 2.3, 0.55
    k = direction * 2 * np.pi / lam
    x = np.linspace(0.055, 0.865, 11)
    t = np.arange(1500)[:, None] * DT
    z = (x - x[0]) * np.sin(2 * np.pi * f * t - k * x)
    got_lam, got_c = flutter.travelling_wave(z, x, DT, flutter.peak_frequency(z[:, -1], DT))
    assert got_lam == pytest.approx(lam, rel=0.01)
    assert got_c == pytest.approx(direction * f * lam, rel=0.01)


def test_travelling_wave_without_motion_is_nan():
    x = np.linspace(0, 1, 5)
    assert all(math.isnan(v) for v in flutter.travelling_wave(np.zeros((100, 5)), x, DT, 2.0))
    with pytest.raises(ValueError, match="x should have one position per column"):
        flutter.travelling_wave(np.zeros((100, 5)), x[:4], DT, 2.0)


def test_free_flag_force_coefficient_matches_a_hand_value():
    # the paper's flag: m_f = 0.15 kg/m^2, rho = 1.2 kg/m^3, h = 0.54 m, A = 0.81 x 0.54 m^2:
    # 0.15 / (1.2 x 0.54) = 0.231481; (0.4374 / 0.2916)^-1.25 = 1.5^-1.25 = 0.602401;
    # 0.02 + 0.7 x 0.231481 x 0.602401 = 0.117612
    assert flutter.free_flag_force_coefficient(0.15, 1.2, 0.54, 0.4374) == pytest.approx(
        0.117612, abs=2e-6
    )
    assert flutter.reference_force_coefficient() == pytest.approx(0.117612, abs=2e-6)
    # heavier cloth flutters harder and pulls more (the formula's only physics)
    assert flutter.free_flag_force_coefficient(0.3, 1.2, 0.54, 0.4374) > 0.2
    with pytest.raises(ValueError, match="height should be a finite number > 0"):
        flutter.free_flag_force_coefficient(0.15, 1.2, 0.0, 0.4374)


def test_scene_for_names_a_bad_model_drag_or_speed():
    with pytest.raises(ValueError, match="model should be one of"):
        flutter.scene_for("storm", "paper", 2.0)
    with pytest.raises(ValueError, match="drag should be one of"):
        flutter.scene_for("eq5", "plate", 2.0)
    with pytest.raises(ValueError, match="speed should be a finite number >= 0"):
        flutter.scene_for("eq5", "paper", -1.0)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("flutter")
    docs = out / "docs"
    code = cli.main(
        ["study", "flutter", "--quick", "--quiet", "--out", str(out), "--docs", str(docs)]
    )
    assert code == 0
    with open(out / "flutter.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return rows, out, docs


def _by(rows, model, drag):
    return {float(r["speed"]): r for r in rows if r["model"] == model and r["drag"] == drag}


def test_quick_study_runs_every_case_to_finite_figures(quick):
    rows, _, _ = quick
    assert [r["id"] for r in rows] == [c["id"] for c in flutter.cases(quick=True)]
    for r in rows:
        assert "diverged" not in r["state"], r["id"]
        keys = ["droop", "force", "cost"]
        if float(r["speed"]) > 0:
            keys += ["frequency", "amplitude", "strouhal", "force_coefficient"]
        for k in keys:
            assert math.isfinite(float(r[k])), (r["id"], k)
        assert float(r["cost"]) > 0


def test_quick_study_droop_falls_as_the_wind_rises(quick):
    rows, _, _ = quick
    for model in ("eq5", "turbulence"):
        for drag in flutter.DRAGS:
            droop = [float(r["droop"]) for _, r in sorted(_by(rows, model, drag).items())]
            assert droop[0] > 30.0, (model, drag, droop)  # still air: falls (a flat one stays ~3)
            assert all(a > b for a, b in zip(droop, droop[1:])), (model, drag, droop)


def test_quick_study_pole_force_of_the_paper_drag_is_its_coefficient(quick):
    # eq. 3 pushes every mass by 1/2 C_D rho S |u| u whatever the flag's orientation, so once the
    # flag streams the mean pull on the pole is C_D (1/2 rho U^2 A): a check of the whole step's
    # momentum balance that measures the pole force (turbulence adds its few per cent of |u| u)
    rows, _, _ = quick
    cd = flagsim.Scene.paper().drag.coefficient
    for model in ("eq5", "turbulence"):
        for u, r in _by(rows, model, "paper").items():
            if u > 0:
                assert float(r["force_coefficient"]) == pytest.approx(cd, rel=0.05), r["id"]
                # sim.pole_impulse's balance of the integrate stage alone: never more, and at
                # 10 m/s short by the strain limiter's pull on the pins (docs/flutter.md)
                assert float(r["force_core"]) <= float(r["force"]) * 1.01, r["id"]


def test_quick_study_flat_plate_drag_falls_with_wind_towards_the_wind_codes(quick):
    # the triangle (flat-plate) drag sees the flag's attitude: a drooping flag at low wind meets
    # the air at an angle, a streaming one mostly by skin friction, so c_f falls with U (as flag
    # measurements do) and stays far below eq. 3's C_D
    rows, _, _ = quick
    for model in ("eq5", "turbulence"):
        cf = [
            float(r["force_coefficient"])
            for u, r in sorted(_by(rows, model, "triangle").items())
            if u > 0
        ]
        assert cf[0] > cf[-1] > 0, (model, cf)
        assert cf[0] < 0.5, (model, cf)


def test_quick_study_eq5_waves_run_from_pole_to_fly_at_a_frequency_wind_does_not_set(quick):
    # eq. 5 paints waves moving at flapping.speed flag lengths per second: the wind scales their
    # height (u_p) but not their frequency, unlike a real flag's
    rows, _, _ = quick
    for drag in flutter.DRAGS:
        runs = [r for u, r in sorted(_by(rows, "eq5", drag).items()) if u > 0]
        assert all(float(r["wave_speed"]) > 0 for r in runs), drag
        f = [float(r["frequency"]) for r in runs]
        assert f[-1] == pytest.approx(f[0], rel=0.1), (drag, f)


def test_quick_study_writes_its_report_and_plot(quick):
    rows, out, docs = quick
    report = (docs / "flutter.md").read_text()
    assert "EN 1991-1-4" in report and f"{flutter.reference_force_coefficient():.3f}" in report
    assert "![flutter](images/flutter.png)" in report
    assert (docs / "images" / "flutter.png").stat().st_size > 10_000
    every_run = report.split("## Every run")[1]
    assert every_run.count("\n| ") == len(rows) + 1  # the header and one line per run


def test_quick_study_plot_gives_each_series_one_style_in_every_panel(quick):
    # one legend names the series of all panels, so a series must look the same in each, also
    # where a panel lacks another (the peak figures leave out runs without a flapping peak)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, _, _ = quick
    # the first series in the plot's order without a flapping peak: every later one moves up a
    # place in the peak figures' panels
    first = min((r["model"], r["drag"]) for r in rows)
    rows = [
        dict(r, state="no flapping peak") if (r["model"], r["drag"]) == first else r for r in rows
    ]
    fig = flutter._figure(rows)
    styles: dict[str, tuple] = {}
    counts = []
    for ax in fig.axes[:-1]:
        lines = [ln for ln in ax.get_lines() if ", " in ln.get_label()]
        counts.append(len(lines))
        for ln in lines:
            style = (ln.get_color(), ln.get_linestyle(), ln.get_marker())
            assert styles.setdefault(ln.get_label(), style) == style, ln.get_label()
    legend = fig.axes[-1].get_legend()
    for handle, text in zip(legend.legend_handles, legend.get_texts()):
        if text.get_text() in styles:
            style = (handle.get_color(), handle.get_linestyle(), handle.get_marker())
            assert style == styles[text.get_text()], text.get_text()
    plt.close(fig)
    assert len(set(styles.values())) == len(styles)  # no two series alike
    assert min(counts) < max(counts)  # the case this guards: a panel with fewer series


def test_a_flapping_peak_is_a_sine_not_slow_wandering():
    t = np.arange(2000) * DT
    assert flutter.has_flapping_peak(np.sin(2 * np.pi * 1.7 * t), DT)
    rng = np.random.default_rng(3)
    walk = np.cumsum(rng.standard_normal(len(t))) * 1e-3  # red: power falls as 1 / f^2
    assert not flutter.has_flapping_peak(walk, DT)
    assert flutter.has_flapping_peak(walk + 0.05 * np.sin(2 * np.pi * 3.1 * t), DT)
