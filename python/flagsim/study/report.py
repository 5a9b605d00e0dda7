"""Shared report helpers: machine description and whole-or-nothing file writes."""

from __future__ import annotations

import os
import platform


def write_text(path: str, text: str) -> None:
    """Write a file whole or not at all (temporary file in the same directory, then rename)."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def machine_description() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import flagsim
    from flagsim._revision import revision

    return (
        f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"flagsim {flagsim.__version__} (git {revision()})"
    )
