import flagsim
import pytest
from _optional import missing_povray, require


def spring_pair(method: str, k: float = 100.0, dt: float = 1e-3) -> flagsim.Scene:
    """One free mass on a vertical spring: the accuracy study's own scene."""
    from flagsim.study.accuracy import pair_scene

    return pair_scene(method, dt, k)


@pytest.fixture
def paper():
    return flagsim.Scene.paper()


@pytest.fixture
def povray_installed():
    """For _optional.needs_povray."""
    require(missing_povray())
