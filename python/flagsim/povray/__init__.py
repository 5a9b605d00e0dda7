"""POV-Ray output: per-frame mesh2 files, the master scene, and a parallel render driver.

    import flagsim, flagsim.povray as pov
    scene = flagsim.Scene.paper()
    sim = flagsim.Simulation(scene)
    pov.write_mesh2(sim, "flag.inc")                       # one frame
    pov.export(sim, "out", seconds=4, fps=25, scene=scene)  # an animation
    result = pov.render("out")                              # render/frame_NNN.png
    pov.make_gif(result.images, "out/flag.gif", fps=25)

Only numpy and the compiled core load with this module; tqdm and imageio load when used.
"""

from .export import ExportConflict, ExportResult, export, frame_steps, read_manifest
from .lock import ExportBusy, ExportLock
from .mesh import format_mesh2, mesh_arrays, vertex_normals, write_mesh2
from .render import (
    FfmpegNotFound,
    FrameJob,
    FrameResult,
    IncompleteExport,
    PovrayNotFound,
    RenderError,
    RenderResult,
    find_povray,
    load_export,
    make_gif,
    make_mp4,
    povray_diagnostics,
    render,
    render_frame,
)
from .scenefiles import TEMPLATE_DIR

__all__ = [
    "ExportBusy",
    "ExportConflict",
    "ExportLock",
    "ExportResult",
    "FfmpegNotFound",
    "FrameJob",
    "FrameResult",
    "IncompleteExport",
    "PovrayNotFound",
    "RenderError",
    "RenderResult",
    "TEMPLATE_DIR",
    "export",
    "find_povray",
    "format_mesh2",
    "frame_steps",
    "load_export",
    "make_gif",
    "make_mp4",
    "mesh_arrays",
    "povray_diagnostics",
    "read_manifest",
    "render",
    "render_frame",
    "vertex_normals",
    "write_mesh2",
]
