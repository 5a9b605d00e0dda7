"""Run independent tasks through a concurrent.futures.Executor, resumably: the study cases, and
the sweep's combinations (flagsim.sweep).

Each case is a plain dict of settings with a unique "id"; the case function is a pure, top-level
(picklable) function of that dict returning a dict of results. Only this (head) process writes:
rows are appended to a CSV as cases finish (one write per row, flushed), so an interrupted run
resumes by skipping the ids already in the file, and once every case is done the CSV is rewritten
in case order, so it is the same, byte for byte apart from measured times, whichever worker ran
a case and in which order. A result may carry files (``FILES``: relative path -> bytes), written
whole under ``files_dir`` before the row: a worker need not see the head's folders.

On a Dask executor each case is a task keyed by a hash of its settings (flagsim._pool.task_key).
A case that raises is submitted once more (``retries``) under a fresh key; one whose workers died
(the scheduler's allowed-failures) is not. The others go on; then TaskFailed names the failed
cases, whose rows are missing, so running the same command again runs only them. ``index``
gets one row per finished case: where it ran, how long it took, how many attempts it needed.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import os
from pathlib import Path, PurePosixPath
from typing import Any, Callable, Iterable, Sequence

from .. import _pool

#: result key of the files a case hands to the head: {path relative to files_dir: bytes}
FILES = "_files"
#: columns of the task index (and the placement columns a sweep's CSV carries)
INDEX_COLUMNS = ["id", "key", "attempts", "worker", "host", "pid", "seconds"]


class TaskFailed(RuntimeError):
    """Cases failed for good; ``failures`` maps each id to its error. The finished cases are in
    the CSV, so running the same command again runs only the failed ones."""

    def __init__(self, message, failures):
        super().__init__(message)
        self.failures = dict(failures)


def read_rows(path: str) -> list[dict[str, str]]:
    """Rows of a results CSV; a torn last line (interrupted write) is dropped."""
    if not os.path.exists(path):
        return []
    with open(path, newline="") as f:
        text = f.read()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    lines = text.splitlines(keepends=True)
    if not lines:
        return []
    reader = csv.DictReader(lines)
    n = len(reader.fieldnames or [])
    return [r for r in reader if None not in r and len(r) == n and None not in r.values()]


def _rewrite_clean(path: str, columns: Sequence[str], rows: list[dict[str, str]]) -> None:
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(columns), extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


def _open_csv(path: str, columns: Sequence[str]) -> list[dict[str, str]]:
    """Rows already in `path` (checked to have `columns`), the file rewritten clean (a torn
    last line dropped) so rows can be appended; a new file gets the header."""
    existing: list[dict[str, str]] = []
    if os.path.exists(path):
        with open(path, newline="") as f:
            header = f.readline().strip().split(",")
        if header != list(columns):
            raise ValueError(
                f"{path} has columns {header}, expected {list(columns)}: "
                "remove it or choose another --out"
            )
        existing = read_rows(path)
    else:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    _rewrite_clean(path, columns, existing)
    return existing


def write_files(root: str, files: dict[str, bytes]) -> None:
    """Write a task's files under `root`, each whole or not at all, in the given order; a file
    already holding the same bytes is left alone (its modification time still says when its
    content changed)."""
    from ..povray.scenefiles import write_bytes

    for rel, data in files.items():
        p = PurePosixPath(rel)
        if p.is_absolute() or ".." in p.parts or not p.parts:
            raise ValueError(
                f"a task's file should be a relative path inside its folder, got {rel!r}"
            )
        path = Path(root, *p.parts)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes(path, data)


def _why(err: BaseException) -> str:
    if type(err).__name__ == "KilledWorker":  # distributed.scheduler.KilledWorker
        n = err.allowed_failures
        return (
            f"the worker running it died, {n + 1} time{'s' if n else ''} (the scheduler's "
            f"distributed.scheduler.allowed-failures is {n})"
        )
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0]}" if text else type(err).__name__


def run_cases(
    cases: Sequence[dict[str, Any]],
    fn: Callable[[dict[str, Any]], dict[str, Any]],
    path: str,
    columns: Sequence[str],
    *,
    jobs: int = 1,
    executor: cf.Executor | None = None,
    progress: bool = True,
    desc: str = "cases",
    unit: str = "case",
    index: str | None = None,
    files_dir: str | None = None,
    retries: int = 1,
) -> list[dict[str, str]]:
    """Run every case not yet in `path`, appending its row; return all rows in case order.

    jobs = 1 runs in this process (best for timing); jobs > 1 uses a process pool unless an
    `executor` is given (any concurrent.futures.Executor: a Dask client's, a thread pool).
    A row holds the case's `columns` from the case and its result, and from its placement
    (INDEX_COLUMNS: attempts, worker, host, pid, seconds) where `columns` names them.
    Raises TaskFailed naming the cases that failed, after every other case has finished.
    """
    ids = [str(c["id"]) for c in cases]
    if len(set(ids)) != len(ids):
        raise ValueError("case ids should be unique")
    existing = _open_csv(path, columns)
    if index is not None:
        _open_csv(index, INDEX_COLUMNS)
    wanted = set(ids)
    done = {r["id"]: r for r in existing if r["id"] in wanted}
    todo = [c for c in cases if str(c["id"]) not in done]
    keys = {str(c["id"]): _pool.task_key(desc, fn, c) for c in todo}

    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc=desc, unit=unit, dynamic_ncols=True)

    def record(case: dict[str, Any], result: dict[str, Any], placement: dict[str, Any]) -> None:
        cid = str(case["id"])
        files = result.pop(FILES, None)
        if files:
            write_files(files_dir or os.path.dirname(os.path.abspath(path)), files)
        where = {**placement, "id": cid, "key": keys[cid]}
        row = {**{k: case.get(k, "") for k in columns}, **result, **where}
        _append(path, [row.get(c, "") for c in columns])
        if index is not None:
            _append(index, [where.get(c, "") for c in INDEX_COLUMNS])
        done[cid] = {c: str(row.get(c, "")) for c in columns}
        if bar is not None:
            bar.update(1)

    failures: dict[str, BaseException] = {}
    try:
        if jobs <= 1 and executor is None:
            for c in todo:
                for attempt in range(retries + 1):
                    try:
                        result, placement = _pool.placed(fn, c)
                    except Exception as e:  # reported with the others at the end
                        failures[str(c["id"])] = e
                        continue
                    failures.pop(str(c["id"]), None)
                    record(c, result, {**placement, "attempts": attempt + 1})
                    break
                else:
                    if bar is not None:
                        bar.update(1)
        else:
            own = executor is None
            ex = executor or _pool.worker_pool(jobs)  # workers die with this process
            try:
                _run_pooled(ex, fn, todo, keys, retries, record, failures, bar)
            finally:
                if own:
                    ex.shutdown(cancel_futures=True)
    finally:
        if bar is not None:
            bar.close()
    if failures:
        failed = [i for i in ids if i in failures]
        shown = "; ".join(f"{i}: {_why(failures[i])}" for i in failed[:3])
        shown += f"; and {len(failed) - 3} more" if len(failed) > 3 else ""
        raise TaskFailed(
            f"{len(failures)} of {len(ids)} {desc} tasks failed ({shown}); the "
            f"{len(done)} finished are in {path}: run the same command again to retry the "
            f"failed ones",
            failures,
        ) from failures[failed[0]]
    others = [r for r in existing if r["id"] not in wanted]
    _rewrite_clean(path, columns, [done[i] for i in ids] + others)  # in case order
    return [done[i] for i in ids]


def _run_pooled(ex, fn, todo, keys, retries, record, failures, bar) -> None:
    """Submit every case, record each as it finishes, resubmit a raising one (fresh key)."""
    pending: dict[cf.Future, tuple[dict[str, Any], int]] = {}

    def submit(case, attempt):
        cid = str(case["id"])
        key = keys[cid] if attempt == 0 else None  # a rerun: pure=False, a fresh key
        try:
            pending[_pool.submit(ex, _pool.placed, fn, case, key=key)] = (case, attempt)
        except Exception as e:  # a broken executor: the case failed, not dropped
            failures[cid] = e
            if bar is not None:
                bar.update(1)

    try:
        for c in todo:
            submit(c, 0)
        while pending:
            finished, _ = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
            for fut in finished:
                case, attempt = pending.pop(fut)
                cid = str(case["id"])
                try:
                    result, placement = fut.result()
                except Exception as e:
                    if attempt < retries and type(e).__name__ != "KilledWorker":
                        submit(case, attempt + 1)
                        continue
                    failures[cid] = e
                    if bar is not None:
                        bar.update(1)
                    continue
                failures.pop(cid, None)
                lost = _pool.reruns(ex, keys[cid]) if attempt == 0 else 0
                record(case, result, {**placement, "attempts": attempt + 1 + lost})
    finally:
        for fut in pending:  # interrupted: nothing more is queued for this run
            fut.cancel()


def _append(path: str, values: Iterable[Any]) -> None:
    import io

    buf = io.StringIO()
    csv.writer(buf).writerow(["" if v is None else v for v in values])
    with open(path, "a", newline="") as f:
        f.write(buf.getvalue())
        f.flush()
