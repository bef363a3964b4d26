"""The scene registry of the shader reference data, next to the kernel registry (`registry.py`).

A scene is registered once, next to its generator, by decorating the function that builds
its surface and lanes:

    @register_scene("wavy_steep", description="wavy pool, 8 cm Gerstner waves (seed 001 §5)")
    def _wavy_steep(rng, n):
        ...
        return SceneData(vertices, faces, normals, grid, P, L, ...)

`SCENES` holds the scenes in registration order, which is the order of the files and of
the CLI's default. `scene_writer.export_scene` runs the float32 walk and the float64
reference on the data and writes the scene file.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..surface.mesh import GridInfo


@dataclasses.dataclass(frozen=True)
class SceneData:
    """What a scene generator returns: a surface and `n` lanes, float64 numpy.

    Attributes:
        vertices, faces, normals: the surface (`SurfaceMesh.from_arrays` arguments).
        grid: its `GridInfo` when it is a regular heightfield grid, else None.
        P, L: `(n, 3)` receivers (in the medium) and light positions.
        receiver_normal: `(n, 3)` unit receiver normals (irradiance's `cos(theta_P)`).
        intensity: `(n,)` radiant intensity of the light (W/sr).
        sigma_t: `(n,)` extinction coefficient of the medium (1/m).
        case: `(n,)` uint32 `records.CASES` code per lane.
        eta: `eta_in / eta_out`, one per scene (the testbed's solve takes one).
        source: how the surface was made (generator and parameters), for the manifest.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    grid: GridInfo | None
    P: np.ndarray
    L: np.ndarray
    receiver_normal: np.ndarray
    intensity: np.ndarray
    sigma_t: np.ndarray
    case: np.ndarray
    eta: float
    source: str


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """A registered scene: name, one-line description, and `build(rng, n) -> SceneData`."""

    name: str
    description: str
    build: Callable


#: Every registered scene by name, in registration order.
SCENES: dict[str, SceneSpec] = {}


def register_scene(name: str, *, description: str):
    """Decorator registering `build(rng, n) -> SceneData` as scene `name`."""
    if name in SCENES:
        raise ValueError(f"scene {name!r} is registered twice")

    def decorator(build: Callable) -> Callable:
        SCENES[name] = SceneSpec(name, description, build)
        return build

    return decorator
