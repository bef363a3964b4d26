"""The exported scenes (docs/export.md "Scenes"): pools, the lagoon, a jittered mesh, lanes
that cross no surface, and the stress categories of `caustics_jax.testing.stress`.

Surfaces come from the package's generators (`scenes.flat_pool`, `wavy_pool`, `lagoon`,
`stress.stress_case`); the lanes are receivers on the floor under random point lights,
or the planted paths of a stress category. Every surface has about 2048 triangles: one
padding bucket, so the float32 walk and the float64 reference compile once for all of
them.
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.precision import precision
from ..surface import scenes
from ..surface.lights import Directional, light_points, scene_size
from ..testing.stress import stress_case
from .records import CASES
from .scene_registry import SceneData, SceneSpec, register_scene

#: Triangles of every exported surface.
TRIANGLES = 2048
#: eta_in / eta_out of every scene (water).
ETA = 1.333


def _surface(scene):
    """`(vertices, faces, normals, grid)` float64 numpy of a generated `Scene`."""
    m = scene.surface
    return (np.asarray(m.vertices, np.float64), np.asarray(m.faces), np.asarray(m.normals, np.float64),
            m.grid)


def _lights(rng, n):
    """Point lights above the pool: a quarter at the scenes' default light (0.4, -0.3, 3),
    a quarter 100 m away (nearly directional), half uniform over a 5 m x 5 m square
    1.5-5 m up."""
    L = np.concatenate([rng.uniform(-2.5, 2.5, (n, 2)), rng.uniform(1.5, 5.0, (n, 1))], -1)
    kind = np.arange(n) % 4
    L[kind == 0] = (0.4, -0.3, 3.0)
    far = rng.normal(size=(n, 3)) * [0.3, 0.3, 0.0] + [0, 0, 1]
    L[kind == 1] = 100 * far[kind == 1] / np.linalg.norm(far[kind == 1], axis=-1, keepdims=True)
    return L


def _receivers(rng, scene, n):
    """`n` of the scene's floor receivers (jittered grid) and their normals, shuffled."""
    R, Rn = np.asarray(scene.receivers, np.float64), np.asarray(scene.receiver_normals, np.float64)
    idx = rng.permutation(len(R))[:n]
    return R[idx], Rn[idx]


def _floor_lanes(rng, scene, n, source, case=None) -> SceneData:
    P, n_P = _receivers(rng, scene, n)
    return SceneData(*_surface(scene), P=P, L=_lights(rng, n), receiver_normal=n_P,
                     intensity=rng.uniform(0.5, 2.0, n), sigma_t=np.where(np.arange(n) % 3 == 0, 0.2, 0.0),
                     case=np.full(n, CASES["random"], np.uint32) if case is None else case, eta=ETA, source=source)


def scene_name(path) -> str:
    """The name a mesh file's scene gets in manifests and reports: its stem, with characters
    other than letters, digits, `_` and `-` replaced by `_`."""
    import re
    from pathlib import Path

    name = re.sub(r"[^A-Za-z0-9_-]", "_", Path(path).stem)
    if not name:
        raise ValueError(f"scene file {str(path)!r} has no name to export it under")
    return name


def mesh_file_scene(path, *, light=None, floor_depth: float | None = None, eta: float = ETA) -> SceneSpec:
    """A scene of the user's own mesh file (any format trimesh reads), placed as `caustics-jax
    compare --scene PATH` places it (`surface.scenes.scene_around`: the floor `floor_depth`
    below it, default a quarter of its width, and a point light `light` above it, or a
    `Directional`); lanes are
    receivers drawn uniformly on the floor under the surface's xy extent, all under that
    light. Named after the file's stem (`scene_name`). The file is read and checked now, so a
    bad path or mesh is a `ValueError` before any export work."""
    from ..runtime.arguments import check_eta

    eta = check_eta(eta)
    with precision("float64"):
        scene = scenes.scene_around(scenes.load_mesh(path, "float64"), light=light, floor_depth=floor_depth,
                                    name=scene_name(path))
    vertices, faces, normals, grid = _surface(scene)
    z_floor = float(np.asarray(scene.receivers)[0, 2])
    source = scene.lights.source(0)
    lo, hi = vertices[:, :2].min(0), vertices[:, :2].max(0)
    if isinstance(source, Directional):
        light = f"directional light travelling along {np.round(source.direction, 6).tolist()}"
    else:
        light = f"point light at {source.tolist()}"

    def build(rng, n):
        P = np.concatenate([rng.uniform(lo, hi, (n, 2)), np.full((n, 1), z_floor)], -1)
        # A directional light as its points on the lanes' rays at float32's limit distance,
        # with the radiant intensity that gives E_perp there (surface/lights.py, math.md §9):
        # the export's lanes stay point-light lanes, read by the shaders unchanged.
        placed = light_points(source, P, scene_size(vertices, P), np.float32)
        E_or_I = rng.uniform(0.5, 2.0, n)
        intensity = np.where(placed.at_infinity, E_or_I * np.sum((placed.points - P) ** 2, -1), E_or_I)
        return SceneData(vertices, faces, normals, grid, P=P, L=placed.points,
                         receiver_normal=np.broadcast_to([0.0, 0.0, 1.0], (n, 3)).copy(),
                         intensity=intensity, sigma_t=np.where(np.arange(n) % 3 == 0, 0.2, 0.0),
                         case=np.full(n, CASES["random"], np.uint32), eta=eta,
                         source=f"mesh file {pathlib_name(path)} ({len(faces)} triangles), floor at z = "
                                f"{z_floor:.6g}, {light}")

    return SceneSpec(scene.name, f"the mesh file {pathlib_name(path)}", build)


def pathlib_name(path) -> str:
    """The file name of `path` (no directories: manifests do not record the user's paths)."""
    from pathlib import Path

    return Path(path).name


def _side(n):
    return math.ceil(math.sqrt(n)) + 1


def _pool(rng, n, **kwargs):
    with precision("float64"):
        return scenes.wavy_pool(TRIANGLES, n_receivers=_side(n), receiver_jitter=1.0, dtype="float64",
                                seed=int(rng.integers(2**31)), **kwargs)


@register_scene("flat_pool", description="still water: the plane z = 0 as a 2048-triangle grid (constant "
                "normals: every conic is a line, seed 001 eq. 1-2)")
def _flat_pool(rng, n):
    with precision("float64"):
        scene = scenes.flat_pool(TRIANGLES, n_receivers=_side(n), receiver_jitter=1.0, dtype="float64")
    return _floor_lanes(rng, scene, n, scene.name)


@register_scene("wavy_gentle", description="the default pool: 3 cm Gerstner waves on a 2048-triangle grid")
def _wavy_gentle(rng, n):
    scene = _pool(rng, n, amplitude=0.03)
    return _floor_lanes(rng, scene, n, scene.name)


@register_scene("wavy_steep", description="8 cm Gerstner waves on a 2048-triangle grid (the comparison's "
                "steep pool)")
def _wavy_steep(rng, n):
    scene = _pool(rng, n, amplitude=0.08)
    return _floor_lanes(rng, scene, n, scene.name)


@register_scene("lagoon", description="irregular Delaunay triangulation of jittered points, waves, a floor "
                "with relief and its normals")
def _lagoon(rng, n):
    with precision("float64"):
        scene = scenes.lagoon(TRIANGLES, n_receivers=_side(n), dtype="float64", seed=int(rng.integers(2**31)))
    return _floor_lanes(rng, scene, n, scene.name)


@register_scene("wavy_jittered", description="choppy Gerstner waves (choppiness 0.5): grid connectivity, "
                "vertices moved off the grid, so a general mesh")
def _wavy_jittered(rng, n):
    scene = _pool(rng, n, amplitude=0.03, choppiness=0.5)
    return _floor_lanes(rng, scene, n, scene.name)


@register_scene("no_crossing", description="the default pool with three quarters of the lanes crossing no "
                "surface: receiver above the water, segment leaving below the water's edge, receiver "
                "beside the pool")
def _no_crossing(rng, n):
    scene = _pool(rng, n, amplitude=0.03)
    data = _floor_lanes(rng, scene, n, scene.name)
    P, L = data.P.copy(), data.L.copy()
    kind = np.arange(n) % 4
    above = kind == 1  # receiver above the water: the segment stays in the air
    P[above, 2] = rng.uniform(0.2, 1.0, above.sum())
    edge = kind == 2  # towards a light far to the side: leaves the water's extent below z = 0
    side = rng.choice([-1.0, 1.0], edge.sum())
    P[edge, 0] = 1.9 * side
    L[edge] = np.stack([12 * side, P[edge, 1], rng.uniform(0.2, 0.6, edge.sum())], -1)
    beside = kind == 3  # receiver and light beside the pool
    P[beside, 0] = rng.choice([-1.0, 1.0], beside.sum()) * rng.uniform(3.0, 4.0, beside.sum())
    L[beside, :2] = P[beside, :2] + rng.uniform(-0.5, 0.5, (beside.sum(), 2))
    case = np.where(kind == 0, CASES["random"], CASES["adversarial"]).astype(np.uint32)
    return SceneData(data.vertices, data.faces, data.normals, data.grid, P, L, data.receiver_normal,
                     data.intensity, data.sigma_t, case, data.eta, data.source)


def _stress(category: str):
    def build(rng, n):
        c = stress_case(category, n, seed=int(rng.integers(2**16)))
        return SceneData(c.vertices, c.faces, c.normals, c.grid, c.P, c.L,
                         receiver_normal=np.broadcast_to([0.0, 0.0, 1.0], (n, 3)).copy(),
                         intensity=np.ones(n), sigma_t=np.zeros(n), case=np.full(n, CASES["planted"], np.uint32),
                         eta=c.eta, source=f"stress category {category!r} (planted paths, seed 001 §3.4)")

    return build


for _category, _what in (
        ("grazing", "light 0.5-5 degrees above the tangent plane at M"),
        ("near_tir", "incidence on P's side 1e-7 to 1e-3 rad below the critical angle"),
        ("vertex_edge", "solutions at vertices and on edges of the wavy pool, a quarter at normal incidence"),
        ("vertex_edge_flat", "solutions at vertices and on edges of the flat pool, the line conic along edges"),
        ("p_near_surface", "P 1e-9 to 1e-6 m below the surface")):
    register_scene(f"stress_{_category}", description=f"stress category {_category}: {_what} (planted paths)")(
        _stress(_category))
