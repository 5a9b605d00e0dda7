import pytest

import flagsim


def spring_pair(method: str, k: float = 100.0, dt: float = 1e-3) -> flagsim.Scene:
    """One free mass on a vertical spring (vertices 0-2 pinned): period 2 pi sqrt(m_3 / k)."""
    s = flagsim.Scene()
    s.flag.rows = s.flag.cols = 2
    s.flag.width = s.flag.height = 0.1
    s.flag.stretch_stiffness = k
    s.flag.shear_stiffness = s.flag.bend_stiffness = s.flag.damping = 0.0
    s.flag.pinned_vertices = [0, 1, 2]
    s.air.model = "none"
    s.gravity = (0, 0, 0)
    s.integrator.method = method
    s.integrator.adaptive = False
    s.integrator.cg_tolerance = 1e-12
    s.dt = dt
    return s


@pytest.fixture
def paper():
    return flagsim.Scene.paper()
