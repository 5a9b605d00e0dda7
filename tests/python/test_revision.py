"""Which flagsim made a report (flagsim._revision): the checkout's HEAD for an editable install,
else the revision the core was built from; the study and bench reports print it."""

import os
import re
import subprocess

import flagsim
import pytest
from flagsim import _core, _revision

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def git(*args):
    return subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True, check=True)


def test_an_editable_install_reports_its_checkouts_head():
    here = os.path.dirname(os.path.abspath(flagsim.__file__))
    assert here.startswith(
        REPO
    ), "the tests run against the checkout (make test's editable install)"
    head = git("rev-parse", "--short=12", "HEAD").stdout.strip()
    dirty = git("status", "--porcelain", "--untracked-files=no").stdout.strip()
    assert _revision.revision() == head + ("-dirty" if dirty else "")


def test_elsewhere_the_revision_the_core_was_built_from(monkeypatch, tmp_path):
    built = dict(_core.build_info())["git_revision"]
    assert re.fullmatch(r"([0-9a-f]{12}(-dirty)?)?", built), built
    if built:  # a commit of this repository's history (configured from it)
        git("cat-file", "-e", built.removesuffix("-dirty") + "^{commit}")
    assert _revision._checkout_revision(str(tmp_path)) == ""  # not a checkout
    # a package inside a checkout's tree but not tracked there (a venv in the checkout)
    venv_like = os.path.join(REPO, "build")
    assert _revision._checkout_revision(venv_like) == ""
    monkeypatch.setattr(_revision, "_checkout_revision", lambda where: "")
    assert _revision.revision() == (f"{built} (build)" if built else "unknown")


def test_the_reports_print_it():
    from flagsim.study.report import machine_description

    from benchmarks.machine import git_revision

    assert git_revision() == _revision.revision()
    assert f"(git {_revision.revision()})" in machine_description()


@pytest.mark.parametrize("name", ["run_accuracy", "run_flutter", "run_stability"])
def test_a_study_reads_the_revision_before_it_writes_anything(monkeypatch, tmp_path, name):
    # Regenerated into a checkout (--docs docs/reports), a study's own plots are local changes to
    # tracked files: read after them, the report would call every regeneration "-dirty".
    from flagsim import study

    calls = []

    class Ran(Exception):
        pass

    def run(*args, **kwargs):
        raise Ran

    monkeypatch.setattr(study, "machine_description", lambda: calls.append("machine") or "m")
    monkeypatch.setattr(study, "_run", run)
    with pytest.raises(Ran):
        getattr(study, name)(str(tmp_path), progress=False)
    assert calls == ["machine"]
