"""Benchmark output: CSV with the machine described, a markdown report, a log-log PNG of cost
against size with fitted slopes, the peers side by side, and the issue's targets."""

from __future__ import annotations

import csv
import math
import re
from typing import Any, Iterable

import numpy as np

from .machine import PROBE_WORK

#: CSV columns, in order. Figures are per step; *_mb are MiB; stage_split is text; iterations
#: (pressure CG iterations per projection, mean over the last steps) and project_ms (the
#: projection stage per step) are filled for the solver group; probe_ms_before/after are the
#: speed probe (machine.speed_probe) just before and after the workload.
COLUMNS = (
    "group",
    "engine",
    "variant",
    "size",
    "n",
    "threads",
    "steps_per_run",
    "runs",
    "ms_min",
    "ms_median",
    "steps_per_s",
    "cpu_ms_median",
    "build_s",
    "peak_rss_mb",
    "workload_mb",
    "stage_split",
    "iterations",
    "project_ms",
    "probe_ms_before",
    "probe_ms_after",
    "ok",
    "note",
)
#: Columns that hold measured figures (positive and finite in every ok row, workload_mb >= 0).
FIGURES = ("ms_min", "ms_median", "steps_per_s", "cpu_ms_median", "build_s", "peak_rss_mb")
PEER_COLUMNS = (
    "workload",
    "size",
    "flagsim_variant",
    "flagsim_steps_per_s",
    "peer",
    "peer_notes",
    "peer_steps_per_s",
    "ratio",
)
PEER_NAMES = {
    "pybullet": "PyBullet",
    "pypbd": "pyPBD",
    "mujoco": "MuJoCo",
    "numpy": "numpy Stam FFT",
    "taichi": "Taichi Stable Fluids",
}


#: Peers that step the air (compared with flagsim.Fluid), not the cloth.
AIR_PEERS = ("numpy", "taichi")


# ---- rows ----------------------------------------------------------------------------------------


def make_row(w, result: dict[str, Any]) -> dict[str, Any]:
    """One CSV row from a workload and its worker result."""
    row: dict[str, Any] = {
        "group": w.group,
        "engine": w.engine,
        "variant": w.variant,
        "size": w.size,
        "n": w.n,
        "threads": w.threads,
    }
    info = result.get("info") or {}
    notes = [str(info["notes"])] if info.get("notes") else []
    if result.get("ok") and result.get("wall_s"):
        wall = np.asarray(result["wall_s"]) * 1e3
        cpu = np.asarray(result["cpu_s"]) * 1e3
        med = float(np.median(wall))
        row.update(
            {
                "steps_per_run": result["steps_per_run"],
                "runs": result["runs"],
                "ms_min": float(wall.min()),
                "ms_median": med,
                "steps_per_s": 1e3 / med,
                "cpu_ms_median": float(np.median(cpu)),
                "build_s": result["build_s"],
                "peak_rss_mb": result["rss_peak_mb"],
                "workload_mb": max(0.0, result["rss_peak_mb"] - result["rss_start_mb"]),
                "stage_split": stage_split(result.get("stages_s") or {}),
                "ok": True,
            }
        )
        if result.get("probe_ms"):
            row["probe_ms_before"], row["probe_ms_after"] = map(float, result["probe_ms"])
        if w.group == "solver":
            if info.get("iterations") is not None:
                row["iterations"] = float(info["iterations"])
            project = (result.get("stages_s") or {}).get("project")
            if project is not None:
                row["project_ms"] = 1e3 * float(project)
        last = info.get("last_step") or {}
        if last.get("substeps"):
            notes.append(f"{last['substeps']} substeps/step")
        if last.get("cg_iterations"):
            notes.append(f"{last['cg_iterations']} CG iterations/step")
        if w.group == "cloth" and "max_strain" in info:
            notes.append(f"max strain {info['max_strain']:.2g} after the runs")
        if info.get("stages") and w.group == "paper":
            notes.append("stages: " + " ".join(info["stages"]))
    else:
        row.update({k: "" for k in COLUMNS if k not in row})
        row["ok"] = False
        notes.append(result.get("error") or "failed")
    for k in ("iterations", "project_ms", "probe_ms_before", "probe_ms_after"):
        row.setdefault(k, "")
    row["note"] = "; ".join(notes)
    row["_stages_s"] = result.get("stages_s") or {}
    return row


#: A speed probe whose slowest reading exceeds its fastest by more than this factor over a run
#: says that the machine's speed moved enough to decide a wall-clock target near its threshold.
PROBE_SPREAD = 1.1


def probe_summary(rows) -> dict[str, Any] | None:
    """The speed probe over a run: its readings before and after every measured workload (min,
    median, max in ms, max / min, the number of workloads), or None when no row has one."""
    ms = [
        float(r[k])
        for r in rows
        if r["ok"] in (True, "True")
        for k in ("probe_ms_before", "probe_ms_after")
        if r.get(k) not in (None, "")
    ]
    if not ms:
        return None
    return {
        "workloads": len(ms) // 2,
        "min_ms": min(ms),
        "median_ms": float(np.median(ms)),
        "max_ms": max(ms),
        "spread": max(ms) / min(ms),
    }


def probe_sentence(summary: dict[str, Any] | None) -> str:
    """One line on the speed probe for the report and the console ("" without readings)."""
    if not summary:
        return ""
    s = (
        f"Speed probe (the same {PROBE_WORK}, timed just before and after each of "
        f"{summary['workloads']} workloads): {summary['min_ms']:.3g}-{summary['max_ms']:.3g} ms, "
        f"median {summary['median_ms']:.3g} ms, slowest / fastest {summary['spread']:.2f}."
    )
    if summary["spread"] > PROBE_SPREAD:
        s += (
            f" The machine's speed moved by more than {100 * (PROBE_SPREAD - 1):.0f} % during "
            "this run: a wall-clock figure within that margin of its target could read either "
            "way on a rerun, and the cpu column does not show it (a slower core is still busy)."
        )
    return s


def stage_split(stages_s: dict[str, float]) -> str:
    """'integrate 61%, springs 22%, ...' (shares of the timed stages, largest first)."""
    total = sum(v for v in stages_s.values() if v > 0)
    if total <= 0:
        return ""
    parts = sorted(((v / total, k) for k, v in stages_s.items() if v > 0), reverse=True)
    return ", ".join(f"{k} {100 * s:.0f}%" for s, k in parts if s >= 0.005)


def ok_rows(rows: Iterable[dict[str, Any]], **match) -> list[dict[str, Any]]:
    return [r for r in rows if r["ok"] and all(r[k] == v for k, v in match.items())]


def find(rows, **match) -> dict[str, Any] | None:
    hits = ok_rows(rows, **match)
    return hits[0] if hits else None


# ---- CSV -----------------------------------------------------------------------------------------


def write_csv(path: str, rows: list[dict[str, Any]], machine: dict[str, Any]) -> None:
    """CSV whose leading '# key: value' lines describe the machine (read it with comment='#')."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        for k, v in machine.items():
            f.write(f"# {k}: {v}\n")
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: _csv_value(r.get(k, "")) for k in COLUMNS})


def _csv_value(v):
    if isinstance(v, float):
        return f"{v:.6g}"
    return v


def read_csv(path: str) -> list[dict[str, str]]:
    with open(path, encoding="utf-8") as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


# ---- scaling -------------------------------------------------------------------------------------


def series(rows) -> dict[tuple, list[dict[str, Any]]]:
    """Rows of the size-swept groups keyed by (group, engine, variant, threads), sorted by n."""
    out: dict[tuple, list] = {}
    for r in rows:
        if r["ok"] and r["group"] in ("cloth", "air", "solver", "peers"):
            out.setdefault((r["group"], r["engine"], r["variant"], r["threads"]), []).append(r)
    return {k: sorted(v, key=lambda r: r["n"]) for k, v in out.items()}


def loglog_slope(n: list[float], cost: list[float]) -> float | None:
    """Slope of the least-squares line through (log n, log cost); None with fewer than 2 sizes."""
    pts = [(math.log(a), math.log(b)) for a, b in zip(n, cost) if a > 0 and b > 0]
    if len({p[0] for p in pts}) < 2:
        return None
    x, y = np.array(pts).T
    return float(np.polyfit(x, y, 1)[0])


def slopes(rows) -> list[dict[str, Any]]:
    out = []
    for (group, engine, variant, threads), rs in series(rows).items():
        s = loglog_slope([r["n"] for r in rs], [r["ms_median"] for r in rs])
        if s is not None:
            out.append(
                {
                    "group": group,
                    "engine": engine,
                    "variant": variant,
                    "threads": threads,
                    "sizes": f"{rs[0]['size']} .. {rs[-1]['size']}",
                    "slope": s,
                }
            )
    return out


def collision_stage_slope(rows) -> tuple[float | None, str]:
    """Slope of the self-collision stage's cost against vertices (1 thread, >= 1000 vertices if
    there are two such sizes), and how it was obtained."""
    for integrator in ("implicit", "explicit"):
        rs = sorted(
            ok_rows(rows, group="cloth", variant=f"{integrator}+self-collision", threads=1),
            key=lambda r: r["n"],
        )
        pts = []
        for r in rs:
            cost = sum(v for k, v in r["_stages_s"].items() if "collision" in k or "collide" in k)
            if cost > 0:
                pts.append((r["n"], cost))
        big = [p for p in pts if p[0] >= 1000]
        use = big if len(big) >= 2 else pts
        s = loglog_slope([p[0] for p in use], [p[1] for p in use])
        if s is not None:
            return (
                s,
                f"{integrator}, self-collision stage, {len(use)} sizes "
                f"from {use[0][0]} to {use[-1][0]} vertices",
            )
    return None, "no self-collision stage timings (self-collision not measured)"


def plot(path: str, rows, title: str = "") -> list[dict[str, Any]]:
    """Log-log PNG of ms per step against size per series (cloth: vertices; air: cells), the fitted
    slope in each legend entry. Returns the slopes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ser = series(rows)
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    panels = {"cloth": axes[0], "air": axes[1]}
    for (_group, engine, variant, threads), rs in sorted(ser.items(), key=lambda kv: str(kv[0])):
        panel = "air" if rs[0]["size"].endswith("^3") else "cloth"
        ax = panels[panel]
        n = [r["n"] for r in rs]
        ms = [r["ms_median"] for r in rs]
        s = loglog_slope(n, ms)
        if engine == "flagsim":
            label = f"flagsim {variant} t{threads}"
        elif engine == "fftw":
            label = "FFTW alone: 3 r2c + 3 c2r"
        else:
            label = PEER_NAMES.get(engine, engine)
        label += f" (slope {s:.2f})" if s is not None else ""
        style = "-" if engine == "flagsim" else "--"
        ax.plot(n, ms, style, marker="o", ms=4, label=label)
    for panel, ax in panels.items():
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.set_ylabel("ms per step (median)")
        ax.set_xlabel("vertices" if panel == "cloth" else "cells")
        ax.set_title("cloth alone" if panel == "cloth" else "air alone")
        if ax.lines:
            ax.legend(fontsize=7, loc="upper left")
        else:
            ax.text(0.5, 0.5, "not measured", ha="center", va="center", transform=ax.transAxes)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return slopes(rows)


# ---- peers side by side --------------------------------------------------------------------------


def comparisons(rows) -> list[dict[str, Any]]:
    """flagsim's steps/s over each peer's at the same size (cloth: implicit, 1 thread; air: the
    first advection/pressure variant, double, 1 thread, against the numpy baseline)."""
    out = []
    for r in ok_rows(rows, group="peers"):
        if r["engine"] in AIR_PEERS:
            mine = [
                m
                for m in ok_rows(rows, group="air", engine="flagsim", size=r["size"], threads=1)
                if m["variant"].count("/") == 1
            ]
            mine = sorted(mine, key=lambda m: (m["variant"] != "sl/fft", m["variant"]))[:1]
        else:
            mine = ok_rows(
                rows, group="cloth", engine="flagsim", variant="implicit", size=r["size"], threads=1
            )
        if not mine:
            continue
        m = mine[0]
        out.append(
            {
                "workload": "air" if r["engine"] in AIR_PEERS else "cloth",
                "size": r["size"],
                "flagsim_variant": m["variant"],
                "flagsim_steps_per_s": m["steps_per_s"],
                "peer": r["engine"],
                "peer_notes": r["note"],
                "peer_steps_per_s": r["steps_per_s"],
                "ratio": m["steps_per_s"] / r["steps_per_s"],
            }
        )
    return out


def write_peers_csv(path: str, comps: list[dict[str, Any]]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=PEER_COLUMNS, lineterminator="\n")
        w.writeheader()
        for c in comps:
            w.writerow({k: _csv_value(c[k]) for k in PEER_COLUMNS})


# ---- targets -------------------------------------------------------------------------------------


def _verdict(ok: bool | None) -> str:
    return "not measured" if ok is None else ("met" if ok else "missed")


def _probed(row) -> str:
    """The speed probe around a row's workload, for wall-clock targets ("" without one)."""
    b, a = _num(row.get("probe_ms_before")), _num(row.get("probe_ms_after"))
    return "" if b is None or a is None else f" (speed probe {b:.3g} / {a:.3g} ms before / after)"


def targets(rows, comps, accuracy: dict[str, Any] | None) -> list[tuple[str, str, str]]:
    """(target, measured figure, met | missed | not measured) for each of the issue's targets."""
    out = []
    full = find(rows, group="paper", variant="full", threads=1)
    builtin = find(rows, group="paper", variant="builtin", threads=1)
    if full:
        out.append(
            (
                "paper scene, full pipeline: >= 5,000 steps/s, 1 thread",
                f"{full['steps_per_s']:,.0f} steps/s" + _probed(full),
                _verdict(full["steps_per_s"] >= 5000),
            )
        )
    else:
        extra = (
            f" (built-in scene without the missing stages: {builtin['steps_per_s']:,.0f} steps/s)"
            if builtin
            else ""
        )
        out.append(
            (
                "paper scene, full pipeline: >= 5,000 steps/s, 1 thread",
                "not run" + extra,
                _verdict(None),
            )
        )

    out += pipeline_targets(rows)

    air = [c for c in comps if c["workload"] == "air" and c["peer"] == "numpy"]
    if air:
        worst = min(air, key=lambda c: c["ratio"])
        out.append(
            (
                "air step >= 10x the numpy Stam FFT baseline at every size (issue 28)",
                ", ".join(f"{c['size']}: {c['ratio']:.1f}x" for c in air),
                _verdict(worst["ratio"] >= 10),
            )
        )
    else:
        out.append(
            (
                "air step >= 10x the numpy Stam FFT baseline at every size (issue 28)",
                "not run (needs --peers and flagsim.Fluid)",
                _verdict(None),
            )
        )

    for n, limit in (("64^3", 3.0), ("128^3", 1.5)):  # issue 8; issue 28 item 5
        fl, ff = (
            find(rows, group="air", engine="flagsim", variant="sl/fft", size=n, threads=1),
            find(rows, group="air", engine="fftw", size=n),
        )
        name = f"air {n} (sl/fft): <= {limit:g}x the FFTW transforms alone"
        if fl and ff:
            r = fl["ms_median"] / ff["ms_median"]
            out.append(
                (
                    name,
                    f"{fl['ms_median']:.2f} ms vs {ff['ms_median']:.2f} ms = {r:.2f}x",
                    _verdict(r <= limit),
                )
            )
        else:
            out.append((name, "not run", _verdict(None)))

    # issue 28 item 4: the workload's peak memory (its own process) is the air's arrays
    name = "air 128^3 (sl/fft, double) memory: <= 250 MiB"
    m = find(rows, group="air", engine="flagsim", variant="sl/fft", size="128^3", threads=1)
    if m:
        f = find(
            rows, group="air", engine="flagsim", variant="sl/fft/float", size="128^3", threads=1
        )
        flt = f", float {f['workload_mb']:.0f} MiB" if f else ""
        out.append((name, f"{m['workload_mb']:.0f} MiB{flt}", _verdict(m["workload_mb"] <= 250)))
    else:
        out.append((name, "not run", _verdict(None)))

    for n in ("64^3", "128^3"):
        a, b = (
            find(rows, group="air", engine="flagsim", variant="sl/fft", size=n, threads=1),
            find(rows, group="air", engine="flagsim", variant="sl/fft", size=n, threads=2),
        )
        name = f"air {n}: 2 threads >= 1.6x one thread"
        if a and b:
            s = a["ms_median"] / b["ms_median"]
            out.append((name, f"{s:.2f}x", _verdict(s >= 1.6)))
        else:
            out.append((name, "not run", _verdict(None)))

    pbd = [c for c in comps if c["peer"] == "pypbd" and c["size"] == "128x128"]
    expl = find(rows, group="cloth", variant="explicit", size="128x128", threads=1)
    beside = f"; explicit (adaptive substeps): {expl['steps_per_s']:,.1f} steps/s" if expl else ""
    if pbd:
        c = pbd[0]
        out.append(
            (
                "cloth 128x128 implicit, dt = 0.01: >= 2x pyPBD's steps/s",
                f"{c['flagsim_steps_per_s']:,.1f} vs {c['peer_steps_per_s']:,.1f} steps/s "
                f"= {c['ratio']:.2f}x" + beside,
                _verdict(c["ratio"] >= 2),
            )
        )
    else:
        impl = find(rows, group="cloth", variant="implicit", size="128x128", threads=1)
        peer_failed = any(
            r["group"] == "peers"
            and r["engine"] == "pypbd"
            and r["size"] == "128x128"
            and not r["ok"]
            for r in rows
        )
        got = (
            f"flagsim {impl['steps_per_s']:,.1f} steps/s, "
            f"pyPBD {'failed' if peer_failed else 'not run'}"
            if impl
            else "not run"
        )
        out.append(
            (
                "cloth 128x128 implicit, dt = 0.01: >= 2x pyPBD's steps/s",
                got + beside,
                _verdict(None),
            )
        )

    s, how = collision_stage_slope(rows)
    out.append(
        (
            "self-collision cost per vertex flat, 1k-16k vertices: log-log slope <= 1.15",
            f"{s:.2f} ({how})" if s is not None else how,
            _verdict(None if s is None else s <= 1.15),
        )
    )

    out += solver_targets(rows)

    out.append(
        (
            "no heap allocation inside a step (paper scene; 64^3 air)",
            "C++ test NoAlloc.* (ctest -R NoAlloc), not a bench figure",
            "see tests",
        )
    )

    speedups = []
    for d in ok_rows(rows, group="air", engine="flagsim", variant="sl/fft", threads=1):
        f = find(
            rows, group="air", engine="flagsim", variant="sl/fft/float", size=d["size"], threads=1
        )
        if f:
            speedups.append(f"{d['size']}: {d['ms_median'] / f['ms_median']:.2f}x")
    acc = ""
    if accuracy and "float_vs_double" in accuracy:
        acc = (
            f"; Taylor-Green {accuracy['n']}^3 after {accuracy['steps']} steps: float vs double "
            f"{accuracy['float_vs_double']:.1e} (relative), error vs exact: double "
            f"{accuracy['error_double']:.2e}, float {accuracy['error_float']:.2e}"
        )
    elif accuracy and accuracy.get("error"):
        acc = f"; Taylor-Green check failed: {accuracy['error']}"
    out.append(
        (
            "float32 grid: speed-up and Taylor-Green error against double",
            ("speed-up " + ", ".join(speedups) if speedups else "not run") + acc,
            "reported" if speedups else _verdict(None),
        )
    )
    return out


PAPER_NOTE = (
    "builtin: Scene.paper() as it is; full: with self-collision and eq. 5 on; large: "
    "Scene.large(), the paper scene meshed finer (64 x 64 flag, 64^3 air, same box and fan). On "
    "two threads the air's step runs beside the cloth's, each on one thread (air.pipeline, the "
    "default; same bits as one after the other: docs/design.md 'Air and cloth side by side'); the "
    "/serial rows are the same scenes with air.pipeline = false, one after the other with both "
    "threads in each stage's loops. The stage split then counts the air's seconds beside the "
    "cloth's, so its shares are of the two threads' busy time. full/two_way_lagged: the full "
    "scene with air.coupling = 'two_way_lagged' (the air takes the flag's drag reaction a step "
    "late, beside the cloth); full/two_way: the serial two-way scheme (never pipelined), the "
    "same physics one step less behind (docs/coupling.md)."
)


def pipeline_targets(rows) -> list[tuple[str, str, str]]:
    """Issue 28 items 1 and 2: the full paper scene >= 10,000 steps/s on 2 threads, and the large
    scene (64 x 64 flag, 64^3 air) >= 100 steps/s on 2 threads, both with the air beside the
    cloth; each with its ratio to the serial order (air.pipeline = false) from the same run."""
    out = []
    for variant, what, goal in (
        ("full", "paper scene, full pipeline: >= 10,000 steps/s, 2 threads", 10_000),
        (
            "large",
            "Scene.large (64x64 flag, 64^3 air, self-collision, eq. 5, dt = 0.01): "
            ">= 100 steps/s (real time), 2 threads",
            100,
        ),
    ):
        row = find(rows, group="paper", variant=variant, threads=2)
        if not row:
            out.append((what, "not run", _verdict(None)))
            continue
        got = f"{row['steps_per_s']:,.0f} steps/s"
        serial = find(rows, group="paper", variant=variant + "/serial", threads=2)
        if serial:
            got += (
                f" (serial order {serial['steps_per_s']:,.0f}: "
                f"{serial['ms_median'] / row['ms_median']:.2f}x)"
            )
        out.append((what, got + _probed(row), _verdict(row["steps_per_s"] >= goal)))
    return out


# ---- pressure solvers ----------------------------------------------------------------------------


def _num(x) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def solver_ratios(rows) -> list[dict[str, Any]]:
    """Per size and thread count: the projection (ms per step) of multigrid on the tunnel with a
    solid, of fft on the periodic box, of pcg on the same tunnel, and the ratios."""
    out = []
    for mg in ok_rows(rows, group="solver", variant="tunnel+solid/multigrid"):
        key = dict(group="solver", size=mg["size"], threads=mg["threads"])
        fft = find(rows, variant="periodic/fft", **key)
        pcg = find(rows, variant="tunnel+solid/pcg", **key)
        pmg = find(rows, variant="periodic/multigrid", **key)
        m = _num(mg["project_ms"])
        f = _num(fft["project_ms"]) if fft else None
        p = _num(pcg["project_ms"]) if pcg else None
        q = _num(pmg["project_ms"]) if pmg else None
        out.append(
            {
                "size": mg["size"],
                "n": mg["n"],
                "threads": mg["threads"],
                "multigrid_ms": m,
                "multigrid_iterations": _num(mg["iterations"]),
                "fft_ms": f,
                "pcg_ms": p,
                "pcg_iterations": _num(pcg["iterations"]) if pcg else None,
                "periodic_multigrid_ms": q,
                "mg_over_fft": m / f if m and f else None,
                "pcg_over_mg": p / m if m and p else None,
                "periodic_mg_over_fft": q / f if q and f else None,
            }
        )
    return sorted(out, key=lambda r: (r["n"], r["threads"]))


def solver_targets(rows) -> list[tuple[str, str, str]]:
    """Issue 23's solver targets: iterations about flat (<= 15) from 32^3 to 128^3, and a 64^3 and
    a 128^3 tunnel with a solid projecting in <= 3x the fft projection (same threads, double)."""
    out = []
    mg = sorted(
        ok_rows(rows, group="solver", variant="tunnel+solid/multigrid", threads=1),
        key=lambda r: r["n"],
    )
    its = [(r["size"], _num(r["iterations"])) for r in mg if _num(r["iterations"]) is not None]
    name = "issue 23: multigrid iterations to 1e-8 about flat 32^3-128^3, <= 15 (tunnel + solid)"
    if its:
        big = [v for size, v in its if int(size.split("^")[0]) >= 32]
        ok = bool(big) and max(big) <= 15 and max(big) <= 1.5 * min(big)
        out.append(
            (name, ", ".join(f"{s}: {v:.1f}" for s, v in its), _verdict(ok if big else None))
        )
    else:
        out.append((name, "not run", _verdict(None)))
    ratios = solver_ratios(rows)
    for size in ("64^3", "128^3"):
        name = f"issue 23: {size} tunnel + solid, multigrid projection <= 3x the fft projection"
        got = [r for r in ratios if r["size"] == size and r["mg_over_fft"] is not None]
        if got:
            text = ", ".join(
                f"t{r['threads']}: {r['multigrid_ms']:.3g} vs {r['fft_ms']:.3g} ms = "
                f"{r['mg_over_fft']:.1f}x"
                for r in got
            )
            out.append((name, text, _verdict(all(r["mg_over_fft"] <= 3 for r in got))))
        else:
            out.append((name, "not run", _verdict(None)))
    return out


def _solver_table(rows) -> list[str]:
    body = []
    for r in sorted(
        (r for r in rows if r["group"] == "solver"),
        key=lambda r: (r["variant"], r["n"], r["threads"]),
    ):
        if not r["ok"]:
            body.append([r["variant"], r["size"], r["threads"], "failed", "", "", "", r["note"]])
            continue
        its = _num(r["iterations"])
        pm = _num(r["project_ms"])
        body.append(
            [
                r["variant"],
                r["size"],
                r["threads"],
                f"{its:.1f}" if its is not None else "",
                _fmt_ms(pm) if pm is not None else "",
                _fmt_ms(r["ms_median"]),
                f"{r['workload_mb']:.1f}",
                r["note"],
            ]
        )
    table = _table(
        ["variant", "size", "threads", "iterations", "project ms", "step ms", "+MiB", "note"], body
    )
    ratios = solver_ratios(rows)
    if ratios:

        def fx(v):
            return f"{v:.2f}x" if v is not None else ""

        table += [""] + _table(
            [
                "size",
                "threads",
                "multigrid (tunnel + solid) / fft (periodic)",
                "pcg / multigrid (tunnel + solid)",
                "multigrid / fft (both periodic)",
            ],
            [
                [
                    r["size"],
                    r["threads"],
                    fx(r["mg_over_fft"]),
                    fx(r["pcg_over_mg"]),
                    fx(r["periodic_mg_over_fft"]),
                ]
                for r in ratios
            ],
        )
    return table


# ---- markdown ------------------------------------------------------------------------------------


def _fmt_rate(x) -> str:
    if x == "" or x is None:
        return ""
    return f"{x:,.0f}" if x >= 100 else (f"{x:,.1f}" if x >= 1 else f"{x:.3g}")


def _fmt_ms(x) -> str:
    if x == "" or x is None:
        return ""
    return f"{x:.3g}" if x < 100 else f"{x:,.0f}"


def _table(header: list[str], body: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in body]
    return lines


def _rows_table(rows) -> list[str]:
    body = []
    for r in rows:
        if r["ok"]:
            body.append(
                [
                    r["engine"],
                    r["variant"],
                    r["size"],
                    r["threads"],
                    _fmt_rate(r["steps_per_s"]),
                    _fmt_ms(r["ms_median"]),
                    _fmt_ms(r["ms_min"]),
                    _fmt_ms(r["cpu_ms_median"]),
                    f"{r['workload_mb']:.1f}",
                    r["stage_split"],
                    r["note"],
                ]
            )
        else:
            body.append(
                [
                    r["engine"],
                    r["variant"],
                    r["size"],
                    r["threads"],
                    "failed",
                    "",
                    "",
                    "",
                    "",
                    "",
                    r["note"],
                ]
            )
    return _table(
        [
            "engine",
            "variant",
            "size",
            "threads",
            "steps/s",
            "median ms",
            "min ms",
            "cpu ms",
            "+MiB",
            "stage split",
            "note",
        ],
        body,
    )


def side_by_side(rows, comps) -> list[str]:
    """The issue's table: rows = workloads, columns = flagsim and each peer (steps/s, ratio)."""
    peers = [
        p
        for p in ("pybullet", "pypbd", "mujoco", "numpy", "taichi")
        if any(c["peer"] == p for c in comps)
    ]
    if not peers:
        return []
    header = ["workload", "flagsim (cloth: implicit)", "flagsim explicit"] + [
        PEER_NAMES[p] for p in peers
    ]
    sizes = {
        (c["workload"], c["size"]): next(r["n"] for r in rows if r["size"] == c["size"])
        for c in comps
    }
    keys = sorted(sizes, key=lambda k: (k[0] != "cloth", sizes[k]))
    body = []
    for workload, size in keys:
        line = [f"{workload} {size}, steps/s"]
        if workload == "cloth":
            for integ in ("implicit", "explicit"):
                m = find(rows, group="cloth", engine="flagsim", variant=integ, size=size, threads=1)
                line.append(_fmt_rate(m["steps_per_s"]) if m else "")
        else:
            m = [c for c in comps if c["workload"] == "air" and c["size"] == size][0]
            line += [f"{_fmt_rate(m['flagsim_steps_per_s'])} ({m['flagsim_variant']})", ""]
        for p in peers:
            c = [
                c
                for c in comps
                if c["peer"] == p and c["size"] == size and c["workload"] == workload
            ]
            failed = [
                r
                for r in rows
                if r["group"] == "peers" and r["engine"] == p and r["size"] == size and not r["ok"]
            ]
            if c:
                sub = re.search(r"(\d+) substeps \(smallest stable\)", c[0]["peer_notes"])
                extra = f", {sub.group(1)} substeps" if sub else ""
                line.append(
                    f"{_fmt_rate(c[0]['peer_steps_per_s'])} (flagsim {c[0]['ratio']:.2g}x{extra})"
                )
            else:
                line.append("failed" if failed else "")
        body.append(line)
    notes = []
    for p in peers:
        if p in AIR_PEERS:
            continue
        first = next((c["peer_notes"] for c in comps if c["peer"] == p and c["peer_notes"]), "")
        if first:
            searched = "(smallest stable)" in first
            notes.append(
                f"- {PEER_NAMES[p]}: "
                + re.sub(r"(, )?\d+ substeps \(smallest stable\)|; max strain.*$", "", first).strip(
                    ", "
                )
                + (", smallest stable substep count per size" if searched else "")
            )
    for r in rows:
        if r["group"] == "peers" and not r["ok"]:
            notes.append(
                f"- {PEER_NAMES.get(r['engine'], r['engine'])} {r['size']} failed: {r['note']}"
            )
    notes.append(
        "- max strain after the runs (largest |l - L| / L of the grid edges) is in the Peers and "
        "Cloth tables: the engines do not stretch alike under the same nominal stiffness."
    )
    return _table(header, body) + [""] + notes


def markdown(
    rows,
    machine: dict[str, Any],
    skipped,
    comps,
    slope_list,
    target_list,
    *,
    command: str,
    plot_name: str | None,
    protocol: dict[str, Any],
    load_end: str,
    probe: dict[str, Any] | None = None,
    docs: bool = False,
) -> str:
    L: list[str] = []
    L.append("# flagsim performance" if docs else "# flagsim benchmark results")
    L.append("")
    if docs:
        L.append(
            "Generated by `python -m benchmarks` (benchmarks/ in the repository); regenerate it on "
            "a quiet machine with `make bench` (which runs "
            "`python -m benchmarks --peers --docs docs/reports/performance.md`"
            " after installing the peers with `pip install .[bench]`). Do not edit by hand."
        )
        L.append("")
    L.append(f"Command: `{command}`  ")
    L.append(
        f"Protocol: build outside the timing, drop the first {protocol['warmup']} steps, steps "
        f"per run grown until a run lasts >= {protocol['min_time']:g} s, {protocol['repeats']} "
        "runs; figures are wall-clock ms per step (median and min of the runs), cpu ms is the "
        "process CPU time per step "
        "(all threads; cpu < wall on one thread means the process was waiting for a core), +MiB is "
        "the peak resident memory the workload added (ru_maxrss of its own process). Stage split: "
        "the Simulation's stage timers over the measured runs."
    )
    L.append("")
    L.append("## Machine")
    L.append("")
    L += _table(["", ""], [[k, v] for k, v in machine.items()] + [["load_average_end", load_end]])
    L.append("")
    L.append(
        "A load average near or above the core count means the figures are noisy (other processes "
        "shared the cores); compare the cpu and wall columns."
    )
    if probe:  # probe_summary(rows), once per run
        L += ["", probe_sentence(probe)]
    L.append("")
    paper = [r for r in rows if r["group"] == "paper"]
    if paper:
        L += ["## Paper scene", "", PAPER_NOTE, ""] + _rows_table(paper) + [""]
    sbs = side_by_side(rows, comps)
    if sbs:
        L += (
            [
                "## Side by side with the peers",
                "",
                "flagsim's steps/s as a multiple of each peer's at the same size (cloth: implicit, "
                "1 thread; air: flagsim.Fluid against the numpy baseline, the textbook Stam FFT "
                "solver (collocated, vectorised gather, benchmarks/stam_numpy.py), 1 thread). "
                "Same flag in each engine: size, mass, pole pins, dt = 0.01 s, gravity, comparable "
                "stiffness, wind where the "
                "peer has it.",
                "",
            ]
            + sbs
            + [""]
        )
    cloth = [r for r in rows if r["group"] == "cloth"]
    if cloth:
        L += (
            [
                "## Cloth alone",
                "",
                "The paper scene's flag (0.81 x 0.54 m, pole pins, 2 m/s analytic wind, "
                "dt = 0.01 s) meshed finer.",
                "",
            ]
            + _rows_table(cloth)
            + [""]
        )
    air = [r for r in rows if r["group"] == "air"]
    if air:
        L += (
            [
                "## Air alone",
                "",
                "flagsim.Fluid on a periodic 2 m box from a seeded smooth random field, "
                "dt = 0.01 s, air viscosity. The fftw rows are the floor of a spectral "
                "diffusion and projection: 3 forward r2c + "
                "3 inverse c2r double transforms, one thread, FFTW_ESTIMATE plans (air's "
                "nu dt / h^2 is below 0.01 here, so flagsim diffuses explicitly and projects "
                "with 1 r2c + 1 c2r in place: docs/design.md 'Explicit viscosity'). Memory: a "
                "periodic semi-Lagrangian fft grid holds 9.6 grid-sized arrays at 128^3 (u 3, "
                "the ghost-padded u^n 3.4, the FFT half spectra 3.05; "
                "docs/design.md 'Memory'); MacCormack adds 6.4, pcg 6.9.",
                "",
            ]
            + _rows_table(air)
            + [""]
        )
    solver = [r for r in rows if r["group"] == "solver"]
    if solver:
        L += (
            [
                "## Pressure solvers",
                "",
                "flagsim.Fluid's projection alone (viscosity 0): the 2 m box at n^3 from the "
                "seeded smooth field, double, to a 1e-8 relative residual. tunnel+solid: inflow "
                "2 m/s and a solid plate (a free-slip box obstacle over the middle half of the "
                "cross-section, n/8 cells thick, a quarter of the way down); periodic: no solid. "
                "Iterations: "
                "CG iterations per projection (warm-started from the last potential), mean over "
                "the last steps; project ms: the projection stage per step (divergence, solve, "
                "gradient); +MiB: the peak memory the workload added.",
                "",
            ]
            + _solver_table(rows)
            + [""]
        )
    peer_rows = [r for r in rows if r["group"] == "peers"]
    if peer_rows:
        L += ["## Peers", ""] + _rows_table(peer_rows) + [""]
    if slope_list or plot_name:
        L += [
            "## Scaling",
            "",
            "Cost per step against size, log-log; slope of the least-squares line through "
            "log(ms per step) against log(size) (1 = linear in vertices or cells).",
        ]
        if plot_name:
            L += ["", f"![cost against size]({plot_name})"]
        if slope_list:
            L += [""] + _table(
                ["group", "engine", "variant", "threads", "sizes", "slope"],
                [
                    [
                        s["group"],
                        s["engine"],
                        s["variant"],
                        s["threads"],
                        s["sizes"],
                        f"{s['slope']:.2f}",
                    ]
                    for s in slope_list
                ],
            )
        L += [""]
    if target_list:
        L += [
            "## Targets (issues 8 and 23)",
            "",
            "Not asserted anywhere; measured on the machine above.",
            "",
        ]
        L += _table(["target", "measured", "verdict"], [list(t) for t in target_list]) + [""]
    if skipped:
        L += ["## Skipped", ""] + [f"- {what}: {why}" for what, why in skipped] + [""]
    return "\n".join(L)
