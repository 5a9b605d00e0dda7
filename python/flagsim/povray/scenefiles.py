"""The static files of an export: master scene, .ini, texture, and POV-Ray's private config.

Everything POV-Ray reads is written inside the export folder under fixed, plain names
(flag.pov, flag.ini, frames/flag_NNNNN.inc, texture.png, render/frame_NNN.png), and the driver
runs POV-Ray in that folder with relative paths: the folder's own path (spaces, ';', '#', quotes)
never appears in a file or on POV-Ray's command line, so it cannot be read as syntax.
"""

from __future__ import annotations

import math
import os
import shutil
import string
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .. import _core

TEMPLATE_DIR = Path(__file__).resolve().parent / "templates"

#: image file suffix -> POV-Ray image_map type keyword
IMAGE_TYPES = {
    ".png": "png",
    ".jpg": "jpeg",
    ".jpeg": "jpeg",
    ".gif": "gif",
    ".tga": "tga",
    ".ppm": "ppm",
    ".pgm": "pgm",
    ".tif": "tiff",
    ".tiff": "tiff",
    ".exr": "exr",
    ".hdr": "hdr",
}

# The built-in flag: red with an off-centre white cross (u = 0 is the pole side, v = 1 the top);
# its colour is easy to tell from sky, ground and pole, and the cross shows the flag's
# orientation. POV-Ray draws it as a function pigment, the viewer as an image (builtin_flag_image).
FLAG_RED = (0.72, 0.03, 0.05)
FLAG_WHITE = (0.96, 0.96, 0.93)
CROSS_U = (0.36, 0.07)  # the vertical bar: centre and half width, in u
CROSS_V = (0.5, 0.09)  # the horizontal bar: centre and half width, in v


def _rgb(c):
    return f"<{c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}>"


BUILTIN_PIGMENT = f"""pigment {{
      uv_mapping
      function {{ max(select(abs(x - {CROSS_U[0]}) - {CROSS_U[1]}, 1, 0), \
select(abs(y - {CROSS_V[0]}) - {CROSS_V[1]}, 1, 0)) }}
      color_map {{ [0.5 color rgb {_rgb(FLAG_RED)}] [0.5 color rgb {_rgb(FLAG_WHITE)}] }}
    }}"""


def builtin_flag_image(size=256):
    """The built-in flag as an (size, size, 3) float image, row 0 at the top (v = 1)."""
    c = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(c, c[::-1])
    white = (np.abs(u - CROSS_U[0]) < CROSS_U[1]) | (np.abs(v - CROSS_V[0]) < CROSS_V[1])
    return np.where(white[..., None], FLAG_WHITE, FLAG_RED)


FRAME_DIR = "frames"
RENDER_DIR = "render"
SCENE_FILE = "flag.pov"
INI_FILE = "flag.ini"


def frame_file(k):
    """Relative path of frame k's mesh include (what flag.pov includes for FRAME = k)."""
    return f"{FRAME_DIR}/flag_{k:05d}.inc"


def render_file(k, final_frame):
    """Relative path of frame k's image, named as ``povray flag.ini`` names it (POV-Ray pads
    the frame number to the digits of the final frame)."""
    return f"{RENDER_DIR}/frame_{k:0{len(str(final_frame))}d}.png"


def write_text(path, text, *, only_if_changed=True):
    """Write text whole or not at all; with only_if_changed an identical file is left alone
    (so its modification time still says when its content last changed). True if written."""
    path = Path(path)
    if only_if_changed and path.is_file() and path.read_text(encoding="utf-8") == text:
        return False
    _core.write_file_atomic(os.fspath(path), text)
    return True


def write_bytes(path, data, *, only_if_changed=True):
    """write_text for bytes (an image, a file a task returned)."""
    path = Path(path)
    if only_if_changed and path.is_file() and path.read_bytes() == data:
        return False
    _core.write_file_atomic(os.fspath(path), bytes(data))
    return True


def pov_vector(v, *, point=True):
    """POV-Ray vector text for a flagsim vector: z negated (left-handed frame)."""
    x, y, z = (float(c) for c in v)
    if not all(math.isfinite(c) for c in (x, y, z)):
        raise ValueError(f"vector should be finite, got ({x}, {y}, {z})")
    return f"<{x:.6f}, {y:.6f}, {-z:.6f}>"


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


@dataclass
class View:
    """Camera and lights in flagsim's frame (converted when written)."""

    location: np.ndarray
    look_at: np.ndarray
    angle: float  # horizontal field of view, degrees
    sun_direction: np.ndarray
    ground_y: float


def view_direction(facing=None, *, min_elevation=-25.0, max_elevation=40.0):
    """Unit vector from the flag towards the camera: along ``facing`` (the flag's mean normal
    over the run; +z when unknown), turned 17 degrees to the right and 5 down so the picture has
    depth and the flag stands against the sky, its elevation kept in the given range (degrees)."""
    f = np.array([0.0, 0.0, 1.0]) if facing is None else np.asarray(facing, dtype=float)
    if not np.all(np.isfinite(f)) or np.linalg.norm(f) < 1e-12:
        f = np.array([0.0, 0.0, 1.0])
    f = _unit(f)
    if f[2] < 0:  # double-sided: prefer the +z side (hoist on the left for +x wind)
        f = -f
    horizontal = f * [1.0, 0.0, 1.0]
    if np.linalg.norm(horizontal) < 1e-6:  # flag lying flat: look from +z
        horizontal = np.array([0.0, 0.0, 1.0])
    horizontal = _unit(horizontal)
    azimuth = math.atan2(horizontal[0], horizontal[2]) + math.radians(17.0)
    elevation = math.degrees(math.asin(float(np.clip(f[1], -1.0, 1.0)))) - 5.0
    elevation = math.radians(min(max(elevation, min_elevation), max_elevation))
    return np.array(
        [
            math.cos(elevation) * math.sin(azimuth),
            math.sin(elevation),
            math.cos(elevation) * math.cos(azimuth),
        ]
    )


def frame_view(lo, hi, pole=None, *, facing=None, aspect=4 / 3, angle=40.0):
    """A camera in front of the flag (see view_direction), far enough that the box [lo, hi]
    (flagsim frame, m) and the top of the pole fill ~90% of the picture; the sun comes from
    above, behind the camera's left shoulder."""
    lo = np.asarray(lo, dtype=float).copy()
    hi = np.asarray(hi, dtype=float).copy()
    ground_y = lo[1] - 1.0
    poles = [p for p in _as_list(pole) if pole_enabled(p)]
    flag_lo_y, flag_span_y = lo[1], hi[1] - lo[1]
    for i, p in enumerate(poles):
        base = np.asarray(p.base, dtype=float)
        top = base + np.array([0.0, float(p.height), 0.0])
        r = float(p.radius)
        finial = top + np.array([0.0, 3.2 * r, 0.0])
        lo = np.minimum(lo, [top[0] - r, max(base[1], flag_lo_y - 0.2 * flag_span_y), top[2] - r])
        hi = np.maximum(hi, finial + r)
        ground_y = float(base[1]) if i == 0 else min(ground_y, float(base[1]))
    pad = 0.05 * float(np.max(hi - lo))
    lo, hi = lo - pad, hi + pad
    target = 0.5 * (lo + hi)
    d = view_direction(facing)
    right = _unit(np.cross([0.0, 1.0, 0.0], d))
    up = np.cross(d, right)
    tan_h = math.tan(math.radians(angle) / 2)
    tan_v = tan_h / aspect
    dist = 0.0
    for corner in np.array(np.meshgrid(*zip(lo, hi))).T.reshape(-1, 3):
        rel = corner - target
        depth_offset = rel @ d
        dist = max(
            dist, abs(rel @ right) / tan_h + depth_offset, abs(rel @ up) / tan_v + depth_offset
        )
    dist = max(dist, 1e-3)
    sun = _unit(0.55 * d - 0.45 * right + 0.8 * np.array([0.0, 1.0, 0.0]))
    return View(
        location=target + dist * d,
        look_at=target,
        angle=angle,
        sun_direction=sun,
        ground_y=ground_y,
    )


# PoleParams' defaults (csrc/collision/params.h): the pole drawn for a flag pinned to a pole
# ("pole" or "grommets") while the Scene does not expose its own `pole`.
DEFAULT_POLE = SimpleNamespace(enabled=True, radius=0.055, height=2.6, base=(0.0, -2.5, 0.0))


def scene_poles(scene):
    """Every pole to draw, one per flag that has one (scene_pole for each of scene.flags)."""
    specs = getattr(scene, "flags", None) if scene is not None else None
    if not specs or len(specs) == 1:
        pole = scene_pole(scene)
        return [] if pole is None else [pole]
    return [s.pole for s in specs if pole_enabled(s.pole)]


def scene_pole(scene):
    """The pole to draw: scene.pole, else the default pole for a pole-pinned flag, else None.
    A scene of several flags: the list of their poles (scene_poles)."""
    if scene is None:
        return None
    specs = getattr(scene, "flags", None)
    if specs and len(specs) > 1:
        return scene_poles(scene)
    pole = getattr(scene, "pole", None)
    if pole is not None:
        return pole
    flag = getattr(scene, "flag", None)
    if getattr(flag, "pin", None) in ("pole", "grommets"):
        return DEFAULT_POLE
    return None


def pole_enabled(pole):
    return (
        bool(getattr(pole, "enabled", True)) and float(pole.height) > 0 and float(pole.radius) > 0
    )


def _as_list(pole):
    if pole is None:
        return []
    return list(pole) if isinstance(pole, (list, tuple)) else [pole]


def pole_text(pole):
    """Cylinder from the scene's pole (base, height, radius) with a ball finial on top; a list
    of poles (a scene of several flags): one each."""
    poles = [p for p in _as_list(pole) if pole_enabled(p)]
    if not poles:
        return "// (the scene has no pole)\n"
    if len(poles) > 1:
        return "".join(pole_text(p) for p in poles)
    base = np.asarray(pole.base, dtype=float)
    r = float(pole.radius)
    top = base + np.array([0.0, float(pole.height), 0.0])
    collar = top + np.array([0.0, 0.6 * r, 0.0])
    ball = top + np.array([0.0, 1.9 * r, 0.0])
    return f"""union {{
  cylinder {{ {pov_vector(base)}, {pov_vector(top)}, {r:.6f} }}
  cylinder {{ {pov_vector(top)}, {pov_vector(collar)}, {1.25 * r:.6f} }}
  texture {{
    pigment {{ color rgb <0.80, 0.80, 0.82> }}
    finish {{ ambient 0.08 diffuse 0.65 specular 0.6 roughness 0.01 metallic reflection 0.06 }}
  }}
}}
sphere {{
  {pov_vector(ball)}, {1.6 * r:.6f}
  texture {{
    pigment {{ color rgb <0.85, 0.65, 0.20> }}
    finish {{ ambient 0.08 diffuse 0.6 specular 0.8 roughness 0.005 metallic reflection 0.12 }}
  }}
}}
"""


def texture_pigment(texture_name):
    if texture_name is None:
        return BUILTIN_PIGMENT
    kind = IMAGE_TYPES[Path(texture_name).suffix.lower()]
    return f'pigment {{ uv_mapping image_map {{ {kind} "{texture_name}" interpolate 2 }} }}'


def _tga_header(head: bytes) -> bool:
    # TGA has no magic number: a colour map type of 0 or 1 and an image type POV-Ray reads
    return len(head) >= 18 and head[1] in (0, 1) and head[2] in (1, 2, 3, 9, 10, 11)


# What each image type's file starts with (its format's signature).
_SIGNATURES = {
    "png": lambda h: h.startswith(b"\x89PNG\r\n\x1a\n"),
    "jpeg": lambda h: h.startswith(b"\xff\xd8\xff"),
    "gif": lambda h: h[:6] in (b"GIF87a", b"GIF89a"),
    "tga": _tga_header,
    "ppm": lambda h: h[:2] in (b"P3", b"P6"),
    "pgm": lambda h: h[:2] in (b"P2", b"P5"),
    "tiff": lambda h: h[:4] in (b"II*\x00", b"MM\x00*"),
    "exr": lambda h: h.startswith(b"\x76\x2f\x31\x01"),
    "hdr": lambda h: h.startswith((b"#?RADIANCE", b"#?RGBE")),
}


def check_texture(texture):
    """Reject a texture POV-Ray cannot read, before any work is done: an unknown extension, a
    missing file, or a file whose content is not the image type its extension names."""
    if texture is None:
        return None
    texture = Path(texture)
    if texture.suffix.lower() not in IMAGE_TYPES:
        raise ValueError(
            f"texture should be an image file ({', '.join(sorted(IMAGE_TYPES))}), "
            f"got '{texture}'"
        )
    if not texture.is_file():
        raise FileNotFoundError(f"texture image '{texture}' not found")
    kind = IMAGE_TYPES[texture.suffix.lower()]
    with open(texture, "rb") as f:
        head = f.read(32)
    if not _SIGNATURES[kind](head):
        raise ValueError(
            f"texture should be a {kind} image, as its name says, but '{texture}' "
            f"does not start like one (first bytes {head[:8]!r}); POV-Ray could not "
            f"read it"
        )
    return texture


def copy_texture(out_dir, texture):
    """Copy the image into the export as texture.<ext> (POV-Ray's I/O restrictions allow reading
    inside the export folder, and the export stays self-contained). Returns its name or None."""
    texture = check_texture(texture)
    if texture is None:
        return None
    name = "texture" + texture.suffix.lower()
    dest = Path(out_dir) / name
    data = texture.read_bytes()
    if not (dest.is_file() and dest.read_bytes() == data):
        tmp = dest.with_name(f".{name}.{os.getpid()}.tmp")
        try:
            shutil.copyfile(texture, tmp)
            os.replace(tmp, dest)
        finally:
            tmp.unlink(missing_ok=True)
    return name


def fill_template(name, **values):
    text = (TEMPLATE_DIR / name).read_text(encoding="utf-8")
    return string.Template(text).substitute(values)


def solids_text(scene):
    """The air's box obstacles (air.model "grid"), drawn as pale stone blocks (a building behind
    a row of flags); "" when there are none. Spheres and cylinders are not drawn."""
    air = getattr(scene, "air", None)
    if air is None or getattr(air, "model", None) != "grid":
        return ""
    out = []
    for o in getattr(air, "obstacles", []):
        if o.shape != "box":
            continue
        c, h = np.asarray(o.center, dtype=float), np.asarray(o.half_size, dtype=float)
        out.append(
            f"box {{\n  {pov_vector(c - h)}, {pov_vector(c + h)}\n"
            "  texture {\n    pigment { color rgb <0.78, 0.74, 0.66> }\n"
            "    finish { ambient 0.10 diffuse 0.75 }\n  }\n}\n"
        )
    return "".join(out)


def scene_text(view, pole, texture_name, solids=""):
    fill = view.location + np.array([0.0, 0.5, 0.0])
    return fill_template(
        "flag.pov.in",
        camera_location=pov_vector(view.location),
        camera_look_at=pov_vector(view.look_at),
        camera_angle=f"{view.angle:.3f}",
        sun_direction=pov_vector(view.sun_direction),
        fill_position=pov_vector(fill),
        ground_y=f"{view.ground_y:.6f}",
        pole=pole_text(pole),
        solids=solids,
        flag_pigment=texture_pigment(texture_name),
    )


def ini_text(width, height, final_frame, final_clock):
    return fill_template(
        "flag.ini.in",
        width=int(width),
        height=int(height),
        final_frame=int(final_frame),
        final_clock=f"{final_clock:.6f}",
    )


def library_paths(povray_binary=None):
    """POV-Ray's standard include folders next to the installed binary (may be empty)."""
    exe = povray_binary or shutil.which("povray")
    if not exe:
        return []
    share = Path(exe).resolve().parent.parent / "share"
    return sorted(str(p) for p in share.glob("povray-3.*/include") if p.is_dir())


def povray_home_files(povray_binary=None):
    """User configuration POV-Ray reads from $HOME/.povray/3.7 (the driver points HOME at the
    export): without it POV-Ray warns that the user configuration file is missing.
    I/O is restricted to the export folder (read and write) and the standard include folders."""
    libs = [p for p in library_paths(povray_binary) if not set(p) & set(' \t";=')]
    conf = [
        "; flagsim: POV-Ray user configuration for this export (HOME is this folder when",
        "; flagsim renders).",
        "[File I/O Security]",
        "restricted",
        "[Shellout Security]",
        "forbidden",
        "[Permitted Paths]",
    ]
    conf += [f"read* = {p}" for p in libs]
    conf += ["read+write* = %HOME%"]
    ini = [
        "; flagsim: POV-Ray defaults for this export",
        "Display=Off",
        "Pause_When_Done=Off",
        "Verbose=Off",
    ]
    ini += [f'Library_Path="{p}"' for p in libs]
    return {
        ".povray/3.7/povray.conf": "\n".join(conf) + "\n",
        ".povray/3.7/povray.ini": "\n".join(ini) + "\n",
    }


def write_static_files(
    out_dir,
    *,
    view,
    pole,
    texture,
    width,
    height,
    final_frame,
    final_clock,
    povray_binary=None,
    solids="",
):
    """Write flag.pov, flag.ini, the texture copy and POV-Ray's private config (unchanged files
    are left alone). Returns the list of files written."""
    out = Path(out_dir)
    (out / FRAME_DIR).mkdir(parents=True, exist_ok=True)
    (out / RENDER_DIR).mkdir(parents=True, exist_ok=True)
    (out / ".povray" / "3.7").mkdir(parents=True, exist_ok=True)
    texture_name = copy_texture(out, texture)
    files = {
        SCENE_FILE: scene_text(view, pole, texture_name, solids),
        INI_FILE: ini_text(width, height, final_frame, final_clock),
    }
    files.update(povray_home_files(povray_binary))
    return [name for name, text in files.items() if write_text(out / name, text)]
