"""Optional parts the tests need (the extras [viewer] and [usd], an OpenGL driver)."""

import importlib.util
import os

import pytest


def require(reason):
    """Skip a test whose optional part is missing here, saying why (`reason` is None when it is
    present). Under CI (CI set) the test fails instead: `make test` installs every extra and
    Debian package the tests need, so a skip there would hide a missing feature."""
    if reason is None:
        return
    if os.environ.get("CI"):
        pytest.fail(f"{reason} (CI installs it: see the Makefile's deps and APT_PACKAGES)")
    pytest.skip(reason, allow_module_level=True)


def missing(module, extra):
    """None when `module` can be imported, else why not (for require)."""
    if importlib.util.find_spec(module) is not None:
        return None
    return f"{module} is not installed (pip install 'flagsim[{extra}]')"
