"""What the accuracy parts share (the cloth parts in accuracy.py, the air parts in
accuracy_air.py): integrator method names and the final states kept for the error pass."""

from __future__ import annotations

import os

import numpy as np

import flagsim

from .report import save_npy


def set_method(scene: flagsim.Scene, method: str) -> None:
    """'implicit', 'explicit', 'explicit_adaptive' or 'explicit_subN' (N fixed substeps)."""
    scene.integrator.method = "implicit" if method == "implicit" else "explicit"
    scene.integrator.adaptive = method == "explicit_adaptive"
    scene.integrator.substeps = int(method.split("sub")[1]) if "sub" in method else 1


def save_state(state_dir: str, case_id: str, x: np.ndarray) -> str:
    """Write a case's final positions under state_dir; returns the file name."""
    name = case_id.replace("/", "_") + ".npy"
    save_npy(os.path.join(state_dir, name), x)
    return name
