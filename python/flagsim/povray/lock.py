"""One writer per export folder: a lock file naming its holder, created whole (link(2)).

`flagsim run` (export), `flagsim render` and `flagsim sweep` hold ``DIR/.flagsim.lock`` while they
write into DIR. The lock's record also tells a task on another machine whether it sees DIR
(sees_folder): a folder of the same name elsewhere does not hold the same record.
A second writer is refused with a message naming the holder (pid, host, start time, command).
A lock left by a process that no longer runs on this host (kill -9, OOM) is taken over. A lock
from another host is never taken over: remove the file by hand once that process is gone.
"""

from __future__ import annotations

import datetime as _dt
import errno
import json
import os
import socket
import sys
from pathlib import Path

LOCK_NAME = ".flagsim.lock"


class ExportBusy(ValueError):
    """Another process is writing into the folder."""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def _describe(holder: dict) -> str:
    return (
        f"pid {holder.get('pid')} on {holder.get('host')} since {holder.get('started')} "
        f"({holder.get('command')})"
    )


#: set to 0 in a worker's environment and it never writes into the head's folders, even when it
#: sees them (a read-only or slow mount): it returns its files to the head instead
SHARED_ENV = "FLAGSIM_SHARED_FOLDERS"


def sees_folder(out_dir, record) -> bool:
    """True when ``out_dir/.flagsim.lock`` holds ``record``, the lock record of the process that
    handed out the task: this process sees that process's folder (the same machine, or a shared
    file system), not merely a folder of the same name. False also where $FLAGSIM_SHARED_FOLDERS
    is 0."""
    if record.get("pid") == os.getpid() and record.get("host") == socket.gethostname():
        return True  # this process's own lock (a task rendering the export it just made)
    if os.environ.get(SHARED_ENV, "1").strip() == "0":
        return False
    try:
        return json.loads((Path(out_dir) / LOCK_NAME).read_text(encoding="utf-8")) == record
    except (OSError, ValueError):
        return False


class ExportLock:
    """Context manager holding ``out/.flagsim.lock``; raises ExportBusy if another live process
    holds it. The folder must exist."""

    def __init__(self, out_dir):
        self.path = Path(out_dir) / LOCK_NAME
        self.held = False
        self.record = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "command": " ".join(Path(sys.argv[0]).name.split() + sys.argv[1:])[:200],
        }

    def _create(self) -> bool:
        # Whole or not at all: the record goes into a private file, which is then linked to the
        # lock's name (link fails if the name exists), so a reader never sees a half-written lock.
        # (Not named *.tmp: the lock holder's clean-up of interrupted writes removes those.)
        tmp = self.path.with_name(f"{LOCK_NAME}.{os.getpid()}")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o644)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(self.record, f)
            os.link(tmp, self.path)
            return True
        except (FileExistsError, FileNotFoundError):
            return False
        finally:
            tmp.unlink(missing_ok=True)

    def _holder(self) -> dict | None:
        try:
            holder = json.loads(self.path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return {}  # unreadable or half-written: treated as held by an unknown process
        return holder if isinstance(holder, dict) else {}

    def acquire(self) -> None:
        holder = None
        for _ in range(3):  # a takeover can race with another process's; retry a few times
            if self._create():
                self.held = True
                return
            holder = self._holder()
            if holder is None:
                continue  # released in between
            stale = (
                holder.get("host") == self.record["host"]
                and isinstance(holder.get("pid"), int)
                and not _alive(holder["pid"])
            )
            if not stale:
                break
            try:  # take over a dead process's lock: remove it, then race for a fresh one
                self.path.unlink()
            except FileNotFoundError:
                pass
        # The holder that refused us, as read then: read again, it may have finished meanwhile.
        raise ExportBusy(
            f"{self.path.parent} is being written by "
            f"{_describe(holder) if holder else 'another process'}; wait for it to "
            f"finish, or remove {self.path} if that process is gone"
        )

    def release(self) -> None:
        if not self.held:
            return
        self.held = False
        try:
            holder = self._holder()
            if (
                holder
                and holder.get("pid") == self.record["pid"]
                and holder.get("started") == self.record["started"]
            ):
                self.path.unlink()
        except OSError as e:
            if e.errno != errno.ENOENT:
                raise

    def __enter__(self):
        self.acquire()
        return self

    def __exit__(self, *exc):
        self.release()
        return False
