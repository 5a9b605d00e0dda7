import flagsim
import pytest


def test_divergence_error_is_a_runtime_error():
    assert issubclass(flagsim.DivergenceError, RuntimeError)


def test_thread_count_round_trip_and_validation():
    n = flagsim.num_threads()
    try:
        flagsim.set_num_threads(1)
        assert flagsim.num_threads() == 1
    finally:
        flagsim.set_num_threads(n)
    with pytest.raises(ValueError, match=r"threads should be >= 1, got 0"):
        flagsim.set_num_threads(0)
