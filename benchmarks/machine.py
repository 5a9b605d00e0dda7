"""The machine a benchmark ran on: CPU, cores, load, compiler and flags, library versions, git."""

from __future__ import annotations

import datetime
import math
import os
import platform
import time
from importlib import metadata
from typing import Any

#: Python packages whose versions a result depends on (absent ones are reported as such).
PACKAGES = ("numpy", "pybullet", "mujoco", "pypbd", "matplotlib")


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (Linux), else platform.processor()."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def physical_cores() -> int | None:
    """Distinct (physical id, core id) pairs in /proc/cpuinfo; None when unknown."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            text = f.read()
    except OSError:
        return None
    cores = set()
    for block in text.split("\n\n"):
        fields = dict(
            (k.strip(), v.strip())
            for k, _, v in (line.partition(":") for line in block.splitlines())
        )
        if "core id" in fields:
            cores.add((fields.get("physical id", "0"), fields["core id"]))
    return len(cores) or None


def load_average() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:  # pragma: no cover - not on Linux
        return "unknown"


def memory_total_gib() -> float | None:
    try:
        with open("/proc/meminfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return round(int(line.split()[1]) / 2**20, 1)
    except (OSError, ValueError, IndexError):
        pass
    return None


#: The speed probe: this many steps of the paper flag in uniform wind, best of PROBE_REPEATS.
PROBE_STEPS, PROBE_REPEATS = 200, 3
PROBE_WORK = (
    f"{PROBE_STEPS} steps of the paper flag alone in uniform wind, one thread, best of "
    f"{PROBE_REPEATS}"
)


def speed_probe() -> float:
    """ms for PROBE_STEPS steps of the paper flag alone in uniform wind (springs, drag, implicit
    integration: flagsim's own kind of work) on one thread, the best of PROBE_REPEATS fresh runs.
    The work is the same every time, so its spread over a benchmark run is how far the machine's
    speed moved: on a 2-core AMD EPYC VM at load 0 it alternated between 13.0 and 18.6-19.2 ms
    from one second to the next (about 1.5x), which neither the load average nor the CPU time
    saw. Leaves one thread set."""
    import flagsim

    flagsim.set_num_threads(1)
    scene = flagsim.Scene.paper()
    scene.air.model = "uniform"
    best = math.inf
    for _ in range(PROBE_REPEATS):
        sim = flagsim.Simulation(scene)
        t0 = time.perf_counter()
        sim.step(PROBE_STEPS)
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def git_revision() -> str:
    """Short revision of the flagsim in use (+ "-dirty"): flagsim._revision.revision()."""
    from flagsim._revision import revision

    return revision()


def package_versions() -> dict[str, str]:
    out = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def build_info() -> dict[str, Any]:
    """flagsim._core.build_info() when the module has it (compiler, flags, FFTW, OpenMP)."""
    from flagsim import _core

    fn = getattr(_core, "build_info", None)
    return dict(fn()) if fn is not None else {}


def describe() -> dict[str, Any]:
    """Flat {key: value} description of this machine and build, in display order."""
    import flagsim

    info = build_info()
    d: dict[str, Any] = {
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": cpu_model(),
        "logical_cpus": os.cpu_count(),
        "physical_cores": physical_cores(),
        "usable_cpus": len(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
        "memory_gib": memory_total_gib(),
        "load_average_start": load_average(),
        "os": f"{platform.system()} {platform.release()}",
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "flagsim": flagsim.__version__,
        "git_revision": git_revision(),
        "compiler": info.get("compiler", "unknown"),
        "build_type": info.get("build_type", "unknown"),
        "cxx_flags": " ".join(
            x for x in (info.get("cxx_flags", ""), info.get("openmp_flags", "")) if x
        )
        or "unknown",
        "eigen": f"{info.get('eigen', '?')} ({info.get('eigen_simd', '?')})",
        "openmp": (f"yes ({info.get('openmp_version')})" if info.get("openmp") else "no")
        if info
        else str(flagsim.has_openmp()),
        "fftw": (info.get("fftw_version") or "yes")
        if info.get("fftw", flagsim.has_fftw())
        else "no",
        "fftw_threads": "yes (OpenMP, grids >= 32^3)" if info.get("fftw_threads") else "no",
        "default_threads": flagsim.num_threads(),
    }
    for name, version in package_versions().items():
        d[name] = version
    return d
