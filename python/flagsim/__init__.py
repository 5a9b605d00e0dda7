"""flagsim: real-time simulation of flags whipped by the wind, rendered with POV-Ray.

The method is Okamoto, Fujisawa and Miura, "Real Time Simulation of Whipped Flags in the Wind":
Stable Fluids air pushing a mass-spring flag one way, vertex-triangle self-collision, and
Perlin-noise flapping (eq. 5). ``import flagsim`` loads only numpy and the compiled core; the
CLI, plotting and rendering helpers load when used.

    >>> import flagsim
    >>> sim = flagsim.Simulation(flagsim.Scene.paper())
    >>> sim.step(100)
    >>> round(sim.time, 6)
    1.0
"""

from . import scene as _scene  # noqa: F401 (attaches Scene.load, Scene.named, ...)
from ._core import (
    AirParams,
    DivergenceError,
    DragParams,
    FanParams,
    FlagParams,
    FlappingParams,
    Fluid,
    IntegratorParams,
    MotionSchedule,
    ObstacleParams,
    PoleParams,
    Scene,
    SelfCollisionParams,
    Simulation,
    SolidParams,
    TurbulenceParams,
    __version__,
    available_memory,
    flapping_displacement,
    flapping_ramp,
    has_fftw,
    has_openmp,
    num_threads,
    perlin1d,
    set_num_threads,
)

__all__ = [
    "AirParams",
    "DivergenceError",
    "DragParams",
    "FanParams",
    "ObstacleParams",
    "FlagParams",
    "FlappingParams",
    "Fluid",
    "IntegratorParams",
    "MotionSchedule",
    "PoleParams",
    "Scene",
    "SelfCollisionParams",
    "Simulation",
    "SolidParams",
    "TurbulenceParams",
    "__version__",
    "available_memory",
    "flapping_displacement",
    "flapping_ramp",
    "has_fftw",
    "has_openmp",
    "num_threads",
    "perlin1d",
    "set_num_threads",
]


def __getattr__(name):
    # flagsim.povray (POV-Ray export and rendering), flagsim.viewer (polyscope) and flagsim.usd
    # (usd-core) load on first use: simulating needs none of them.
    if name in ("povray", "viewer", "usd"):
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'flagsim' has no attribute {name!r}")
