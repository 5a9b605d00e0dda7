"""Executors for the many-task commands (studies, sweeps, renders): a local process pool whose
workers die with the process that started them, or a Dask cluster (the optional extra
``distributed``). The commands see only a concurrent.futures.Executor; this module opens one and
names the tasks submitted to it.

Local pool: a worker of a plain ProcessPoolExecutor outlives a parent killed with SIGKILL (or by
the OOM killer) and goes on rendering frames or running study cases for nobody. Here every worker
asks the kernel for SIGKILL when its parent dies (Linux ``prctl(PR_SET_PDEATHSIG)``), and the
POV-Ray processes a worker starts ask the same of the worker, so the whole tree goes with the
head process. Where prctl does not exist (macOS, Windows) the workers fall back to the pool's
own clean-up, which covers every exit but SIGKILL.

Dask (docs/distributed.md): ``cluster(scheduler=ADDRESS)`` connects to a running scheduler,
``cluster(workers=N)`` starts a LocalCluster of N single-threaded worker processes (children of
this process; they leave with it); both yield ``Client.get_executor()``. ``submit`` gives a Dask
task the key ``task_key(...)``, a hash of its settings, so the same settings are one task
cluster-wide, and a fresh random key (pure=False) where a task must run again.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import hashlib
import json
import logging
import multiprocessing
import os
import signal
import socket
import sys
import time
from concurrent.futures import ProcessPoolExecutor

_PR_SET_PDEATHSIG = 1

#: what to install for --scheduler / --workers (named in the error when Dask is missing)
DASK_INSTALL = "pip install 'flagsim[distributed]'  (or: pip install distributed)"


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


# ---- Dask -----------------------------------------------------------------------------------


class DaskNotInstalled(ModuleNotFoundError):
    """A Dask cluster was asked for, but the ``distributed`` package is not installed."""


def import_distributed():
    """The ``distributed`` module, or DaskNotInstalled saying what to install."""
    try:
        import distributed
    except ImportError:
        raise DaskNotInstalled(
            f"running on a Dask cluster (--scheduler, --workers) needs Dask distributed, which "
            f"is not installed: {DASK_INSTALL}",
            name="distributed",
        ) from None
    return distributed


def is_dask(executor) -> bool:
    """True for a Dask client's executor (``Client.get_executor()``)."""
    cf = sys.modules.get("distributed.cfexecutor")  # not imported: cannot be one
    return cf is not None and isinstance(executor, cf.ClientExecutor)


def _flagsim_version() -> str:
    import flagsim

    return flagsim.__version__


@contextlib.contextmanager
def cluster(scheduler: str | None = None, workers: int | None = None):
    """Yield the executor of a Dask cluster: the scheduler at ``scheduler`` (``tcp://host:8786``),
    or a LocalCluster of ``workers`` processes with one thread each, started here and closed on
    exit. Yields None when neither is given (the caller's local pool applies)."""
    if scheduler is None and workers is None:
        yield None
        return
    if scheduler is not None and workers is not None:
        raise ValueError(
            "--workers should not be given with --scheduler: --workers starts a local "
            "cluster, while a scheduler's own workers run the tasks"
        )
    if workers is not None and (isinstance(workers, bool) or workers < 1):
        raise ValueError(f"--workers should be >= 1, got {workers}")
    if scheduler is not None and not str(scheduler).strip():
        raise ValueError(
            f"--scheduler should be a scheduler address (tcp://host:8786), got {scheduler!r}"
        )
    distributed = import_distributed()
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            # processes, not threads: the simulation and POV-Ray are CPU-bound, and a killed
            # worker process is replaced by its nanny (docs/distributed.md)
            target = stack.enter_context(
                distributed.LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=":0",  # any free port: 8787 may be another cluster's
                    # quiet: a task's failure reaches the head, which names it; on Ctrl-C a worker
                    # still busy would log the scheduler's going (heartbeat errors, tracebacks)
                    silence_logs=logging.CRITICAL,
                )
            )
        else:
            target = scheduler
        try:
            # waits up to Dask's distributed.comm.timeouts.connect (30 s) for a scheduler
            client = stack.enter_context(distributed.Client(target))
        except (OSError, ValueError) as e:  # unreachable (TimeoutError is an OSError), bad form
            raise OSError(f"could not connect to the Dask scheduler at {scheduler}: {e}") from None
        _check_workers(client)
        if scheduler is None:
            from ._dask import IgnoreInterrupts

            client.register_plugin(IgnoreInterrupts())
        executor = client.get_executor()
        try:
            yield executor
        finally:
            executor.shutdown(wait=False)  # cancels what is still queued (Ctrl-C, a failure)


def _check_workers(client) -> None:
    """Every connected worker runs this flagsim version (they unpickle flagsim's functions);
    a scheduler without workers is said so, since its tasks then wait."""
    mine = _flagsim_version()
    try:
        theirs = client.run(_flagsim_version)
    except ImportError as e:
        raise OSError(
            f"a Dask worker cannot import flagsim ({e}): install the same flagsim on every "
            f"worker (docs/distributed.md)"
        ) from None
    other = {w: v for w, v in theirs.items() if v != mine}
    if other:
        shown = ", ".join(f"{w} has {v}" for w, v in sorted(other.items()))
        raise OSError(f"Dask workers run another flagsim than this {mine}: {shown}")
    if not theirs:
        print(
            "flagsim: the Dask scheduler has no workers yet; the tasks wait for them",
            file=sys.stderr,
        )


def _jsonable(obj):
    import dataclasses
    import functools

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        # a field left out of comparisons (compare=False) is where a task runs, not what it is
        return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.compare}
    if isinstance(obj, functools.partial):
        return [obj.func, list(obj.args), obj.keywords]
    if callable(obj):
        return f"{getattr(obj, '__module__', '')}.{getattr(obj, '__qualname__', repr(obj))}"
    if isinstance(obj, bytes):
        return hashlib.sha256(obj).hexdigest()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"task settings should be JSON-able, got {type(obj).__name__}")


def task_key(prefix: str, *settings) -> str:
    """A Dask key from a hash of a task's settings: ``PREFIX-<24 hex>``. The same settings give
    the same key on every head, so a cluster runs them once (a second submission joins the
    first); any change of a setting gives another task."""
    blob = json.dumps(settings, sort_keys=True, default=_jsonable, separators=(",", ":"))
    return f"{prefix}-{hashlib.sha256(blob.encode()).hexdigest()[:24]}"


def submit(executor, fn, *args, key: str | None = None):
    """``executor.submit(fn, *args)``; on Dask the task is named ``key`` (task_key), or, with
    key None, gets a fresh random key (pure=False) so that it runs again even when the cluster
    still holds a result or an error under its settings' key."""
    if not is_dask(executor):
        return executor.submit(fn, *args)
    if key is None:
        return executor.submit(fn, *args, pure=False)
    return executor.submit(fn, *args, key=key)


def reruns(executor, key: str) -> int:
    """How many times the task ``key`` was sent back to the queue because the worker running it
    left the cluster (the scheduler's remove-worker events); 0 off Dask."""
    client = getattr(executor, "_client", None) if is_dask(executor) else None
    if client is None:
        return 0
    return sum(
        1
        for _, msg in client.get_events("all")
        if isinstance(msg, dict)
        and msg.get("action") == "remove-worker"
        and key in msg.get("processing-tasks", ())
    )


def worker_name() -> str:
    """The Dask worker's address when called in a Dask task, else "local"."""
    if sys.modules.get("distributed") is not None:  # not imported: not in a Dask task
        from distributed import get_worker

        try:
            return get_worker().address
        except ValueError:  # not in a Dask task
            pass
    return "local"


def placed(fn, *args):
    """Run ``fn(*args)`` and say where and for how long: ``(result, placement)``, placement a
    dict of worker (Dask address or "local"), host, pid and seconds (wall time)."""
    t0 = time.perf_counter()
    result = fn(*args)
    return result, {
        "worker": worker_name(),
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "seconds": f"{time.perf_counter() - t0:.4g}",
    }
