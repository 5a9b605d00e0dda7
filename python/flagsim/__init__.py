"""flagsim: real-time simulation of flags whipped by the wind, rendered with POV-Ray.

The method is Okamoto, Fujisawa and Miura, "Real Time Simulation of Whipped Flags in the Wind":
Stable Fluids air pushing a mass-spring flag one way, vertex-triangle self-collision, and
Perlin-noise flapping (eq. 5). ``import flagsim`` loads only numpy and the compiled core; the
CLI, plotting and rendering helpers load when used.
"""
from ._core import (
    DivergenceError,
    FanParams,
    Fluid,
    __version__,
    has_fftw,
    has_openmp,
    num_threads,
    set_num_threads,
)

__all__ = [
    "DivergenceError",
    "FanParams",
    "Fluid",
    "__version__",
    "has_fftw",
    "has_openmp",
    "num_threads",
    "set_num_threads",
]
