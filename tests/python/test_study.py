"""Studies: the reduced stability matrix, convergence orders, reports, resumable executor runs."""
import concurrent.futures as cf
import csv
import math

import numpy as np
import pytest

import flagsim
from flagsim import study
from flagsim.study import accuracy, runner, stability


@pytest.fixture(scope="module")
def stability_rows(tmp_path_factory):
    out = tmp_path_factory.mktemp("stability")
    return study.run_stability(str(out), reduced=True, jobs=2, progress=False), out


def test_reduced_stability_matrix_has_no_silent_nonfinite_result(stability_rows):
    rows, _ = stability_rows
    assert len(rows) == len(stability.cases(reduced=True))
    assert [r["id"] for r in rows if r["outcome"] == "silent_nonfinite"] == []
    assert {r["outcome"] for r in rows} <= {"stable", "diverged"}


@pytest.mark.parametrize("integrator", ["implicit", "explicit_adaptive"])
def test_implicit_and_adaptive_explicit_are_stable_in_every_reduced_case(stability_rows, integrator):
    rows, _ = stability_rows
    bad = [(r["id"], r["cause"]) for r in rows if r["integrator"] == integrator and r["outcome"] != "stable"]
    assert bad == []
    for r in rows:
        if r["integrator"] == integrator:
            # strain limiting (tethers to the pins + Provot, limit 10 %) bounds every spring
            assert float(r["max_strain"]) < 0.15, r["id"]


def test_plain_explicit_reports_its_divergence(stability_rows):
    rows, _ = stability_rows
    diverged = [r for r in rows if r["integrator"] == "explicit" and r["outcome"] == "diverged"]
    assert diverged and all(r["cause"] in ("unstable_step", "strain", "non-finite") for r in diverged)


def test_stability_report_counts_every_case(stability_rows):
    rows, out = stability_rows
    text = (out / "stability.md").read_text()
    counts = stability.summarize(rows)
    for integ, c in counts.items():
        assert f"| {integ} | {c['stable']} | {c['diverged']} | {c['silent_nonfinite']} |" in text


def test_long_conservative_run_keeps_its_energy_with_the_symplectic_integrator(stability_rows):
    rows, _ = stability_rows
    r = next(r for r in rows if r["id"] == "p-long_run_1000s-explicit_adaptive")
    e0, e1 = float(r["energy_min"]), float(r["energy_max"])
    assert r["outcome"] == "stable" and (e1 - e0) < 0.01 * abs(e0)


@pytest.fixture(scope="module")
def accuracy_rows(tmp_path_factory):
    out = tmp_path_factory.mktemp("accuracy")
    return study.run_accuracy(str(out), quick=True, jobs=1, progress=False), out


@pytest.mark.parametrize("method", ["explicit", "implicit"])
def test_spring_pair_converges_at_first_order(accuracy_rows, method):
    rows, _ = accuracy_rows
    q = accuracy.observed_order(rows, "pair", method)
    assert 0.75 < q < 1.25, q


def test_implicit_flag_trajectory_converges_at_first_order(accuracy_rows):
    rows, _ = accuracy_rows
    q = accuracy.observed_order(rows, "trajectory", "implicit")
    assert 0.8 < q < 1.3, q


def test_accuracy_report_files(accuracy_rows):
    rows, out = accuracy_rows
    with open(out / "accuracy.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert list(table[0].keys()) == accuracy.COLUMNS and len(table) == len(rows)
    for r in table:
        if r["error"]:
            assert math.isfinite(float(r["error"])) and float(r["seconds_per_step"]) > 0
    text = (out / "accuracy.md").read_text()
    assert "Observed convergence orders" in text and "Pareto" in text
    for part in ("pair", "trajectory", "banner"):
        png = out / f"accuracy_{part}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pareto_front():
    pts = [(1.0, 5.0), (2.0, 1.0), (3.0, 2.0), (0.5, 9.0), (4.0, 0.5)]
    assert sorted(accuracy.pareto(pts)) == [0, 1, 3, 4]


def _square(case):
    return {"value": case["x"] ** 2}


def test_runner_resumes_after_an_interruption(tmp_path):
    cases = [{"id": f"c{i}", "x": i} for i in range(6)]
    path = str(tmp_path / "runs.csv")
    calls = []

    def flaky(case):
        calls.append(case["id"])
        if case["x"] == 3:
            raise KeyboardInterrupt
        return _square(case)

    with pytest.raises(KeyboardInterrupt):
        runner.run_cases(cases, flaky, path, ["id", "x", "value"], progress=False)
    with open(path, "a") as f:
        f.write("c9,9,8")  # a torn line from a crash mid-write
    calls.clear()
    rows = runner.run_cases(cases, flaky_ok := _square, path, ["id", "x", "value"], progress=False)
    assert [r["value"] for r in rows] == [str(i * i) for i in range(6)]
    assert len(runner.read_rows(path)) == 6
    del flaky_ok


def test_results_do_not_depend_on_executor_or_order(tmp_path):
    cases = [{"id": f"c{i}", "x": i} for i in range(8)]
    serial = runner.run_cases(cases, _square, str(tmp_path / "a.csv"), ["id", "x", "value"], progress=False)
    with cf.ThreadPoolExecutor(max_workers=3) as ex:
        pooled = runner.run_cases(cases, _square, str(tmp_path / "b.csv"), ["id", "x", "value"],
                                  executor=ex, progress=False)
    assert serial == pooled


def test_stability_case_is_a_pure_function_of_its_settings():
    case = stability.cases(reduced=True)[5]
    a, b = stability.run_case(case), stability.run_case(case)
    a.pop("wall_s"), b.pop("wall_s")
    assert a == b


@pytest.mark.skipif(not hasattr(flagsim, "Fluid"), reason="needs the air solver")
def test_air_orders_semi_lagrangian_about_one_maccormack_clearly_higher_in_space(accuracy_rows):
    rows, _ = accuracy_rows
    p = "fft" if flagsim.has_fftw() else "pcg"
    sl = -accuracy.observed_order(rows, "air", "semi_lagrangian", key="resolution", pressure=p,
                                  tolerance=repr(1e-8), refinement="cfl")
    assert 0.6 < sl < 1.3, sl
    sl_h2 = -accuracy.observed_order(rows, "air", "semi_lagrangian", key="resolution", pressure=p,
                                     tolerance=repr(1e-8), refinement="dt~h^2")
    mc_h2 = -accuracy.observed_order(rows, "air", "maccormack", key="resolution", pressure=p,
                                     tolerance=repr(1e-8), refinement="dt~h^2")
    assert mc_h2 > 1.3 and mc_h2 > sl_h2 + 0.6, (sl_h2, mc_h2)
