"""One writer per export folder (flagsim.povray.lock): a second writer is refused naming the
holder, a dead process's lock is taken over, and two real processes racing into one folder leave
one whole export."""

import json
import os
import socket
import subprocess
import sys

import flagsim.povray as pov
import pytest
from _standin import StandInSim


def export(out, **kw):
    return pov.export(StandInSim(), out, seconds=0.2, fps=10, dt=0.01, progress=False, **kw)


def test_a_second_writer_is_refused_naming_the_holder(tmp_path):
    with pov.ExportLock(tmp_path):
        with pytest.raises(
            pov.ExportBusy,
            match=rf"is being written by pid {os.getpid()} on "
            rf"{socket.gethostname()} since .*; wait",
        ):
            export(tmp_path)
        with pytest.raises(pov.ExportBusy):
            pov.render(tmp_path)
    assert not (tmp_path / ".flagsim.lock").exists()
    assert export(tmp_path).frames == 3  # free again


def test_a_refusal_names_the_holder_that_refused_even_if_it_finished_since(tmp_path, monkeypatch):
    # The holder finishes between the refusal and the message: the message names the holder
    # read at the refusal, not "another process" (seen in a race of two real runs).
    lock = pov.ExportLock(tmp_path)
    other = {"pid": 4321, "host": "elsewhere", "started": "earlier", "command": "flagsim run"}
    (tmp_path / ".flagsim.lock").write_text(json.dumps(other))
    reads = iter([other, None])
    monkeypatch.setattr(lock, "_holder", lambda: next(reads))
    with pytest.raises(pov.ExportBusy, match="is being written by pid 4321 on elsewhere"):
        lock.acquire()
    assert not lock.held


def test_the_lock_of_a_process_that_died_is_taken_over(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / ".flagsim.lock").write_text(
        json.dumps(
            {"pid": dead.pid, "host": socket.gethostname(), "started": "earlier", "command": "x"}
        )
    )
    assert export(tmp_path).frames == 3
    assert not (tmp_path / ".flagsim.lock").exists()


@pytest.mark.parametrize("holder", [{"pid": 1, "host": "another-machine"}, "half-written {"])
def test_a_lock_from_another_host_or_unreadable_is_never_taken_over(tmp_path, holder):
    lock = tmp_path / ".flagsim.lock"
    lock.write_text(json.dumps(holder) if isinstance(holder, dict) else holder)
    with pytest.raises(pov.ExportBusy, match=r"remove .*\.flagsim\.lock if that process is gone"):
        export(tmp_path)
    assert lock.exists()


def _race(out, scenes):
    cmd = [sys.executable, "-m", "flagsim", "run"]
    procs = [
        subprocess.Popen(
            cmd + [s, "--out", str(out), "--seconds", "0.3", "--quiet"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for s in scenes
    ]
    results = []
    for p in procs:
        _, err = p.communicate(timeout=120)  # waits, and closes the pipes
        results.append((p.returncode, err))
    return results


@pytest.mark.parametrize("attempt", range(2))
def test_two_processes_exporting_other_scenes_into_one_folder_leave_one_whole_export(
    tmp_path, attempt
):
    out = tmp_path / "shared"
    results = _race(out, ["paper", "flapping_demo"])
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2], results  # one wins; the other is refused, never both
    refused = next(err for code, err in results if code == 2)
    assert "is being written by pid" in refused or "holds an export of another scene" in refused
    manifest = pov.load_export(out)  # complete, and its frames are the winner's
    winner = next(s for s, (code, _) in zip(["paper", "flapping_demo"], results) if code == 0)
    assert winner in json.dumps(manifest["key"])
    assert len(list((out / "frames").glob("flag_*.inc"))) == manifest["frames"]
    assert not (out / ".flagsim.lock").exists()


def test_two_identical_runs_into_one_folder_never_break_each_other(tmp_path):
    out = tmp_path / "same"
    results = _race(out, ["paper", "paper"])
    assert {code for code, _ in results} <= {0, 2} and 0 in {c for c, _ in results}, results
    for code, err in results:
        assert "cannot rename" not in err
        if code == 2:
            assert "is being written by pid" in err
    assert pov.load_export(out)["complete"] is True
