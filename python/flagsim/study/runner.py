"""Run independent study cases through a concurrent.futures.Executor, resumably.

Each case is a plain dict of settings with a unique "id"; the case function is a pure, top-level
(picklable) function of that dict returning a dict of results. Rows are appended to a CSV as they
finish (one write per row, flushed), so an interrupted study resumes by skipping the ids already
in the file. Results do not depend on where or in which order a case ran.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import os
from typing import Any, Callable, Iterable, Sequence

from .._pool import worker_pool


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
    tmp = path + ".tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(columns), extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


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
) -> list[dict[str, str]]:
    """Run every case not yet in `path`, appending its row; return all rows in case order.

    jobs = 1 runs in this process (best for timing); jobs > 1 uses a process pool unless an
    `executor` is given (any concurrent.futures.Executor, e.g. a cluster's).
    """
    ids = [str(c["id"]) for c in cases]
    if len(set(ids)) != len(ids):
        raise ValueError("case ids should be unique")
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
    _rewrite_clean(path, columns, existing)  # drops a torn last line before appending
    wanted = set(ids)
    done = {r["id"]: r for r in existing if r["id"] in wanted}
    todo = [c for c in cases if str(c["id"]) not in done]

    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc=desc, unit="case", dynamic_ncols=True)

    def record(case: dict[str, Any], result: dict[str, Any]) -> None:
        row = {**{k: case.get(k, "") for k in columns}, **result, "id": str(case["id"])}
        line = _csv_line([row.get(c, "") for c in columns])
        with open(path, "a", newline="") as f:
            f.write(line)
            f.flush()
        done[str(case["id"])] = {c: str(row.get(c, "")) for c in columns}
        if bar is not None:
            bar.update(1)

    try:
        if jobs <= 1 and executor is None:
            for c in todo:
                record(c, fn(c))
        else:
            own = executor is None
            ex = executor or worker_pool(jobs)  # workers die with this process
            try:
                futures = {ex.submit(fn, c): c for c in todo}
                for fut in cf.as_completed(futures):
                    record(futures[fut], fut.result())
            finally:
                if own:
                    ex.shutdown(cancel_futures=True)
    finally:
        if bar is not None:
            bar.close()
    return [done[i] for i in ids]


def _csv_line(values: Iterable[Any]) -> str:
    import io

    buf = io.StringIO()
    csv.writer(buf).writerow(["" if v is None else v for v in values])
    return buf.getvalue()
