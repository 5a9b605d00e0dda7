"""The parts of the Dask executor (flagsim._pool.cluster) that import distributed: loaded only
when a cluster is asked for, so flagsim runs without the optional extra."""

from __future__ import annotations

import signal
import threading

from distributed.diagnostics.plugin import WorkerPlugin


class IgnoreInterrupts(WorkerPlugin):
    """A local cluster's worker processes share the terminal's process group, so Ctrl-C reaches
    them as well as the head: they ignore it (instead of each printing a traceback) and leave
    when the head, interrupted, closes the cluster. Restarted workers get the plugin too."""

    idempotent = True
    name = "flagsim-ignore-interrupts"

    def setup(self, worker):
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
