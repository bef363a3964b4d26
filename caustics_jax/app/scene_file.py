"""Scene options of `caustics-jax compare` and `export`, from the command line and from a
small TOML scene description (`--scene-file`, docs/export.md "Your own mesh").

A scene file names the scene and what the command line would otherwise say::

    # pool.toml
    scene = "pool.obj"          # a mesh file (relative to this file) or a named scene
    light = [0.4, -0.3, 3.0]    # a point light (m), or instead:
    # sun = [0.1, 0.05, -1.0]   # a directional light: the way its rays travel
    floor_depth = 1.0           # the receivers' floor, m below the surface's lowest point
    eta = 1.333                 # eta_in / eta_out
    triangles = 8192            # named scenes: tessellation (compare)
    lanes = 256                 # export: lanes of the scene

Every key is optional; a flag given on the command line wins over the file. Unknown keys
and values of the wrong kind are a `ValueError` naming the file and the key.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from ..runtime.arguments import check_eta, check_int, check_real, is_real_scalar
from ..surface.lights import Directional

#: Keys of a scene file and what each holds.
KEYS = {"scene": "a mesh file path or a scene name", "light": "a point [x, y, z]",
        "sun": "a direction [dx, dy, dz] the light travels (a directional light)",
        "floor_depth": "metres below the surface (> 0)", "eta": "eta_in / eta_out (> 0)",
        "triangles": "an integer (named scenes)", "lanes": "an integer (export)"}


def check_light(name: str, value, what: str = "point x y z") -> tuple[float, float, float] | None:
    """`value` as one finite point `(x, y, z)` (None passes); `ValueError` naming `name`."""
    if value is None:
        return None
    ok = isinstance(value, list | tuple) and len(value) == 3 and all(is_real_scalar(x) for x in value)
    point = tuple(float(x) for x in value) if ok else ()
    if not ok or not all(abs(x) < float("inf") for x in point):
        raise ValueError(f"{name} must be one finite {what}, got {value!r}")
    return point  # type: ignore[return-value]


def read_scene_file(path) -> dict:
    """The options of a scene file (module docstring), checked; a `scene` path is made
    relative to the file's folder."""
    path = Path(path).expanduser()
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"scene file {str(path)!r} does not exist") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"scene file {str(path)!r} is not a TOML scene description: {exc}") from None
    unknown = sorted(set(data) - set(KEYS))
    if unknown:
        raise ValueError(f"scene file {str(path)!r}: unknown key(s) {unknown}; known: "
                         + "; ".join(f"{k} ({v})" for k, v in KEYS.items()))
    where = f"scene file {str(path)!r}: "
    out = {}
    if "scene" in data:
        if not isinstance(data["scene"], str) or not data["scene"]:
            raise ValueError(f"{where}scene must be {KEYS['scene']}, got {data['scene']!r}")
        scene = data["scene"]
        local = path.parent / scene
        out["scene"] = str(local) if Path(scene).suffix and not Path(scene).is_absolute() else scene
    if "light" in data:
        out["light"] = check_light(f"{where}light", data["light"])
    if "sun" in data:
        out["sun"] = check_light(f"{where}sun", data["sun"], "direction dx dy dz")
    if "floor_depth" in data:
        out["floor_depth"] = check_real(f"{where}floor_depth", data["floor_depth"], 0, lo_open=True)
    if "eta" in data:
        out["eta"] = check_eta(data["eta"], f"{where}eta")
    for key in ("triangles", "lanes"):
        if key in data:
            out[key] = check_int(f"{where}{key}", data[key], 1)
    return out


def scene_options(args, defaults: dict) -> dict:
    """The scene options of a command: each of `defaults`' keys from its flag when given
    (not None), else from `--scene-file`, else the default."""
    from_file = read_scene_file(args.scene_file) if getattr(args, "scene_file", None) else {}
    out = {}
    for key, default in defaults.items():
        flag = getattr(args, key, None)
        out[key] = flag if flag is not None else from_file.get(key, default)
    out["light"] = check_light("--light", out.get("light"))
    # The sun (`--sun` or `sun = [...]`): a Directional in place of the point light; a flag
    # wins over the file, as for every key.
    point_flag, sun_flag = getattr(args, "light", None), getattr(args, "sun", None)
    if point_flag is not None and sun_flag is not None:
        raise ValueError("--light (a point light) and --sun (a directional light) exclude each other: give one")
    if "light" in from_file and "sun" in from_file:
        raise ValueError(f"scene file {str(args.scene_file)!r}: light and sun exclude each other: give one")
    sun = sun_flag if sun_flag is not None else (from_file.get("sun") if point_flag is None else None)
    if sun is not None:
        out["light"] = Directional(np.asarray(check_light("--sun", sun, "direction dx dy dz")))
    return out
