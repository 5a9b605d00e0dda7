"""`flagsim study flutter` (issue 24 item 5): how each model of the air makes the paper's flag
flap, against published flag measurements and the free-flag force coefficient of the wind codes.

For each wind speed U (0 m/s for the droop alone, then 2..20 m/s), each model and each drag
model ("paper": eq. 3 per mass; "triangle": flat-plate pressure on the normal part plus skin
friction, docs/design.md), one run of the paper's flag (8 x 11 masses, 0.81 m x 0.54 m,
0.15 kg/m^2) on its pole, dt = 0.01 s, one thread, recorded every step after a transient:

  eq5         one-way, uniform analytic wind, eq. 5 "displace" (the paper's method)
  turbulence  one-way, uniform wind + curl noise (docs/turbulence.md), eq. 5 off: intensity
              TURBULENCE_INTENSITY x U, length scale TURBULENCE_LENGTH, evolution U / length
              scale (a new noise slice each time the mean wind has carried the air one eddy on)
  two_way     the air grid of Scene.emergent() around the flag with the pole as a solid (its
              wake), two-way coupling, the same turbulence injected, eq. 5 off; at
              TWO_WAY_SPEEDS for TWO_WAY_TIMES (its grid costs ~30x a one-way step). Only when
              this build has air.coupling; otherwise the study says so and runs the others.
              --quick leaves it out.

Measured (docs/flutter.md says why each is defined this way):
  frequency   Hz, the peak of the Welch spectrum (numpy; Hann windows of SEGMENT seconds,
              half overlap, each segment's mean removed) of the free edge's out-of-plane motion
              z (mean of the two middle rows of the last column), refined by a parabola
              through the log power of the peak bin and its neighbours
  amplitude   m, A = 2 sqrt(2) x RMS of that z: the peak-to-peak excursion for a sine;
              reported as A / L (L = the flag's length along the wind)
  strouhal    f A / U
  wavelength  m, and wave_speed m/s: from the phase of the out-of-plane motion along the
              centreline at the peak frequency (each column's windowed Fourier coefficient),
              unwrapped and fitted against the column's rest position, weighted by amplitude;
              wave_speed = 2 pi f / k is positive for waves running from the pole to the fly
  c_f         mean force of the flag on its pole along the wind / (1/2 rho U^2 A): one-way, from
              the whole step's momentum balance (the air's force + weight - dP/dt over the
              window); two-way, sim.pole_impulse (the balance of the drag the implicit solve
              applied, linearised: force_core, recorded for every run, shows the difference)
  droop       degrees below horizontal of the line from the pole edge to the free edge
              (mean of each column), time-averaged
  cost        wall seconds of sim.step per simulated second
"""

from __future__ import annotations

import math
import os
import time
import warnings
from typing import Any

import numpy as np

import flagsim

from .report import write_text

MODELS = ("eq5", "turbulence", "two_way")
MODEL_TITLES = {
    "eq5": "one-way + eq. 5",
    "turbulence": "one-way + turbulence",
    "two_way": "two-way + turbulence + pole wake",
}
DRAGS = ("paper", "triangle")
SPEEDS = (0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0, 20.0)
QUICK_SPEEDS = (0.0, 3.0, 10.0)
#: the two-way model pays for its air grid (0.013 s a step on one thread, ~30x the one-way
#: models): fewer, shorter runs (the full study: ~5 min on 2 loaded cores)
TWO_WAY_SPEEDS = (2.0, 5.0, 10.0, 15.0, 20.0)
TURBULENCE_INTENSITY = 0.1  # of U: a moderate atmospheric intensity near the ground
TURBULENCE_LENGTH = 0.3  # m, about half the flag's height
SEGMENT = 4.0  # s, Welch segment: 0.25 Hz bins, refined by the parabola
#: (transient s, recorded s) per run
FULL_TIMES = (5.0, 20.0)
TWO_WAY_TIMES = (2.0, 8.0)
QUICK_TIMES = (1.0, 4.0)

COLUMNS = [
    "id",
    "model",
    "drag",
    "speed",
    "transient",
    "duration",
    "frequency",
    "amplitude",
    "amplitude_ratio",
    "strouhal",
    "wavelength",
    "wave_speed",
    "force",
    "force_core",
    "force_coefficient",
    "droop",
    "cost",
    "state",
    "attempts",
    "worker",
    "seconds",
]


# --- the published reference ---------------------------------------------------------------


def free_flag_force_coefficient(
    areal_density: float, air_density: float, height: float, area: float
) -> float:
    """EN 1991-1-4 section 7.12 (Table 7.15, free flag) and AS/NZS 1170.2:
    c_f = 0.02 + 0.7 (m_f / (rho h)) (A / h^2)^-1.25, m_f kg/m^2, rho kg/m^3, h m (the flag's
    height along the pole), A m^2. AS 1170.2:2002 Appendix F writes the constant as 0.05."""
    for name, v in (
        ("areal_density", areal_density),
        ("air_density", air_density),
        ("height", height),
        ("area", area),
    ):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} should be a finite number > 0, got {v!r}")
    return 0.02 + 0.7 * (areal_density / (air_density * height)) * (area / height**2) ** -1.25


# --- estimators ------------------------------------------------------------------------------


def _check_signal(name: str, x, dt: float, ndim: int) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != ndim:
        raise ValueError(f"{name} should be a {ndim}-D array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} should be finite")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt should be > 0, got {dt!r}")
    return a


def _segments(length: int, n: int):
    """Start indices of Welch's half-overlapping segments of n samples in `length`."""
    return range(0, length - n + 1, max(1, n // 2))


def welch_spectrum(signal, dt: float, segment: float = SEGMENT) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies Hz, power) of `signal` (samples dt s apart): Welch's average of the squared
    FFTs of Hann-windowed segments of `segment` s (the whole signal if shorter) with half
    overlap, each segment's mean removed. Power is in arbitrary units (only ratios are used)."""
    z = _check_signal("signal", signal, dt, 1)
    if len(z) < 8:
        raise ValueError(f"signal should have >= 8 samples, got {len(z)}")
    n = min(len(z), max(8, int(round(segment / dt))))
    w = np.hanning(n)
    power = np.zeros(n // 2 + 1)
    for s in _segments(len(z), n):
        seg = z[s : s + n] - z[s : s + n].mean()
        power += np.abs(np.fft.rfft(seg * w)) ** 2
    return np.fft.rfftfreq(n, dt), power


def peak_frequency(signal, dt: float, segment: float = SEGMENT) -> float:
    """Hz: the peak of the Welch power spectrum (welch_spectrum) of `signal`, DC excluded,
    refined by a parabola through the log power of the peak bin and its neighbours'. NaN for a
    signal constant to round-off."""
    z = _check_signal("signal", signal, dt, 1)
    scale = float(np.abs(z).max()) if len(z) else 0.0
    if len(z) >= 8 and (scale == 0 or np.ptp(z) <= 1e-12 * scale):
        return float("nan")  # constant: no spectrum
    freqs, power = welch_spectrum(z, dt, segment)
    k = 1 + int(np.argmax(power[1:]))
    shift = 0.0
    if 1 < k < len(power) - 1 and np.all(power[k - 1 : k + 2] > 0):
        a, b, c = np.log(power[k - 1 : k + 2])
        den = a - 2 * b + c
        shift = 0.5 * (a - c) / den if den < 0 else 0.0
    return float(freqs[1] * (k + shift))


def has_flapping_peak(signal, dt: float, segment: float = SEGMENT) -> bool:
    """Does the spectrum peak away from its lowest frequencies? The peak bin must be above the
    first non-DC bin and hold at least twice that bin's power: slow wandering (a red spectrum,
    highest at the lowest frequency) is not flapping."""
    freqs, power = welch_spectrum(signal, dt, segment)
    if len(power) < 4 or not np.any(power[1:] > 0):
        return False
    k = 1 + int(np.argmax(power[1:]))
    return k >= 2 and power[k] >= 2.0 * power[1]


def peak_to_peak(signal) -> float:
    """2 sqrt(2) x the RMS about the mean: a sine's peak-to-peak excursion, and a robust one for
    motion that is not a sine (it does not follow a single extreme sample)."""
    z = np.asarray(signal, dtype=float)
    return float(2.0 * math.sqrt(2.0) * z.std())


def travelling_wave(
    z, x, dt: float, frequency: float, segment: float = SEGMENT
) -> tuple[float, float]:
    """(wavelength m, speed m/s) of the wave in z (T samples x C points along the flag at rest
    positions x, m) at `frequency` Hz. Each point's Fourier coefficient at exactly that frequency
    in each Hann-windowed Welch segment (as peak_frequency's), multiplied by the conjugate of the
    most moving point's and summed over the segments (the cross-spectrum: what is coherent adds
    up); its phase, unwrapped along x, fitted (weighted by magnitude, over the points whose
    cross-spectrum is at least a quarter of the largest) by phase = phi0 - k x. speed =
    2 pi f / k is positive for a wave running towards +x; wavelength = 2 pi / |k|. NaN when
    fewer than 3 points move or the phase does not change along x."""
    a = _check_signal("z", z, dt, 2)
    xs = _check_signal("x", x, dt, 1)
    if a.shape[1] != len(xs):
        raise ValueError(
            f"x should have one position per column of z ({a.shape[1]}), got {len(xs)}"
        )
    nan = (float("nan"), float("nan"))
    if not (math.isfinite(frequency) and frequency > 0) or len(a) < 8:
        return nan
    n = min(len(a), max(8, int(round(segment / dt))))
    kernel = np.hanning(n) * np.exp(-2j * np.pi * frequency * np.arange(n) * dt)
    coefs = np.array(
        [kernel @ (a[s : s + n] - a[s : s + n].mean(axis=0)) for s in _segments(len(a), n)]
    )  # (segments, C)
    ref = int(np.argmax((np.abs(coefs) ** 2).sum(axis=0)))
    cross = (coefs * np.conj(coefs[:, ref : ref + 1])).sum(axis=0)
    mag = np.abs(cross)
    if mag.max() <= 0:
        return nan
    keep = mag >= 0.25 * mag.max()
    if keep.sum() < 3:
        return nan
    order = np.argsort(xs[keep])
    phase = np.unwrap(np.angle(cross[keep][order]))
    slope = np.polyfit(xs[keep][order], phase, 1, w=mag[keep][order])[0]
    k = -slope
    if abs(k) < 1e-12:
        return nan
    return float(2 * np.pi / abs(k)), float(2 * np.pi * frequency / k)


def droop_degrees(positions, rows: int, cols: int) -> float:
    """Angle (degrees) below the horizontal of the line from the pole edge to the free edge,
    each the mean of its column (y up)."""
    x = np.asarray(positions, dtype=float).reshape(rows, cols, 3)
    d = x[:, -1].mean(axis=0) - x[:, 0].mean(axis=0)
    return float(np.degrees(np.arctan2(-d[1], np.hypot(d[0], d[2]))))


# --- scenes ----------------------------------------------------------------------------------


def has_two_way() -> bool:
    """Does this build couple the air to the flag both ways (air.coupling)?"""
    return hasattr(flagsim.Scene.paper().air, "coupling")


def scene_for(model: str, drag: str, speed: float) -> flagsim.Scene:
    """The paper's flag on its pole in a wind of `speed` m/s along +x, as `model` sees it."""
    if model not in MODELS:
        raise ValueError(f"model should be one of {', '.join(MODELS)}, got {model!r}")
    if drag not in DRAGS:
        raise ValueError(f"drag should be one of {', '.join(DRAGS)}, got {drag!r}")
    if not (math.isfinite(speed) and speed >= 0):
        raise ValueError(f"speed should be a finite number >= 0 (m/s), got {speed!r}")
    s = flagsim.Scene.paper()
    s.name = f"flutter-{model}-{drag}-{speed:g}"
    s.drag.model = drag
    s.air.fans = []
    s.air.wind = (speed, 0.0, 0.0)
    if model == "eq5":
        s.air.model = "uniform"  # the paper's eq. 5 waves on the analytic wind: U is exact
        return s
    s.flapping.mode = "off"
    if speed > 0:
        s.air.turbulence.intensity = TURBULENCE_INTENSITY * speed
        s.air.turbulence.length_scale = TURBULENCE_LENGTH
        s.air.turbulence.evolution = speed / TURBULENCE_LENGTH
    if model == "turbulence":
        s.air.model = "uniform"
        return s
    return _two_way_scene(s, speed)


def _two_way_scene(s: flagsim.Scene, speed: float) -> flagsim.Scene:
    if not has_two_way():
        raise ValueError(
            "model 'two_way' needs air.coupling (two-way coupling), which this build lacks"
        )
    # the air of the built-in emergent scene (a grid around the flag that resolves the pole,
    # the pole a solid of it, two-way): its grid, with this study's wind, drag and turbulence
    e = flagsim.Scene.emergent()
    for k in ("model", "boundary", "pressure", "advection", "cell_size", "origin", "resolution"):
        setattr(s.air, k, getattr(e.air, k))
    s.air.pole_obstacle = True
    s.air.coupling = "two_way"
    return s


# --- one run ---------------------------------------------------------------------------------


def aero_force(sim: flagsim.Simulation, scene: flagsim.Scene) -> np.ndarray:
    """(3,) N: the air's total force on the flag now, as the one-way drag stage computes it
    (eq. 3 per mass, or per triangle: csrc/cloth/forces.cpp add_drag; two-way scales it by
    1 / (1 + kappa), which this does not know). For the whole step's momentum balance of the pole
    force: sim.pole_impulse balances the drag the integrator applied, which the implicit solve
    linearises (docs/flutter.md)."""
    x, v = sim.positions, sim.velocities
    u = sim.air_velocity(x)
    c = 0.5 * scene.drag.coefficient * scene.air.density
    if scene.drag.model == "paper":
        f = np.linalg.norm(u, axis=1)[:, None] * u - np.linalg.norm(v, axis=1)[:, None] * v
        return c * (sim.node_area[:, None] * f).sum(axis=0)
    if scene.drag.model == "relative":
        r = u - v
        return c * (sim.node_area[:, None] * np.linalg.norm(r, axis=1)[:, None] * r).sum(axis=0)
    tri = sim.triangles
    cr = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    area = 0.5 * np.linalg.norm(cr, axis=1)
    n = cr / np.where(area > 0, 2 * area, 1.0)[:, None]
    w = (u[tri].sum(axis=1) - v[tri].sum(axis=1)) / 3.0
    wn = (w * n).sum(axis=1)
    wt = w - wn[:, None] * n
    ct = 0.5 * scene.drag.tangential_coefficient * scene.air.density
    f = c * (np.abs(wn) * wn)[:, None] * n + ct * np.linalg.norm(wt, axis=1)[:, None] * wt
    return (area[:, None] * f).sum(axis=0)


def simulate(scene: flagsim.Scene, transient: float, duration: float) -> dict[str, Any]:
    """Run `scene` for transient + duration s; record the positions every step of the last
    `duration` s and the mean force of the flag on its pins and pole over them: `force` from the
    whole step's momentum balance (air's force + weight - dP/dt) for one-way air, else the
    core's; `force_core` from sim.pole_impulse (the integrate stage's balance) always. Returns
    the series and the step cost."""
    with warnings.catch_warnings():
        # the emergent grid resolves the pole by a few cells, not the 8 its wake needs: known,
        # and said in docs/flutter.md
        warnings.filterwarnings("ignore", message=".*cells across.*", category=UserWarning)
        sim = flagsim.Simulation(scene)
    dt = scene.dt
    n0, n = int(round(transient / dt)), int(round(duration / dt))
    spent = 0.0
    t0 = time.perf_counter()
    sim.step(n0)
    spent += time.perf_counter() - t0
    xs = np.empty((n, len(sim.positions), 3))
    one_way = getattr(scene.air, "coupling", "one_way") == "one_way"
    aero = np.zeros((n, 3))
    mass = np.asarray(sim.node_mass)
    p0 = (mass[:, None] * sim.velocities).sum(axis=0)
    j0 = np.asarray(sim.pole_impulse)  # N s, the pins' impulse from the flag since the start
    for i in range(n):
        t0 = time.perf_counter()
        sim.step(1)
        spent += time.perf_counter() - t0
        xs[i] = sim.positions
        if one_way:
            aero[i] = aero_force(sim, scene)
    core = (np.asarray(sim.pole_impulse) - j0) / (n * dt)  # mean over the recorded window
    force = core
    if one_way:
        p1 = (mass[:, None] * sim.velocities).sum(axis=0)
        weight = mass.sum() * np.asarray(scene.gravity)
        force = aero.mean(axis=0) + weight - (p1 - p0) / (n * dt)
    return dict(positions=xs, force=force, force_core=core, dt=dt, cost=spent / ((n0 + n) * dt))


def measure(scene: flagsim.Scene, rec: dict[str, Any], speed: float) -> dict[str, Any]:
    """The study's figures from one recorded run (see the module docstring)."""
    rows, cols = scene.flag.rows, scene.flag.cols
    x = rec["positions"].reshape(len(rec["positions"]), rows, cols, 3)
    mid = [rows // 2 - 1, rows // 2] if rows % 2 == 0 else [rows // 2]
    centre_z = x[..., 2][:, mid, :].mean(axis=1)  # (T, cols): out of the rest plane
    tip = centre_z[:, -1]
    dt = rec["dt"]
    length = scene.flag.width  # along the wind
    area = scene.flag.width * scene.flag.height
    droop = float(np.mean([droop_degrees(p, rows, cols) for p in rec["positions"]]))
    out: dict[str, Any] = dict(
        droop=droop,
        force=float(rec["force"][0]),
        force_core=float(rec["force_core"][0]),
        cost=rec["cost"],
    )
    if speed <= 0:
        return {**out, "state": "still air: droop only"}
    f = peak_frequency(tip, dt)
    amp = peak_to_peak(tip)
    xs = scene.flag.origin[0] + np.linspace(0.0, length, cols)
    lam, c = travelling_wave(centre_z[:, 1:], xs[1:], dt, f)  # column 0 is pinned
    q = 0.5 * scene.air.density * speed**2 * area
    state = (
        "ok"
        if has_flapping_peak(tip, dt)
        else "no flapping peak: the tip's spectrum is highest at its lowest frequencies"
    )
    return {
        **out,
        "frequency": f,
        "amplitude": amp,
        "amplitude_ratio": amp / length,
        "strouhal": f * amp / speed,
        "wavelength": lam,
        "wave_speed": c,
        "force_coefficient": float(rec["force"][0]) / q,
        "state": state,
    }


def cases(quick: bool = False) -> list[dict[str, Any]]:
    out = []
    for m in MODELS:
        if m == "two_way" and (quick or not has_two_way()):
            continue  # quick (seconds): the one-way models only; the grid costs ~30x a step
        speeds = QUICK_SPEEDS if quick else TWO_WAY_SPEEDS if m == "two_way" else SPEEDS
        times = QUICK_TIMES if quick else TWO_WAY_TIMES if m == "two_way" else FULL_TIMES
        for d in DRAGS:
            for u in speeds:
                out.append(
                    dict(
                        id=f"{m}-{d}-{u:g}",
                        model=m,
                        drag=d,
                        speed=u,
                        transient=times[0],
                        duration=times[1],
                    )
                )
    return out


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    """One (model, drag, speed) run on one thread."""
    scene = scene_for(case["model"], case["drag"], float(case["speed"]))
    threads = flagsim.num_threads()
    flagsim.set_num_threads(1)
    try:
        rec = simulate(scene, float(case["transient"]), float(case["duration"]))
    except flagsim.DivergenceError as e:
        return dict(state=f"diverged: {e.cause}")
    finally:
        flagsim.set_num_threads(threads)
    return measure(scene, rec, float(case["speed"]))


# --- references, plots and report ------------------------------------------------------------

#: Raynaud & Mulleners (arXiv 2602.06237): bending waves of flapping flags (48 flags, several
#: aspect and mass ratios) have a nearly constant wavelength lambda / L ~ 1.87 and travel from
#: root to tip at a speed close to the incoming flow's.
WAVELENGTH_REF = 1.87
WAVE_SPEED_REF = 1.0


def _num(r: dict[str, str], key: str) -> float:
    try:
        return float(r.get(key, ""))
    except ValueError:
        return float("nan")


def _series(rows, key):
    """{(model, drag): (speeds, values)} for the rows with a finite `key`."""
    out: dict[tuple[str, str], tuple[list[float], list[float]]] = {}
    for r in rows:
        v = _num(r, key)
        if math.isfinite(v):
            s = out.setdefault((r["model"], r["drag"]), ([], []))
            s[0].append(_num(r, "speed"))
            s[1].append(v)
    return out


def reference_force_coefficient(scene: flagsim.Scene | None = None) -> float:
    s = scene or flagsim.Scene.paper()
    return free_flag_force_coefficient(
        s.flag.areal_density, s.air.density, s.flag.height, s.flag.width * s.flag.height
    )


_PEAK_FIGURES = ("frequency", "strouhal", "wavelength_ratio", "speed_ratio")


def write_plots(rows, directory: str) -> str | None:
    """One PNG of six panels against wind speed: frequency, A / L, Strouhal number, wavelength /
    L, wave speed / U, c_f, and the droop angle; the references drawn where there are any."""
    if not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = _figure(rows)
    os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, "flutter.png")
    tmp = path + ".tmp.png"
    fig.savefig(tmp)
    plt.close(fig)
    os.replace(tmp, path)
    return path


def _figure(rows):
    """write_plots' figure. Each (model, drag) keeps one colour and line style in every panel,
    whichever series a panel lacks (the one legend names them all)."""
    import matplotlib.pyplot as plt

    s = flagsim.Scene.paper()
    length = s.flag.width
    derived = []
    for r in rows:
        r = dict(r)
        u = _num(r, "speed")
        r["wavelength_ratio"] = _num(r, "wavelength") / length
        r["speed_ratio"] = _num(r, "wave_speed") / u if u > 0 else float("nan")
        derived.append(r)
    panels = [
        ("frequency", "flapping frequency (Hz)"),
        ("amplitude_ratio", "amplitude A / L"),
        ("strouhal", "Strouhal number f A / U"),
        ("wavelength_ratio", "wavelength / L"),
        ("speed_ratio", "wave speed / U"),
        ("force_coefficient", "c_f = F / (1/2 rho U^2 A)"),
        ("droop", "droop (degrees below horizontal)"),
    ]
    fig, axes = plt.subplots(2, 4, figsize=(16, 7.5), dpi=90)
    styles = {"eq5": "o-", "turbulence": "s--", "two_way": "^-."}
    colours = {k: f"C{i}" for i, k in enumerate(sorted({(r["model"], r["drag"]) for r in rows}))}
    umax = max(_num(r, "speed") for r in rows)
    flapping = [r for r in derived if r["state"] == "ok"]
    for ax, (key, label) in zip(axes.flat, panels):
        # the figures of a spectral peak only where there is one (the study's "ok" runs)
        src = flapping if key in _PEAK_FIGURES else derived
        for (model, drag), (us, vs) in sorted(_series(src, key).items()):
            ax.plot(
                us,
                vs,
                styles.get(model, "o-"),
                color=colours[(model, drag)],
                ms=4,
                label=f"{MODEL_TITLES[model]}, {drag}",
            )
        if key == "frequency":
            us = np.linspace(2, umax, 20)
            ax.plot(us, us / (WAVELENGTH_REF * length), "k:", label="U / (1.87 L) (waves at U)")
        if key == "wavelength_ratio":
            ax.axhline(WAVELENGTH_REF, color="k", ls=":", label="1.87 (Raynaud & Mulleners)")
            ax.set_yscale("log")
        if key == "speed_ratio":
            ax.axhline(WAVE_SPEED_REF, color="k", ls=":", label="1 (Raynaud & Mulleners)")
        if key == "force_coefficient":
            cf = reference_force_coefficient(s)
            ax.axhline(cf, color="k", ls=":", label=f"EN 1991-1-4 free flag ({cf:.3f})")
            ax.set_yscale("log")
        ax.set_xlabel("wind speed U (m/s)")
        ax.set_title(
            label + (" (runs with a flapping peak)" if key in _PEAK_FIGURES else ""), fontsize=9
        )
        ax.grid(True, alpha=0.3)
    handles, labels = [], []
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    axes.flat[-1].axis("off")
    axes.flat[-1].legend(handles, labels, fontsize=8, loc="center")
    fig.suptitle("flagsim study flutter: the paper's flag (0.81 m x 0.54 m, 0.15 kg/m^2)")
    fig.tight_layout()
    return fig


def _fmt(r, key, spec=".3g") -> str:
    v = _num(r, key)
    return format(v, spec) if math.isfinite(v) else ""


def _median(values) -> float:
    """Median of the values that are not NaN (inf counts: it sorts last); NaN if none."""
    v = [x for x in values if not math.isnan(x)]
    return float(np.median(v)) if v else float("nan")


def _log_error(value: float, ref: float) -> float:
    """|ln(value / ref)|: 0 when equal, ln 2 a factor of two either way; inf for a value <= 0
    (a wave running the wrong way, a force pulling upwind); NaN when not measured."""
    if math.isnan(value):
        return float("nan")
    return abs(math.log(value / ref)) if value > 0 else float("inf")


def model_summary(rows) -> list[dict[str, Any]]:
    """Per (model, drag) over the flapping runs (U > 0): the median of each figure, its distance
    to the references (|log ratio|: c_f against EN 1991-1-4, wavelength / L against 1.87, wave
    speed / U against 1), and the median cost."""
    s = flagsim.Scene.paper()
    cf_ref, length = reference_force_coefficient(s), s.flag.width
    out = []
    keys = sorted({(r["model"], r["drag"]) for r in rows}, key=lambda k: (MODELS.index(k[0]), k))
    for model, drag in keys:
        rs = [r for r in rows if (r["model"], r["drag"]) == (model, drag)]
        windy = [r for r in rs if _num(r, "speed") > 0 and "diverged" not in r["state"]]
        fl = [r for r in windy if r["state"] == "ok"]  # a flapping peak in the spectrum
        cf = [_num(r, "force_coefficient") for r in windy]
        lam = [_num(r, "wavelength") / length for r in fl]
        c = [_num(r, "wave_speed") / _num(r, "speed") for r in fl]
        # a speed without a flapping peak is as far from the flags' waves as it gets (inf), so
        # a model that flaps at fewer than half the speeds cannot score on its lucky ones
        missed = [math.inf] * (len(windy) - len(fl))
        errs = {
            "c_f": _median([_log_error(v, cf_ref) for v in cf]),
            "wavelength": _median([_log_error(v, WAVELENGTH_REF) for v in lam] + missed),
            "wave speed": _median([_log_error(v, WAVE_SPEED_REF) for v in c] + missed),
        }
        out.append(
            dict(
                model=model,
                drag=drag,
                c_f=_median(cf),
                wavelength_ratio=_median(lam),
                speed_ratio=_median(c),
                frequency=_median([_num(r, "frequency") for r in fl]),
                amplitude_ratio=_median([_num(r, "amplitude_ratio") for r in fl]),
                strouhal=_median([_num(r, "strouhal") for r in fl]),
                errors=errs,
                score=float(np.mean(list(errs.values()))),
                cost=_median([_num(r, "cost") for r in rs]),
                diverged=sum("diverged" in r["state"] for r in rs),
                flapping=f"{len(fl)} of {len(windy)}",
            )
        )
    return out


def _sizes(rows) -> str:
    s = flagsim.Scene.paper()
    speeds = sorted({_num(r, "speed") for r in rows})
    t = sorted({(_num(r, "transient"), _num(r, "duration")) for r in rows})
    times = ", ".join(f"{a:g} s transient + {b:g} s recorded" for a, b in t)
    return (
        f"Sizes: the paper's flag ({s.flag.rows} x {s.flag.cols} masses, {s.flag.width} m x "
        f"{s.flag.height} m, {s.flag.areal_density} kg/m^2, implicit, dt = {s.dt} s) on its "
        f"pole; wind {', '.join(f'{u:g}' for u in speeds)} m/s; {times} per run; one thread "
        f"per run. Turbulence: intensity {TURBULENCE_INTENSITY:g} U, length scale "
        f"{TURBULENCE_LENGTH:g} m, evolution U / length scale. Spectra: Welch, {SEGMENT:g} s "
        "Hann segments, half overlap."
    )


def write_report(rows, path: str, plot: str | None, relative_to: str, machine: str) -> None:
    """The markdown report; machine: as accuracy.write_report's."""
    cf_ref = reference_force_coefficient()
    lines = [
        "# Flutter study: the paper's flag in wind, per model",
        "",
        "Generated by `flagsim study flutter`; rerun it to regenerate this page. What is measured,"
        " why, and the references: [docs/flutter.md](../flutter.md).",
        "",
        f"Machine: {machine}",
        "",
        _sizes(rows),
        "",
    ]
    if not any(r["model"] == "two_way" for r in rows):
        lines += [
            "The two-way model (two-way coupling + turbulence + the pole's wake) was not run: "
            "this build has no `air.coupling`.",
            "",
        ]
    if plot:
        lines += [f"![flutter]({os.path.relpath(plot, relative_to)})", ""]
    summary = model_summary(rows)
    ranked = sorted(summary, key=lambda m: m["score"])
    lines += [
        "## Per model: medians over 2..20 m/s against the references",
        "",
        f"References: c_f of a free flag {cf_ref:.3f} (EN 1991-1-4 section 7.12 for this flag), "
        f"wavelength {WAVELENGTH_REF} L and wave speed {WAVE_SPEED_REF:g} U (Raynaud & "
        "Mulleners). The flapping figures (f, A / L, f A / U, lambda, c) are medians over the "
        "runs whose spectrum has a flapping peak ('flapping': how many of the windy runs), c_f "
        "over every windy run. Error = median over the windy speeds of |ln(value / reference)| "
        "(0.69 = a factor of two; inf for waves running towards the pole and for a speed without "
        "a flapping peak); score = the mean of the three errors. Cost = wall seconds of "
        "stepping per simulated second, one thread.",
        "",
        "| model | drag | flapping | f (Hz) | A / L | f A / U | lambda / L | c / U | c_f "
        "| err c_f | err lambda | err c | score | wall s / sim s |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for m in ranked:
        e = m["errors"]
        lines.append(
            f"| {MODEL_TITLES[m['model']]} | {m['drag']} | {m['flapping']} | {m['frequency']:.3g} "
            f"| {m['amplitude_ratio']:.3g} | {m['strouhal']:.3g} | {m['wavelength_ratio']:.3g} "
            f"| {m['speed_ratio']:.3g} | {m['c_f']:.3g} | {e['c_f']:.2f} | {e['wavelength']:.2f} "
            f"| {e['wave speed']:.2f} | {m['score']:.2f} | {m['cost']:.3g} |"
        )
    lines.append("")
    if ranked:
        best = ranked[0]
        by_cf = min(summary, key=lambda m: m["errors"]["c_f"])
        lines += [
            f"Closest overall: **{MODEL_TITLES[best['model']]}, {best['drag']} drag** (score "
            f"{best['score']:.2f}) at {best['cost']:.3g} wall s per simulated s. Closest c_f: "
            f"{MODEL_TITLES[by_cf['model']]}, {by_cf['drag']} drag (median {by_cf['c_f']:.3g} "
            f"against {cf_ref:.3f}).",
            "",
        ]
    lines += ["## Droop angle (degrees below horizontal) against wind speed", ""]
    speeds = sorted({_num(r, "speed") for r in rows})
    lines += [
        "| model | drag | " + " | ".join(f"{u:g} m/s" for u in speeds) + " |",
        "|---|---|" + "---:|" * len(speeds),
    ]
    for model, drag in sorted(
        {(r["model"], r["drag"]) for r in rows}, key=lambda k: (MODELS.index(k[0]), k)
    ):
        by = {_num(r, "speed"): r for r in rows if (r["model"], r["drag"]) == (model, drag)}
        cells = [_fmt(by[u], "droop", ".1f") if u in by else "" for u in speeds]
        lines.append(f"| {MODEL_TITLES[model]} | {drag} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Every run",
        "",
        "F: the mean force of the flag on its pole along the wind (one-way: the whole step's "
        "momentum balance; two-way: sim.pole_impulse). F core: sim.pole_impulse for every run, "
        "the balance of the drag the implicit solve applied (linearised; docs/flutter.md).",
        "",
        "| model | drag | U (m/s) | f (Hz) | A / L | f A / U | lambda (m) | c (m/s) | F (N) "
        "| F core (N) | c_f | droop | wall s / sim s | state |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        lines.append(
            f"| {MODEL_TITLES[r['model']]} | {r['drag']} | {_fmt(r, 'speed', 'g')} "
            f"| {_fmt(r, 'frequency')} | {_fmt(r, 'amplitude_ratio')} | {_fmt(r, 'strouhal')} "
            f"| {_fmt(r, 'wavelength')} | {_fmt(r, 'wave_speed')} | {_fmt(r, 'force')} "
            f"| {_fmt(r, 'force_core')} "
            f"| {_fmt(r, 'force_coefficient')} | {_fmt(r, 'droop', '.1f')} | {_fmt(r, 'cost')} "
            f"| {r['state']} |"
        )
    lines.append("")
    write_text(path, "\n".join(lines))


def headline(rows) -> str:
    """One line per model and drag for the terminal: medians, and the closest model."""
    summary = model_summary(rows)
    out = [
        f"{MODEL_TITLES[m['model']]:>34}, {m['drag']:>8}: f {m['frequency']:.3g} Hz, "
        f"A/L {m['amplitude_ratio']:.3g}, lambda/L {m['wavelength_ratio']:.3g}, "
        f"c/U {m['speed_ratio']:.3g}, c_f {m['c_f']:.3g}, score {m['score']:.2f}, "
        f"{m['cost']:.3g} wall s per simulated s"
        for m in summary
    ]
    if summary:
        best = min(summary, key=lambda m: m["score"])
        out.append(
            f"closest to the references: {MODEL_TITLES[best['model']]}, {best['drag']} drag "
            f"(c_f reference {reference_force_coefficient():.3f})"
        )
    return "\n".join(out)
