"""The polyscope side of the viewer: the structures, the camera, the panel and the keys.

Everything the panel and the keys change goes through a Controller (controls.py); this module
only draws and forwards. It imports polyscope, so flagsim.viewer imports it only when a window
or a screenshot is asked for.
"""

from __future__ import annotations

import math

import numpy as np
import polyscope as ps
import polyscope.imgui as psim

from ..povray import scenefiles
from . import PANEL_WIDTH, ViewerUnavailable
from .controls import FLAPPING_MODES, INTEGRATORS, KEYS, MAX_WIND_SPEED

POLE_COLOUR = (0.80, 0.80, 0.82)
FINIAL_COLOUR = (0.85, 0.65, 0.20)
AIR_SLICE_CELLS = 16  # samples per side of the air slice
AIR_SLICE_GAP = 0.1  # m between the flag and the air slice behind it
AIR_SPEED = "air speed, m/s"
AIR_VELOCITY = "air velocity"
RED = (0.9, 0.2, 0.2, 1.0)
STAGE_BARS = 3  # stages drawn as bars; the rest as one line of text
MAX_FRAME_SECONDS = 0.25  # a longer frame (the window dragged, the machine busy) counts as this


class Window:
    """The viewer's structures in polyscope (polyscope.init must have run) and its panel.

    controller  a Controller
    texture     image file mapped onto the flag (uv), or None for the built-in flag
    """

    def __init__(self, controller, *, texture=None):
        self.ctrl = controller
        self.message = ""  # the last error a control raised, shown in the panel
        self._ui = {}  # slider values while they are dragged
        ps.remove_all_structures()
        x, _ = controller.mesh()
        triangles, uv = controller.topology()  # every flag of the scene, as one mesh
        self.flag = ps.register_surface_mesh(
            "flag",
            x,
            triangles,
            smooth_shade=True,
            back_face_policy="identical",
            material="clay",
        )
        self.flag.add_parameterization_quantity("uv", uv, enabled=False)
        self.flag.add_color_quantity(
            "flag",
            flag_image(texture),
            defined_on="texture",
            param_name="uv",
            image_origin="upper_left",
            enabled=True,
        )
        self.poles = scenefiles.scene_poles(controller.base_scene)  # one per flag that has one
        for i, pole in enumerate(p for p in self.poles if scenefiles.pole_enabled(p)):
            suffix = "" if i == 0 else f"_{i}"
            base = np.asarray(pole.base, dtype=float)
            r = float(pole.radius)
            top = base + [0.0, float(pole.height), 0.0]
            c = ps.register_curve_network(
                "pole" + suffix, np.array([base, top]), "line", color=POLE_COLOUR, material="clay"
            )
            c.set_radius(r, relative=False)
            ball = ps.register_point_cloud(
                "finial" + suffix, (top + [0.0, 1.9 * r, 0.0])[None], color=FINIAL_COLOUR
            )
            ball.set_radius(1.6 * r, relative=False)
        self.air = None

    # --- per frame -----------------------------------------------------------------------
    def update(self):
        """Move the flag (and refresh the air slice) to the controller's current state."""
        x, _ = self.ctrl.mesh()
        self.flag.update_vertex_positions(x)
        if self.ctrl.show_air:
            self._update_air(x)
        elif self.air is not None:
            self.air.set_enabled(False)

    def _update_air(self, x):
        """A vertical slice of the air just behind the flag (an x-y plane AIR_SLICE_GAP behind
        its rearmost vertex, seen from the default camera on the +z side), coloured by speed,
        with arrows: whatever air the flag sees (the analytic wind, or the grid with its fans).
        Opaque, and its quantities made once and then refreshed: in software GL (llvmpipe, 960
        x 540) a see-through slice costs ~300 ms a frame, 576 arrows ~45 ms, and adding a
        quantity again compiles its shaders."""
        sim = self.ctrl.sim
        z = float(x[:, 2].min()) - AIR_SLICE_GAP
        fluid = sim.fluid
        if fluid is not None:  # the grid's extent, half a cell inside its faces
            h = float(fluid.cell_size)
            lo = np.asarray(fluid.origin, dtype=float) + 0.5 * h
            hi = lo + (np.asarray(fluid.resolution, dtype=float) - 1.0) * h
        else:
            pad = max(float(np.ptp(x[:, 0])), float(np.ptp(x[:, 1])), 0.5)
            lo, hi = x.min(axis=0) - pad, x.max(axis=0) + pad
        n = AIR_SLICE_CELLS
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
        points = np.column_stack([gx.ravel(), gy.ravel(), np.full(n * n, z)])
        velocity = sim.air_velocity(points)
        speed = np.linalg.norm(velocity, axis=1)
        if self.air is None or speed.max() > self._air_range:
            i = np.arange(n * n).reshape(n, n)
            quads = np.column_stack(
                [i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()]
            )
            self.air = ps.register_surface_mesh("air", points, quads, material="flat")
            self._air_range = max(1.0, 1.5 * float(speed.max()))
            self.air.add_scalar_quantity(
                AIR_SPEED, speed, enabled=True, cmap="viridis", vminmax=(0.0, self._air_range)
            )
            self.air.add_vector_quantity(
                AIR_VELOCITY, velocity, enabled=True, vectortype="standard", color=(0.2, 0.2, 0.2)
            )
        else:
            self.air.update_vertex_positions(points)
            self.air.get_quantity_buffer(AIR_SPEED, "values").update_data(speed)
            self.air.get_quantity_buffer(AIR_VELOCITY, "values").update_data(velocity)
        self.air.set_enabled(True)

    # --- camera --------------------------------------------------------------------------
    def frame_camera(self, width, height, right_margin=0):
        """Put the camera where the POV-Ray export puts it (scenefiles.frame_view): in front of
        the flag, the flag and the pole's top filling the picture left of `right_margin`
        pixels (the panel's)."""
        x, _ = self.ctrl.mesh()
        facing = _area_normal(x, self.ctrl.topology()[0])
        free = width - right_margin
        view = scenefiles.frame_view(
            x.min(axis=0), x.max(axis=0), self.poles, facing=facing, aspect=free / height
        )
        tan_free = math.tan(math.radians(view.angle) / 2.0)  # half the free part's width
        ps.set_vertical_fov_degrees(math.degrees(2.0 * math.atan(tan_free * height / free)))
        # Slide the camera sideways (direction kept) so that the target, at the picture's centre
        # as framed, lands at the centre of the free part: ndc x = free / width - 1.
        d = view.location - view.look_at
        right = np.cross([0.0, 1.0, 0.0], d)
        right /= np.linalg.norm(right)
        shift = (1.0 - free / width) * np.linalg.norm(d) * tan_free * width / free
        ps.look_at(view.location + shift * right, view.look_at + shift * right)

    # --- panel and keys ------------------------------------------------------------------
    def _do(self, fn, *args, **kwargs):
        """Run a control; a ValueError or DivergenceError becomes the panel's message."""
        import flagsim

        try:
            fn(*args, **kwargs)
            self.message = ""
        except (ValueError, flagsim.DivergenceError) as e:
            self.ctrl.pause()
            self.message = str(e)

    def keys(self):
        if psim.GetIO().WantCaptureKeyboard:
            return
        for key, _, _, names in KEYS:
            if any(psim.IsKeyPressed(getattr(psim, "ImGuiKey_" + n), False) for n in names):
                self._do(self.ctrl.press, key)

    def panel(self):
        ctrl = self.ctrl
        st = ctrl.stats()
        psim.PushItemWidth(170)
        psim.Text(f"{ctrl.base_scene.name}   t = {st.time:.2f} s")
        if psim.Button("pause" if ctrl.playing else "play"):
            ctrl.toggle()
        psim.SameLine()
        if psim.Button("step"):
            self._do(ctrl.step)
        psim.SameLine()
        if psim.Button("reset"):
            self._do(ctrl.reset)
        if ctrl.has_wind:
            self._slider("wind, m/s", "speed", ctrl.wind_speed, 0.0, _speed_max(ctrl))
            self._slider("direction, deg", "direction", ctrl.wind_direction, -180.0, 180.0)
        changed, i = psim.Combo("flapping", FLAPPING_MODES.index(ctrl.flapping), FLAPPING_MODES)
        if changed:
            self._do(ctrl.set_flapping, FLAPPING_MODES[i])
        changed, i = psim.Combo("integrator", INTEGRATORS.index(ctrl.integrator), INTEGRATORS)
        if changed:
            self._do(ctrl.set_integrator, INTEGRATORS[i])
        changed, ctrl.show_air = psim.Checkbox("air slice", ctrl.show_air)
        psim.Separator()
        psim.Text(f"{st.steps_per_second:,.0f} steps/s (stepping only)")
        psim.Text(f"simulated / wall time: {st.realtime_ratio:.2f}  (real time = 1.0)")
        if st.behind:
            psim.TextColored(RED, "behind real time: the steps cannot keep up")
        split = sorted(st.stage_split.items(), key=lambda kv: -kv[1])
        for stage, fraction in split[:STAGE_BARS]:
            psim.ProgressBar(fraction, (170.0, 0.0), f"{100 * fraction:.0f} %")
            psim.SameLine()
            psim.Text(stage)
        if len(split) > STAGE_BARS:
            psim.Text(_wrap(", ".join(f"{k} {100 * f:.0f}%" for k, f in split[STAGE_BARS:])))
        e = st.energy
        psim.Text(f"energy (mJ): kinetic {1e3 * e['kinetic']:.2f}, spring {1e3 * e['spring']:.2f}")
        psim.Text(f"  gravity {1e3 * e['gravity']:.1f}, total {1e3 * e['total']:.1f}")
        if self.message:
            psim.TextColored(RED, _wrap(self.message))
        psim.PopItemWidth()

    def _slider(self, label, key, value, lo, hi):
        """A slider that applies its value when released (a rebuild per dragged pixel would
        stall the window)."""
        shown = self._ui.get(key, value)
        _, shown = psim.SliderFloat(label, shown, lo, hi, "%.1f")
        if psim.IsItemActive():
            self._ui[key] = shown
        elif key in self._ui:
            del self._ui[key]
            if psim.IsItemDeactivatedAfterEdit():
                self._do(self.ctrl.set_wind, **{key: shown})


def flag_image(texture=None):
    """The flag's colours as an (H, W, 3) float image, row 0 at the top: the texture file, or
    the built-in flag."""
    if texture is None:
        return scenefiles.builtin_flag_image()
    import imageio.v3 as iio

    scenefiles.check_texture(texture)
    image = np.asarray(iio.imread(texture))
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    image = image[..., :3]
    scale = float(np.iinfo(image.dtype).max) if image.dtype.kind in "ui" else 1.0
    return image.astype(np.float64) / scale


def _area_normal(x, triangles):
    t = triangles
    return 0.5 * np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]).sum(axis=0)


def _speed_max(ctrl):
    return min(MAX_WIND_SPEED, max(10.0, 2.0 * ctrl.wind_speed))


def _wrap(text, width=48):
    import textwrap

    return "\n".join(textwrap.wrap(text, width))


# --- polyscope's one context per process ---------------------------------------------------
_backend = None


def init(backend):
    """polyscope.init(backend) once per process (polyscope has one context); ViewerUnavailable
    when another backend was initialised before or the backend cannot start."""
    global _backend
    if _backend == backend:
        return
    if _backend is not None:
        raise ViewerUnavailable(
            f"polyscope runs one context per process and this one was started for "
            f"{_backend!r}; start a new process for {backend!r}"
        )
    ps.set_use_prefs_file(False)  # no .polyscope.ini / imgui.ini in the current folder
    ps.set_program_name("flagsim")
    ps.set_verbosity(0)
    ps.set_errors_throw_exceptions(True)
    ps.set_allow_headless_backends(backend == "openGL3_egl")
    try:
        ps.init(backend)
    except RuntimeError as e:
        raise ViewerUnavailable(f"polyscope could not start ({backend}): {e}") from None
    # No ground plane: its shadow pass costs ~50 ms a frame in software GL (llvmpipe, 960 x 540:
    # 22 ms a frame without it, 44 ms with tiles, 80 ms with shadows).
    ps.set_ground_plane_mode("none")
    ps.set_transparency_mode("none")
    _backend = backend


class Offscreen:
    """The viewer drawn off-screen through EGL, one frame at a time (no display needed).

    controller  a Controller; width, height: picture size, pixels
    texture     image file for the flag, or None for the built-in flag
    panel       draw the control panel into the pictures (on the right, PANEL_WIDTH pixels;
                the camera frames the flag in the rest)
    """

    def __init__(self, controller, *, width=960, height=540, texture=None, panel=True):
        init("openGL3_egl")
        self.width, self.height, self.panel = int(width), int(height), bool(panel)
        ps.set_window_size(self.width, self.height)
        ps.set_build_default_gui_panels(False)
        ps.set_right_gui_pane_width(PANEL_WIDTH)
        self.window = Window(controller, texture=texture)
        self.window.frame_camera(
            self.width, self.height, right_margin=PANEL_WIDTH if self.panel else 0
        )
        ps.set_user_callback(self.window.panel if self.panel else None)

    def render(self):
        """Draw the controller's current state (and the panel) once."""
        self.window.update()
        ps.frame_tick()

    def image(self):
        """The last frame drawn, (height, width, 3) uint8 RGB, row 0 at the top."""
        buf = ps.screenshot_to_buffer(transparent_bg=False, include_UI=self.panel)
        return np.ascontiguousarray(buf[..., :3])

    def project(self, points):
        """Pixel coordinates (M, 2) (column, row from the top-left corner) of world points
        (M, 3) through polyscope's current camera."""
        view = np.asarray(ps.get_camera_view_matrix(), dtype=float)
        p = np.column_stack([np.asarray(points, dtype=float), np.ones(len(points))]) @ view.T
        f = 1.0 / math.tan(math.radians(ps.get_vertical_fov_degrees()) / 2.0)
        depth = -p[:, 2]  # the camera looks down its -z axis
        xn = f * (self.height / self.width) * p[:, 0] / depth
        yn = f * p[:, 1] / depth
        return np.column_stack([(xn + 1.0) * self.width / 2.0, (1.0 - yn) * self.height / 2.0])


def show(controller, *, texture=None, width=1280, height=720):
    """Open the live window and run until it is closed."""
    import time

    init("openGL3_glfw")
    ps.set_window_size(int(width), int(height))
    ps.set_build_default_gui_panels(True)
    ps.set_right_gui_pane_width(PANEL_WIDTH)
    window = Window(controller, texture=texture)
    window.frame_camera(int(width), int(height), right_margin=PANEL_WIDTH)
    last = [time.perf_counter()]

    def frame():
        now = time.perf_counter()
        wall, last[0] = min(now - last[0], MAX_FRAME_SECONDS), now
        window.keys()
        window._do(controller.advance, wall)
        window.update()
        window.panel()

    ps.set_user_callback(frame)
    ps.show()
    ps.clear_user_callback()
