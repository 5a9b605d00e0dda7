"""Pool workers, and the POV-Ray processes they start, die with the head process (issue 29:
kill -9 of `flagsim render` used to leave its workers rendering frames for nobody)."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from flagsim._pool import die_with_parent

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"),
    reason="PR_SET_PDEATHSIG is Linux's; elsewhere only the pool's " "own clean-up applies",
)


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie not yet reaped by its new parent is dead for our purpose
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (OSError, IndexError):
        return False


def _children(pid):
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True)
    return [int(p) for p in out.stdout.split()]


def _wait_gone(pids, seconds=30.0):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.1)
    return [p for p in pids if _alive(p)]


def _wait_for(predicate, seconds=60.0):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError("timed out waiting")


def test_die_with_parent_is_granted_on_linux():
    assert die_with_parent() is True


def test_study_pool_workers_die_with_a_killed_head(tmp_path):
    # The head runs worker_pool tasks that would sleep for minutes; kill -9 of the head must
    # take the workers with it.
    (tmp_path / "tasks.py").write_text(
        "import os, time\n"
        "def sleeper(folder):\n"
        "    open(os.path.join(folder, str(os.getpid())), 'w').close()\n"
        "    time.sleep(600)\n"
    )
    head = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; sys.path.insert(0, sys.argv[1]); import tasks\n"
            "from flagsim._pool import worker_pool\n"
            "ex = worker_pool(2)\n"
            "futures = [ex.submit(tasks.sleeper, sys.argv[1]) for _ in range(2)]\n"
            "[f.result() for f in futures]\n",
            str(tmp_path),
        ]
    )
    try:
        pids = _wait_for(
            lambda: [int(p.name) for p in tmp_path.iterdir() if p.name.isdigit()]
            if len(list(tmp_path.glob("[0-9]*"))) == 2
            else None
        )
        assert all(_alive(p) for p in pids)
        head.send_signal(signal.SIGKILL)
        head.wait()
        assert _wait_gone(pids) == [], "pool workers outlived their parent"
    finally:
        head.kill()


def test_render_workers_and_povray_die_with_a_killed_head(tmp_path):
    out = tmp_path / "out"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "flagsim",
            "run",
            "paper",
            "--seconds",
            "0.2",
            "--fps",
            "25",
            "--out",
            str(out),
            "--quiet",
        ],
        check=True,
    )
    pids_dir = tmp_path / "povray_pids"
    pids_dir.mkdir()
    fake = tmp_path / "povray"
    fake.write_text(f"#!/bin/sh\ntouch {pids_dir}/$$\nexec sleep 600\n")
    fake.chmod(0o755)
    env = dict(os.environ, FLAGSIM_POVRAY=str(fake))
    head = subprocess.Popen(
        [sys.executable, "-m", "flagsim", "render", str(out), "--jobs", "2", "--quiet"],
        env=env,
        stderr=subprocess.DEVNULL,
    )
    try:
        povrays = _wait_for(
            lambda: [int(p.name) for p in pids_dir.iterdir()]
            if len(list(pids_dir.iterdir())) >= 2
            else None
        )
        workers = [p for p in _children(head.pid) if _alive(p)]
        assert len(workers) >= 2 and all(_alive(p) for p in povrays)
        head.send_signal(signal.SIGKILL)
        head.wait()
        assert _wait_gone(workers + povrays) == [], "workers or POV-Ray outlived the head"
    finally:
        head.kill()
