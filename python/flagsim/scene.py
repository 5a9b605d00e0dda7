"""Scene construction from built-ins and TOML files, and generic helpers over parameter structs.

A TOML scene mirrors the Scene's sections; every key is optional and unknown keys are errors::

    base = "paper"            # start from a built-in scene (default: the plain Scene())
    name = "my flag"
    dt = 0.005
    gravity = [0.0, -9.81, 0.0]

    [flag]
    rows = 16
    cols = 24

    [air]
    model = "uniform"
    wind = [[0.0, [2.0, 0.0, 0.0]], [2.0, [8.0, 0.0, 1.0]]]   # keyframes (time, velocity)

    [integrator]
    method = "implicit"

Several flags share one scene (its air, gravity, dt and self_collision) as an array of tables;
each entry starts from the scene's own flag, drag, integrator, flapping and pole (from ``base``
and the sections above) and changes what it names (docs/multiflag.md)::

    [[flags]]
    origin = [0.0, 0.0, 0.0]

    [[flags]]
    origin = [0.0, 0.0, 1.5]
    width = 0.6
    pole.base = [0.0, -2.5, 1.5]
"""

from __future__ import annotations

import copy
import os
from typing import Any

from . import _core

try:  # Python 3.11+
    import tomllib as _toml
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as _toml  # type: ignore[no-redef]

Scene = _core.Scene

# Fields that hold lists of parameter structs: (owner type, field) -> item type. Areas register
# theirs here (e.g. air.fans), so TOML arrays of tables map onto them.
LIST_ITEM_TYPES: dict[tuple[type, str], type] = {
    (_core.AirParams, "fans"): _core.FanParams,
    (_core.AirParams, "obstacles"): _core.ObstacleParams,
}

# The section a struct's own setters name in their errors when it stands alone (a FanParams says
# "fan.center"); apply_dict renames it to the item's path ("air.fans[1].center").
OWN_SECTION: dict[type, str] = {
    _core.FanParams: "fan",
    _core.ObstacleParams: "obstacle",
    _core.FlagSpec: "flag",
    _core.DragParams: "drag",
    _core.IntegratorParams: "integrator",
    _core.FlappingParams: "flapping",
    _core.PoleParams: "pole",
}


def fields(obj_or_type: Any) -> list[str]:
    """Public field names of a bound parameter struct, in definition order."""
    cls = obj_or_type if isinstance(obj_or_type, type) else type(obj_or_type)
    return [k for k, v in vars(cls).items() if isinstance(v, property) and not k.startswith("_")]


def _is_struct(value: Any) -> bool:
    return type(value).__module__.startswith("flagsim") and bool(fields(value))


def to_dict(obj: Any) -> dict[str, Any]:
    """Nested plain-Python dict of a Scene or parameter struct (tuples become lists)."""
    out: dict[str, Any] = {}
    for k in fields(obj):
        if k == "flags" and isinstance(obj, Scene) and len(obj.flags) == 1:
            continue  # one flag: the flag, pole, ... sections say it all (as before [[flags]])
        out[k] = _plain(getattr(obj, k))
    return out


def _plain(v: Any) -> Any:
    if _is_struct(v):
        return to_dict(v)
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def apply_dict(obj: Any, data: dict[str, Any], section: str) -> None:
    """Set the fields of `obj` from `data`, recursing into sub-structs.

    Unknown keys raise ValueError naming the key and its section; bad values raise the
    ValueError of the field's own validation (which names section.key).
    """
    known = fields(obj)
    where = f"section [{section}]" if section else "the top level"
    for key, value in data.items():
        name = f"{section}.{key}" if section else key
        if key not in known:
            raise ValueError(f"unknown key '{key}' in {where}; known keys: {', '.join(known)}")
        current = getattr(obj, key)
        if _is_struct(current):
            if not isinstance(value, dict):
                raise ValueError(f"{name} should be a table, got {value!r}")
            apply_dict(current, value, name)
            continue
        item_type = LIST_ITEM_TYPES.get((type(obj), key))
        if item_type is not None:
            if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
                raise ValueError(f"{name} should be an array of tables, got {value!r}")
            items = []
            for i, v in enumerate(value):
                item = item_type()
                apply_dict(item, v, f"{name}[{i}]")
                items.append(item)
            value = items
        try:
            setattr(obj, key, value)
        except (TypeError, ValueError) as e:
            raise ValueError(_renamed(str(e), type(obj), section)) from None


def _flag_entries(scene: Scene, entries: Any) -> list:
    """The [[flags]] array as FlagSpecs, each the scene's flag 0 with the entry's keys applied
    (errors name the entry: ``flags[2].width``, ``flags[2].pole.radius``)."""
    if (
        not isinstance(entries, list)
        or not entries
        or not all(isinstance(e, dict) for e in entries)
    ):
        raise ValueError(f"flags should be a non-empty array of tables, got {entries!r}")
    template = scene.flags[0]
    out = []
    for i, entry in enumerate(entries):
        spec = copy.copy(template)
        apply_dict(spec, entry, f"flags[{i}]")
        out.append(spec)
    return out


def _renamed(message: str, cls: type, section: str) -> str:
    own = OWN_SECTION.get(cls)
    if own and own != section and message.startswith(own + "."):
        return section + message[len(own) :]
    return message


def builtins() -> dict[str, str]:
    """Built-in scenes: {name: one-line description}."""
    return dict(_core.Scene._builtins())


GALLERY = os.path.join(os.path.dirname(__file__), "gallery")


def gallery() -> dict[str, str]:
    """Gallery scenes (TOML files shipped in flagsim/gallery/): {name: the file's first comment
    line}."""
    out = {}
    for entry in sorted(os.listdir(GALLERY)) if os.path.isdir(GALLERY) else []:
        if entry.endswith(".toml"):
            with open(os.path.join(GALLERY, entry), encoding="utf-8") as f:
                first = f.readline().lstrip("#").strip()
            out[entry[: -len(".toml")]] = first
    return out


def gallery_path(name: str) -> str:
    """The TOML file of gallery scene `name`."""
    return os.path.join(GALLERY, name + ".toml")


def named(name: str) -> Scene:
    """The built-in scene `name` (ValueError listing the known names otherwise)."""
    return _core.Scene._named(name)


def from_dict(data: dict[str, Any], source: str = "scene") -> Scene:
    """A Scene from a dict shaped like the TOML file (optional `base` names a built-in)."""
    data = dict(data)
    base = data.pop("base", None)
    if base is not None and not isinstance(base, str):
        raise ValueError(f"base should be a built-in scene name, got {base!r}")
    scene = named(base) if base else Scene()
    flags = data.pop("flags", None)
    try:
        apply_dict(scene, data, "")
        if flags is not None:
            scene.flags = _flag_entries(scene, flags)
        scene.validate()  # the rules that span fields (a file names its error here, not later)
    except ValueError as e:
        raise ValueError(f"{source}: {e}") from None
    return scene


def load(path: str | os.PathLike[str]) -> Scene:
    """Read a TOML scene file. Unknown keys and bad values raise ValueError naming the key."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            data = _toml.load(f)
    except FileNotFoundError:
        raise ValueError(f"scene file not found: {path}") from None
    except _toml.TOMLDecodeError as e:
        raise ValueError(f"{path}: not valid TOML: {e}") from None
    except RecursionError:
        raise ValueError(f"{path}: not valid TOML: arrays or tables nested too deeply") from None
    scene = from_dict(data, source=path)
    if "name" not in data:
        scene.name = os.path.splitext(os.path.basename(path))[0]
    return scene


def resolve(spec: str | os.PathLike[str]) -> Scene:
    """A built-in scene name or a path to a TOML file."""
    s = os.fspath(spec)
    if s in builtins():
        return named(s)
    if s in gallery():
        return load(gallery_path(s))
    if s.endswith(".toml") or os.path.sep in s or os.path.exists(s):
        return load(s)
    return named(s)  # raises, listing the built-in names


def _repr(obj: Any) -> str:
    inner = ", ".join(f"{k}={getattr(obj, k)!r}" for k in fields(obj))
    return f"{type(obj).__name__}({inner})"


def _forwarded(key: str, doc: str | None) -> property:
    def get(spec):
        return getattr(spec._flag, key)

    def set_(spec, value):
        setattr(spec._flag, key, value)

    return property(get, set_, doc=doc)


def _install() -> None:
    """Attach the Python-side helpers to the compiled classes."""
    Scene.load = staticmethod(load)
    Scene.builtins = staticmethod(builtins)
    Scene.named = staticmethod(named)
    Scene.gallery = staticmethod(gallery)
    Scene.from_dict = staticmethod(from_dict)
    Scene.to_dict = to_dict
    Scene.__reduce__ = lambda self: (from_dict, (to_dict(self),))
    for key in fields(_core.FlagParams):  # a [[flags]] entry reads like a [flag] section
        setattr(_core.FlagSpec, key, _forwarded(key, _core.FlagParams.__dict__[key].__doc__))
    for cls in (
        Scene,
        _core.FlagSpec,
        _core.FlagParams,
        _core.AirParams,
        _core.DragParams,
        _core.IntegratorParams,
        _core.FanParams,
        _core.ObstacleParams,
        _core.FlappingParams,
        _core.SelfCollisionParams,
        _core.PoleParams,
        _core.TurbulenceParams,
    ):
        cls.__repr__ = _repr


_install()
