import flagsim
import pytest


def spring_pair(method: str, k: float = 100.0, dt: float = 1e-3) -> flagsim.Scene:
    """One free mass on a vertical spring: the accuracy study's own scene."""
    from flagsim.study.accuracy import pair_scene

    return pair_scene(method, dt, k)


@pytest.fixture
def paper():
    return flagsim.Scene.paper()
