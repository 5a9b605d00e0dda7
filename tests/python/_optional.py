"""Optional parts the tests need (the extras [viewer], [usd] and [distributed], an OpenGL
driver, POV-Ray)."""

import importlib.util
import os
import shutil

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


def missing_povray():
    """None when POV-Ray is on the PATH, else why not (for require)."""
    if shutil.which("povray") is not None:
        return None
    return "POV-Ray is not installed (Debian package povray)"


#: Marks a test that runs POV-Ray: skipped without it, failed without it under CI (the fixture
#: povray_installed, tests/python/conftest.py, calls require).
needs_povray = pytest.mark.usefixtures("povray_installed")
