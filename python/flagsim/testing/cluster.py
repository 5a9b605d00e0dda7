"""Task wrappers for the cluster tests (tests/python/test_distributed.py): importable by Dask
workers, which unpickle a task's function by its module and name."""

from __future__ import annotations

import importlib
import os
import time
from pathlib import Path


def _resolve(name: str):
    module, _, attr = name.partition(":")
    return getattr(importlib.import_module(module), attr)


def announced(case, *, fn: str, folder: str, victim: str = "", timeout: float = 120.0):
    """Run ``fn`` ("module:name") on the case, first leaving ``folder/started/<id>.<pid>`` (the
    worker's pid: a test can kill it). The ``victim`` case then waits for ``folder/go`` before
    it runs: time for the test to kill its worker mid-task; its rerun (go there) does not wait."""
    started = Path(folder) / "started"
    started.mkdir(parents=True, exist_ok=True)
    (started / f"{case['id']}.{os.getpid()}").touch()
    if case["id"] == victim:
        deadline = time.monotonic() + timeout
        while not (Path(folder) / "go").exists():
            if time.monotonic() > deadline:
                raise TimeoutError(f"{folder}/go did not appear within {timeout} s")
            time.sleep(0.02)
    return _resolve(fn)(case)


def failing(case, *, fn: str, fails: str):
    """Run ``fn`` on the case, except the case ``fails``, which always raises."""
    if case["id"] == fails:
        raise RuntimeError(f"case {case['id']} fails on purpose")
    return _resolve(fn)(case)


def setenv(name: str, value: str | None) -> None:
    """Set (or, with None, remove) an environment variable in this process: ``client.run``
    it to change a running worker's (os.environ's own methods would pickle a copy)."""
    if value is None:
        os.environ.pop(name, None)
    else:
        os.environ[name] = value
