"""Which flagsim produced a report: the git revision, for the study and bench reports."""

from __future__ import annotations

import os
import subprocess


def revision() -> str:
    """Short git revision of the flagsim in use, with "-dirty" for local changes to tracked files.

    Imported from a git checkout (an editable install): the checkout's HEAD now. Otherwise (a
    wheel or a non-editable install): the revision the core module was built from
    (``_core.build_info()["git_revision"]``), followed by " (build)". "unknown" when neither
    is known (built outside a checkout)."""
    live = _checkout_revision(os.path.dirname(os.path.abspath(__file__)))
    if live:
        return live
    from . import _core

    built = dict(_core.build_info()).get("git_revision", "")
    return f"{built} (build)" if built else "unknown"


def _checkout_revision(where: str) -> str:
    """HEAD of the git checkout whose tracked files include `where`/__init__.py (+ "-dirty"), or
    "" if there is none: a package installed into a virtual environment inside a checkout is
    not that checkout's source."""

    def git(*args):
        return subprocess.run(["git", *args], cwd=where, capture_output=True, text=True, timeout=10)

    try:
        if git("ls-files", "--error-unmatch", "__init__.py").returncode != 0:
            return ""
        rev = git("rev-parse", "--short=12", "HEAD")
        if rev.returncode != 0 or not rev.stdout.strip():
            return ""
        dirty = git("status", "--porcelain", "--untracked-files=no").stdout.strip()
        return rev.stdout.strip() + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return ""
