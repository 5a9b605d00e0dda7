"""What the accuracy parts share (the cloth parts in accuracy.py, the air parts in
accuracy_air.py): integrator method names and the final states kept for the error pass."""

from __future__ import annotations

import io

import numpy as np

import flagsim

from .runner import FILES


def set_method(scene: flagsim.Scene, method: str) -> None:
    """'implicit', 'explicit', 'explicit_adaptive' or 'explicit_subN' (N fixed substeps)."""
    scene.integrator.method = "implicit" if method == "implicit" else "explicit"
    scene.integrator.adaptive = method == "explicit_adaptive"
    scene.integrator.substeps = int(method.split("sub")[1]) if "sub" in method else 1


def state_result(case_id: str, x: np.ndarray) -> dict:
    """A case's final positions as result fields: the file name (``state``), and the .npy bytes
    among the files the study's head writes into its states/ folder (runner.FILES), so the case
    may run on a worker that does not see the head's folders."""
    name = case_id.replace("/", "_") + ".npy"
    buf = io.BytesIO()
    np.save(buf, x)
    return {"state": name, FILES: {name: buf.getvalue()}}
