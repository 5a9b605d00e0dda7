"""benchmarks (python -m benchmarks): the smoke run writes its CSV, table and plot; the protocol,
the selection, the peers' cloth and the feature detection behave. No wall-clock figure is
asserted anywhere."""

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import flagsim
import numpy as np
import pytest
from _optional import missing, require

import benchmarks as bench
from benchmarks import engines, peers, report, worker, workloads
from benchmarks.command import selection


def _figures_ok(row):
    for col in report.FIGURES:
        v = float(row[col])
        assert math.isfinite(v) and v > 0, (row["variant"], row["size"], col, row[col])
    # what the workload added to the process's peak memory, never more than that peak
    assert 0 <= float(row["workload_mb"]) <= float(row["peak_rss_mb"])


def test_smoke_run_writes_csv_table_and_plot(tmp_path, capsys):
    out = tmp_path / "bench"
    assert bench.main(["--quick", "--out", str(out)]) == 0  # the issue's CI smoke run
    printed = capsys.readouterr().out
    for name in ("results.csv", "results.md", "scaling.png", "results.json"):
        assert (out / name).is_file(), name

    with open(out / "results.csv", encoding="utf-8") as f:
        header = [line for line in f if line.startswith("#")]
    machine = dict(line[2:].rstrip("\n").split(": ", 1) for line in header)
    for key in (
        "cpu",
        "logical_cpus",
        "compiler",
        "cxx_flags",
        "git_revision",
        "numpy",
        "fftw",
        "openmp",
        "load_average_start",
    ):
        assert machine.get(key), key
    rows = report.read_csv(out / "results.csv")
    assert rows and list(rows[0]) == list(report.COLUMNS)
    groups = {r["group"] for r in rows}
    assert {"paper", "cloth"} <= groups
    for r in rows:
        assert r["ok"] == "True", r
        _figures_ok(r)
        for k in ("probe_ms_before", "probe_ms_after"):  # the speed probe around each workload
            assert math.isfinite(float(r[k])) and float(r[k]) > 0, (r["variant"], k)
        assert (
            int(r["steps_per_run"]) >= 1
            and int(r["runs"]) == workloads.PROTOCOLS["quick"]["repeats"]
        )
        assert float(r["steps_per_s"]) == pytest.approx(1e3 / float(r["ms_median"]), rel=1e-4)
        assert float(r["ms_min"]) <= float(r["ms_median"])
    paper = [r for r in rows if r["group"] == "paper"][0]
    assert "integrate" in paper["stage_split"] and "stages:" in paper["note"]

    md = (out / "results.md").read_text(encoding="utf-8")
    assert "## Machine" in md and "## Paper scene" in md and "## Targets (issues 8 and 23)" in md
    assert md.count("| flagsim |") >= len([r for r in rows if r["engine"] == "flagsim"])
    png = (out / "scaling.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert data["protocol"] == workloads.PROTOCOLS["quick"]
    assert data["speed_probe"]["workloads"] == len(rows)
    assert "Speed probe (the same" in md and "Speed probe (the same" in printed
    # one progress line per workload, and a line for everything skipped
    assert printed.count("steps/s (median") == len(rows)
    for what, _ in data["skipped"]:
        assert f"skip {what}:" in printed


def test_docs_report_is_written_with_its_plot(tmp_path):
    docs = tmp_path / "docs" / "performance.md"
    assert (
        bench.main(
            [
                "--smoke",
                "--only",
                "cloth",
                "--integrators",
                "explicit",
                "--out",
                str(tmp_path / "o"),
                "--docs",
                str(docs),
            ]
        )
        == 0
    )
    text = docs.read_text(encoding="utf-8")
    assert text.startswith("# flagsim performance") and "Do not edit by hand" in text
    assert "![cost against size](performance.png)" in text
    assert (tmp_path / "docs" / "performance.png").is_file()


def test_peers_run_the_same_cloth_or_are_skipped_with_a_line(tmp_path, capsys):
    out = tmp_path / "peers"
    assert bench.main(["--smoke", "--only", "peers", "--sizes", "8x11", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    rows = report.read_csv(out / "results.csv")
    comps = report.read_csv(out / "peers.csv") if (out / "peers.csv").exists() else []
    for name, (_module, display, _) in peers.PEERS.items():
        ran = [r for r in rows if r["engine"] == name]
        if peers.peer_available(name)[0]:
            assert len(ran) == 1 and ran[0]["ok"] == "True", ran
            _figures_ok(ran[0])
            c = [c for c in comps if c["peer"] == name]
            assert len(c) == 1 and float(c[0]["ratio"]) > 0
            assert float(c[0]["ratio"]) == pytest.approx(
                float(c[0]["flagsim_steps_per_s"]) / float(c[0]["peer_steps_per_s"]), rel=1e-4
            )
        else:
            assert not ran
            assert f"skip peer {name}: {display} is not installed" in printed
    md = (out / "results.md").read_text(encoding="utf-8")
    if comps:
        assert "## Side by side with the peers" in md


@pytest.mark.parametrize("name", list(peers.PEERS))
def test_peer_flag_starts_where_flagsims_does(name):
    if not peers.peer_available(name)[0]:
        pytest.skip(f"{name} not installed")
    sim = flagsim.Simulation(engines.cloth_scene(5, 7))
    p = peers.make(name, 5, 7)
    np.testing.assert_allclose(p.positions(), sim.rest_positions, atol=1e-6)
    assert peers.structural_strain(p.spec, p.positions()) < 1e-6
    p.step(3)
    assert p.ok()
    p.close()


class TearingPeer(peers.PeerStepper):
    """A peer whose cloth holds for `holds` steps and then has its free corner flung 1 m out."""

    def __init__(self, holds):
        self.spec = peers.cloth_spec(5, 7)
        self.x, _ = peers.flag_mesh(self.spec)
        self.holds, self.steps = holds, 0

    def step(self, n):
        self.steps += n
        if self.steps > self.holds:
            self.x[-1, 2] = 1.0

    def positions(self):
        return self.x.copy()


class SubstepPeer(TearingPeer):
    """Holds only with at least `needs` substeps; load(n) rebuilds it from rest."""

    def __init__(self, needs):
        super().__init__(holds=10**9)
        self.needs, self.loads = needs, []

    def load(self, n):
        self.loads.append(n)
        self.x, _ = peers.flag_mesh(self.spec)
        self.steps, self.holds = 0, (10**9 if n >= self.needs else 7)


@pytest.mark.parametrize("needs, picked", [(1, 5), (5, 5), (11, 20), (80, 80)])
def test_the_substep_search_picks_the_smallest_count_that_holds_and_restarts_from_rest(
    needs, picked
):
    p = SubstepPeer(needs)
    assert p._smallest_stable((5, 10, 20, 40, 80), p.load) == picked
    tried = [n for n in (5, 10, 20, 40, 80) if n <= picked]
    assert p.loads == tried + [picked]  # the last load starts the timed runs from rest
    assert p.steps == 0 and peers.structural_strain(p.spec, p.positions()) < 1e-12


def test_the_substep_search_fails_when_no_count_holds():
    p = SubstepPeer(needs=1000)
    with pytest.raises(RuntimeError, match="unstable at every substep count up to 80"):
        p._smallest_stable((5, 10, 20, 40, 80), p.load)


@pytest.mark.parametrize("holds, ok", [(10**9, True), (1, False)])
def test_a_peer_torn_after_the_timed_runs_fails_its_row(monkeypatch, holds, ok):
    # A short stability try can pass a peer that blows up later (PyBullet at 128 x 128 did, with
    # 16 substeps): its steps/s must not reach the table as a figure.
    monkeypatch.setattr(peers, "make", lambda name, rows, cols: TearingPeer(holds))
    spec = {
        "name": "peers/fake/5x7/t1",
        "threads": 1,
        "protocol": {"min_time": 0.0, "repeats": 2, "warmup": 3},
        "params": {"kind": "peer", "peer": "fake", "rows": 5, "cols": 7},
    }
    result = worker.run(spec)
    assert result["ok"] is ok
    strain = result["info"]["max_strain"]
    assert (strain < 1e-12) if ok else (strain > peers.TORN_STRAIN)
    if not ok:
        assert result["error"] == "state not finite or torn apart after the runs"
        w = SimpleNamespace(
            group="peers", engine="fake", variant="cloth", size="5x7", n=35, threads=1
        )
        note = report.make_row(w, result)["note"]
        assert note.count(f"max strain {strain:.2g}") == 1 and note.endswith(result["error"]), note


def test_flag_mesh_matches_flagsim_topology():
    sim = flagsim.Simulation(engines.cloth_scene(6, 9))
    spec = peers.cloth_spec(6, 9)
    x, tris = peers.flag_mesh(spec)
    np.testing.assert_allclose(x, sim.rest_positions, atol=1e-12)
    assert sorted(map(tuple, np.sort(tris, axis=1))) == sorted(
        map(tuple, np.sort(sim.triangles, axis=1))
    )
    np.testing.assert_array_equal(np.flatnonzero(sim.pinned), peers.pole_pins(spec))
    assert spec["areal_density"] * spec["width"] * spec["height"] == pytest.approx(
        sim.node_mass.sum()
    )


class FakeClock:
    """perf_counter/process_time stand-in: a step costs exactly `cost` seconds."""

    def __init__(self, cost):
        self.t, self.cost, self.steps = 0.0, cost, 0

    def __call__(self):
        return self.t

    def step(self, n):
        self.steps += n
        self.t += n * self.cost

    def timings(self):
        return {"a": 0.25 * self.t, "b": 0.75 * self.t}


def test_protocol_drops_warmup_grows_runs_to_min_time_and_splits_stages(monkeypatch):
    clock = FakeClock(cost=1e-3)
    monkeypatch.setattr(worker.time, "perf_counter", clock)
    monkeypatch.setattr(worker.time, "process_time", clock)
    r = worker.measure(clock, min_time=0.5, repeats=3, warmup=7)
    n = r["steps_per_run"]
    assert n * clock.cost >= 0.5 and r["runs"] == 3
    assert r["wall_s"] == pytest.approx([1e-3] * 3) and r["cpu_s"] == pytest.approx([1e-3] * 3)
    assert r["stages_s"] == pytest.approx({"a": 0.25e-3, "b": 0.75e-3})
    assert clock.steps > 7 + 3 * n  # warm-up and calibration steps are not in the runs


def test_the_speed_probe_summary_says_when_the_machine_changed_speed_during_a_run():
    def row(before, after, ok=True):
        return {"ok": ok, "probe_ms_before": before, "probe_ms_after": after}

    steady = [row(13.0, 13.2), row(13.1, 12.9)]
    s = report.probe_summary(steady + [row(40.0, 40.0, ok=False), row("", "")])
    assert s == pytest.approx(
        {"workloads": 2, "min_ms": 12.9, "median_ms": 13.05, "max_ms": 13.2, "spread": 13.2 / 12.9}
    )  # failed rows and rows without readings left out
    assert "12.9-13.2 ms" in report.probe_sentence(s)
    assert "moved" not in report.probe_sentence(s)
    bimodal = report.probe_summary(steady + [row("19.1", "13.0")])  # as read back from the CSV
    assert bimodal["spread"] == pytest.approx(19.1 / 12.9)
    assert "moved by more than 10 %" in report.probe_sentence(bimodal)
    assert report.probe_summary([row("", "")]) is None and report.probe_sentence(None) == ""
    # the wall-clock targets carry the readings around their own workload
    paper = {"group": "paper", "variant": "full", "threads": 1, "ok": True, "steps_per_s": 4500.0}
    (target,) = [
        t for t in report.targets([dict(paper, **row(13.0, 19.1))], [], None) if "1 thread" in t[0]
    ]
    assert (
        target[1] == "4,500 steps/s (speed probe 13 / 19.1 ms before / after)"
        and target[2] == "missed"
    )


def test_loglog_slope_and_stage_split():
    n = [100, 1000, 10000]
    assert report.loglog_slope(n, [2 * k**1.5 for k in n]) == pytest.approx(1.5)
    assert report.loglog_slope([64], [1.0]) is None
    assert (
        report.stage_split({"integrate": 3.0, "springs": 1.0, "check": 0.0})
        == "integrate 75%, springs 25%"
    )


def _features(**available):
    names = ("fluid", "self_collision", "flapping", "grid_air")
    return {
        k: (available.get(k, False), "" if available.get(k, False) else f"no {k} here")
        for k in names
    }


def test_workloads_needing_missing_parts_are_skipped_with_the_reason():
    sel = workloads.Selection(mode="full", groups=("paper", "cloth", "air"))
    work, skipped = workloads.catalogue(sel, _features(), baselines={"fftw": (True, "")})
    assert not any(w.group == "air" and w.engine == "flagsim" for w in work)
    assert not any("self-collision" in w.variant or w.variant == "full" for w in work)
    why = dict(skipped)
    assert "no fluid here" in why["air alone (flagsim.Fluid)"]
    assert "no self_collision here" in why["cloth with self-collision"]
    assert (
        "no grid_air here"
        in why["paper scene, full pipeline (grid air + self-collision + flapping)"]
    )

    everything = _features(fluid=True, self_collision=True, flapping=True, grid_air=True)
    work, skipped = workloads.catalogue(sel, everything, baselines={"fftw": (True, "")})
    assert not skipped
    names = {w.name for w in work}
    # the issue's grid: every integrator x self-collision x size x thread count ...
    for integ in workloads.INTEGRATORS:
        for sc in ("", "+self-collision"):
            for r, c in workloads.CLOTH_SIZES:
                for t in workloads.THREADS:
                    assert f"cloth/flagsim/{integ}{sc}/{r}x{c}/t{t}" in names
    # ... and every advection x pressure x size x thread count, the float grid and the FFTW floor
    for adv in ("sl", "maccormack"):
        for pres in workloads.PRESSURE:
            for n in workloads.AIR_SIZES:
                for t in workloads.THREADS:
                    assert f"air/flagsim/{adv}/{pres}/{n}^3/t{t}" in names
    assert {f"air/flagsim/sl/fft/float/{n}^3/t1" for n in workloads.AIR_SIZES} <= names
    assert {f"air/fftw/3r2c+3c2r/{n}^3/t1" for n in workloads.AIR_SIZES} <= names
    assert {"paper/flagsim/full/8x11/t1", "paper/flagsim/full/8x11/t2"} <= names
    # issue 28: the air beside the cloth against the serial order in the same run, two-way lagged
    # (pipelined) and serial, and the large scene (Scene.large) at every thread count
    large = workloads.LARGE_SIZE
    assert {
        "paper/flagsim/full/serial/8x11/t2",
        "paper/flagsim/full/two_way_lagged/8x11/t1",
        "paper/flagsim/full/two_way_lagged/8x11/t2",
        "paper/flagsim/full/two_way/8x11/t2",
        f"paper/flagsim/large/{large}/t1",
        f"paper/flagsim/large/{large}/t2",
        f"paper/flagsim/large/serial/{large}/t2",
    } <= names
    assert len(names) == len(work)


def test_solver_workloads_cover_the_issues_grid_or_say_why_not():
    sel = workloads.Selection(mode="full", groups=("solver",))
    everything = _features(fluid=True)
    names = {w.name for w in workloads.catalogue(sel, everything)[0]}
    for boundary, pressure in workloads.SOLVERS:
        for n in workloads.AIR_SIZES:
            for t in workloads.THREADS:
                assert f"solver/flagsim/{boundary}/{pressure}/{n}^3/t{t}" in names
    work, skipped = workloads.catalogue(sel, _features())
    assert not work and "no fluid here" in dict(skipped)["pressure solvers"]
    no_fft = dict(everything, fft=(False, "built without FFTW"))
    work, skipped = workloads.catalogue(sel, no_fft)
    assert not any(w.variant.endswith("/fft") for w in work) and work
    assert dict(skipped)["solver periodic/fft"] == "built without FFTW"


def test_solver_smoke_run_reports_iterations_projection_and_targets(tmp_path):
    out = tmp_path / "solver"
    assert bench.main(["--smoke", "--only", "solver", "--no-plot", "--out", str(out)]) == 0
    rows = report.read_csv(out / "results.csv")
    variants = {r["variant"]: r for r in rows}
    assert {"tunnel+solid/multigrid", "periodic/multigrid"} <= set(variants)
    for r in rows:
        assert r["group"] == "solver" and r["ok"] == "True", r
        _figures_ok(r)
        assert 0 < float(r["project_ms"]) <= float(r["ms_median"])  # a stage of the step
        if r["variant"].endswith("multigrid"):
            assert 1 <= float(r["iterations"]) <= 15
        else:
            assert r["iterations"] == ""  # fft does not iterate
    md = (out / "results.md").read_text(encoding="utf-8")
    assert "## Pressure solvers" in md and "multigrid (tunnel + solid) / fft (periodic)" in md
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    targets = {t[0]: t for t in data["targets"]}
    flat = [t for name, t in targets.items() if "iterations to 1e-8 about flat" in name]
    assert flat and "16^3: " in flat[0][1]


def test_quick_selection_is_smaller_and_flags_narrow_it():
    import argparse

    parser = argparse.ArgumentParser()
    bench.configure(parser)
    everything = _features(fluid=True, self_collision=True, flapping=True, grid_air=True)

    def names(argv):
        sel, proto = selection(parser.parse_args(argv))
        return [w.name for w in workloads.catalogue(sel, everything)[0]], proto

    full, quick = names([])[0], names(["--quick"])[0]
    assert 0 < len(quick) < len(full) / 2
    work, proto = names(
        [
            "--only",
            "cloth",
            "--sizes",
            "8x11,64",
            "--threads",
            "2",
            "--integrators",
            "explicit",
            "--no-self-collision",
            "--min-time",
            "0.3",
        ]
    )
    assert work == ["cloth/flagsim/explicit/8x11/t2"]
    assert proto["min_time"] == 0.3


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--sizes", "8by11"], "--sizes should list ROWSxCOLS"),
        (["--threads", "0"], "--threads should be"),
        (
            ["--only", "cloth,wind"],
            "--only should be a comma-separated list among paper, cloth, air, solver, multiflag, "
            "peers",
        ),
        (["--pressure", "jacobi"], "--pressure should be"),
        (["--repeats", "0"], "--repeats should be >= 1, got 0"),
    ],
)
def test_bad_selections_exit_2_with_a_message(argv, message, capsys, tmp_path):
    assert bench.main(argv + ["--out", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err
    assert not os.listdir(tmp_path)


def test_list_runs_nothing(capsys, tmp_path):
    assert bench.main(["--list", "--smoke", "--out", str(tmp_path / "x")]) == 0
    out = capsys.readouterr().out
    assert "paper/flagsim/builtin/8x11/t1" in out and "workloads," in out
    assert not (tmp_path / "x").exists()


def test_build_info_describes_the_compiled_module():
    info = flagsim._core.build_info()
    assert info["compiler"] and info["build_type"] and isinstance(info["cxx_flags"], str)
    assert info["openmp"] == flagsim.has_openmp() and info["fftw"] == flagsim.has_fftw()
    if info["fftw"]:
        assert info["fftw_version"].startswith("fftw-3")
    assert info["eigen"].count(".") == 2


def test_fftw_floor_transforms_round_trip():
    if not engines.fftw_available()[0]:
        pytest.skip("libfftw3 not found")
    s = engines.FftwFloorStepper(8)
    before = [r.copy() for r in s.real]
    s.step(2)  # forward + normalised inverse is the identity
    for a, b in zip(before, s.real):
        np.testing.assert_allclose(a, b, atol=1e-12)
    assert s.ok()


def test_import_flagsim_bench_loads_no_plotting_or_peers():
    code = (
        "import sys, benchmarks; "
        "bad = [m for m in ('matplotlib', 'pybullet', 'mujoco', 'pypbd') if m in sys.modules]; "
        "print(bad)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"


def test_bench_runs_as_python_m_benchmarks_and_is_not_in_the_package(capsys):
    # The benchmarks live outside the product: the flagsim command and package know nothing of
    # them, and `python -m benchmarks` (the repository root on the path) runs them.
    from flagsim import cli

    assert "bench" not in cli.COMMANDS
    assert bench.main(["--list", "--smoke"]) == 0
    assert "cloth/flagsim/implicit/8x11/t1" in capsys.readouterr().out
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks", "--list", "--smoke"],
        cwd=root,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0 and "cloth/flagsim/implicit/8x11/t1" in proc.stdout, proc.stderr


def test_cloth_workloads_keep_the_papers_thickness_to_spacing_ratio():
    # Every size is the same problem meshed finer (the self-collision slope compares them): the
    # paper's own thickness at the paper's mesh, and the same ratio to the spacing at the others.
    paper = engines.plain_paper_scene()
    ratio = paper.self_collision.thickness / engines._spacing(paper.flag)
    for rows, cols in [(8, 11), (32, 32), (64, 64), (128, 128)]:
        s = engines.cloth_scene(rows, cols, "implicit", self_collision=True)
        assert s.self_collision.thickness / engines._spacing(s.flag) == pytest.approx(
            ratio, rel=1e-12
        )
        assert s.self_collision.thickness < 0.5 * engines._spacing(s.flag)
    assert engines.cloth_scene(
        8, 11, self_collision=True
    ).self_collision.thickness == pytest.approx(paper.self_collision.thickness, rel=1e-12)


@pytest.mark.parametrize("rows, cols", [(8, 11), (128, 128)])
def test_cloth_workloads_build_at_every_size_with_self_collision(rows, cols):
    assert engines.features()["self_collision"] == (True, "")  # detected: the cloth rows run
    sim = flagsim.Simulation(engines.cloth_scene(rows, cols, "implicit", self_collision=True))
    assert "self_collision" in sim.stages and "fluid" not in sim.stages


def test_cluster_smoke_run_reports_times_and_ratios(tmp_path, capsys):
    require(missing("distributed", "distributed"))
    from benchmarks import cluster

    out = tmp_path / "bench"
    assert cluster.main(["--smoke", "--out", str(out)]) == 0
    capsys.readouterr()
    with open(out / "cluster.csv", encoding="utf-8") as f:
        lines = f.read().splitlines()
    machine = dict(line[2:].split(": ", 1) for line in lines if line.startswith("#"))
    assert machine["cpu"] and machine["load_average_end"]
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    assert [(r["executor"], r["workers"]) for r in rows] == [
        ("here", "1"),
        ("pool", "2"),
        ("dask", "1"),
        ("dask", "2"),
        ("dask", "1"),
    ]
    for r in rows:
        assert float(r["wall_s_min"]) > 0
    assert float(rows[3]["speedup_2v1"]) == pytest.approx(
        float(rows[2]["wall_s_min"]) / float(rows[3]["wall_s_min"]), rel=0.02
    )
    assert float(rows[3]["dask_over_pool"]) > 0 and rows[4]["workload"].endswith("start-up")


def test_taichi_air_peer_keeps_a_uniform_wind_or_is_skipped_with_a_line(tmp_path):
    """The second air peer (benchmarks/taichi_air.py), where Taichi is installed (the bench
    extra; an optional peer like PyBullet): a uniform wind through its advection, Jacobi sweeps
    and gradient comes out unchanged. In its own process, as the bench runs it (ti.init)."""
    from benchmarks.taichi_air import taichi_available

    ok, why = taichi_available()
    if not ok:
        pytest.skip(why)
    code = (
        "import numpy as np\n"
        "from benchmarks.taichi_air import TaichiFluid\n"
        "w = np.array([2.0, -0.5, 0.25])\n"
        "f = TaichiFluid(8, 2.0, lambda p: np.tile(w, (len(p), 1)), 0.01)\n"
        "f.step(3)\n"
        "v = f.v.to_numpy()\n"
        "assert f.ok() and np.abs(v - w).max() < 1e-12, np.abs(v - w).max()\n"
    )
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]


def test_set_velocity_by_planes_gives_set_velocity_values():
    """The air workloads' field is set plane by plane (so the set-up does not count in the air's
    memory): the same face values as Fluid.set_velocity, on a grid whose sides all differ."""

    def fluid():
        return flagsim.Fluid(
            resolution=(6, 7, 8), cell_size=0.25, origin=(0.5, -1.0, 2.0), boundary="periodic"
        )

    whole, planes = fluid(), fluid()
    whole.set_velocity(engines.smooth_periodic_field)
    engines.set_velocity_by_planes(planes, engines.smooth_periodic_field)
    for name in "uvw":
        a, b = np.asarray(getattr(whole, name)), np.asarray(getattr(planes, name))
        assert np.abs(a).max() > 0.1
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)


def test_solver_iterations_are_read_on_the_same_steps_however_long_the_timing_ran():
    # The timed runs' step counts follow the machine's speed and the tunnel's flow settles as it
    # goes (7 iterations at first, 6 after, fewer after hundreds of steps): the figure is read on
    # the same steps whatever ran before, so the sizes compare the same flow.
    short, long = (engines.SolverStepper(16, "tunnel+solid", "multigrid") for _ in range(2))
    short.step(1)
    long.step(30)
    a, b = short.info(), long.info()
    assert len(short.iterations) == engines.ITERATION_WINDOW[1]  # topped up, untimed
    assert a["iterations"] == b["iterations"]
    assert "steps 3-12" in a["notes"]
    assert a["iterations"] == np.mean(long.iterations[2:12])
