"""Process pools whose workers die with the process that started them.

A worker of a plain ProcessPoolExecutor outlives a parent killed with SIGKILL (or by the OOM
killer) and goes on rendering frames or running study cases for nobody. Here every worker asks
the kernel for SIGKILL when its parent dies (Linux ``prctl(PR_SET_PDEATHSIG)``), and the
POV-Ray processes a worker starts ask the same of the worker, so the whole tree goes with the
head process. Where prctl does not exist (macOS, Windows) the workers fall back to the pool's
own clean-up, which covers every exit but SIGKILL.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import multiprocessing
import os
import signal
import sys
from concurrent.futures import ProcessPoolExecutor

_PR_SET_PDEATHSIG = 1


def die_with_parent(parent_pid: int | None = None) -> bool:
    """Ask for SIGKILL when the parent process dies; True when the kernel took the request. The
    pool's worker initializer, and the ``preexec_fn`` of the processes a (single-threaded)
    worker starts.

    ``parent_pid``: the pid the caller expects as its parent; if the parent is already gone
    (it died before the request was made), exit at once.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        ok = libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False
    if parent_pid is not None and os.getppid() != parent_pid:
        os._exit(1)
    return ok


def worker_pool(max_workers: int | None = None) -> ProcessPoolExecutor:
    """A ProcessPoolExecutor (spawn start method: the parent may run OpenMP threads, and fork
    after threads is unsafe) whose workers die with this process."""
    return ProcessPoolExecutor(
        max_workers=max_workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=die_with_parent,
        initargs=(os.getpid(),),
    )
