"""Adversarial configurations for the stress suite (docs/stability.md), seeded numpy, float64.

Each category is one surface plus a batch of refracted paths planted on it (math.md §4
"verify with planted solutions"): a face, a barycentric point `ab` and the receiver `P`
and light `L` for which `P -> M -> L` refracts at `M`. Every kernel can be evaluated at
the planted point, and every solver must return that point or another valid solution.

- `baseline`: nothing; the control (`testing.planted_mesh_paths` on the wavy pool).
- `grazing`: the light 0.5-5 degrees above the tangent plane at `M` (grazing `w_L`).
- `near_tir`: incidence on `P`'s side `1e-7`-`1e-3` rad below the critical angle.
- `sliver`: every other grid column collapsed onto its neighbour: needle triangles
  `1e-1`-`1e-7` of a cell wide (below float32's resolution at the narrow end).
- `flat`: exactly constant normals; the conic degenerates to a line (seed 001 eq. 1-2).
- `nearly_flat`: 1 micrometre waves; normals constant to about 1e-5.
- `vertex_edge`: solutions at vertices and on edges of the wavy pool, a quarter at normal
  incidence (the segment `P -> L` then passes through the vertex).
- `vertex_edge_flat`: the same on the flat pool with the path's plane along grid lines:
  the line conic runs along edges and through vertices.
- `p_near_surface`: `P` `1e-9`-`1e-6` m below the surface.
- `far_light`: `L` `1e5`-`1e6` m away (nearly directional).
- `scale_1e-3`, `scale_1e4`: the baseline scene and paths scaled by `1e-3` and `1e4`.
- `large`: the baseline on a 250,632-triangle pool (too large for the exhaustive reference).
- `irregular`, `irregular_steep`, `irregular_fine`: an irregular mesh (the heightfield
  grid with every interior vertex moved by up to 30% of a cell, `jittered_heightfield`,
  2,048 faces) under gentle waves (amplitude 0.05 m over 4 m), steep ones (0.15 m) and
  a fine one (the same waves over 1.2 m: 15x the triangles per wavelength); the meshes
  where the walk alone loses lanes (docs/solvers.md "Robustness on irregular meshes").
- `multi_solution`: several refraction points per receiver: a lagoon (irregular Delaunay
  mesh) under two steep short waves (amplitude 0.1 m, wavelengths 0.6-0.9 m, slopes
  near 1), receivers 0.5-2.5 m below, past the waves' focal distance (about 0.4 m): the
  light reaching one receiver folds over several sheets of the caustic. The planted
  point is one of the solutions; the certified exhaustive reference counts the others.

Generators reuse `scenes.wavy_pool` / `scenes.flat_pool` (the surfaces) and
`testing.planted_mesh_paths` (the planted faces and points); `plant` only adds what they
do not offer: a prescribed point (vertex, edge), incidence angle, azimuth and distances.
The geometry is the numpy oracle's (`testing.oracle`), as is the rounding bound of
`refract` (`oracle.refraction_rounding_bound`) that the stress suite judges lanes by.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..runtime.precision import precision
from ..surface import scenes
from ..surface.mesh import GridInfo, SurfaceMesh
from . import path_endpoints, planted_mesh_paths
from .oracle import NumpyMesh, barycentric_point, shading_normal, unit

ETA = 1.333
CRITICAL = float(np.arcsin(1 / ETA))  # critical angle on P's (water) side, rad
SMALL_TRIANGLES = 2048  # the pools of every category but `large` (one compile bucket)
LARGE_TRIANGLES = 250_000  # 250,632 faces: fits the 2^18 padding bucket


@dataclasses.dataclass(frozen=True)
class StressCase:
    """One category: a surface (float64 numpy) and `n` paths planted on it.

    Attributes:
        category: name (a key of `CATEGORIES`).
        vertices, faces, normals: the surface, float64 / int32 numpy.
        grid: its `GridInfo` when it is a regular heightfield grid, else None.
        P, L: `(n, 3)` receivers and lights.
        face: `(n,)` face of the planted refraction point.
        ab: `(n, 2)` its barycentric coordinates (on the face's closure).
        eta: index ratio of the planted paths.
    """

    category: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    grid: GridInfo | None
    P: np.ndarray
    L: np.ndarray
    face: np.ndarray
    ab: np.ndarray
    eta: float = ETA

    def mesh(self, dtype="float32") -> SurfaceMesh:
        """The surface as a `SurfaceMesh` of `dtype` (float64 needs x64 on)."""
        return SurfaceMesh.from_arrays(self.vertices, self.faces, self.normals, grid=self.grid,
                                       dtype=dtype)

    def triangles(self):
        """`(V, N)` `(n, 3, 3)` float64 of each lane's planted face."""
        return NumpyMesh(self.vertices, self.faces, self.normals).triangles(self.face)

    @property
    def M(self) -> np.ndarray:
        return barycentric_point(self.triangles()[0], self.ab)

    @property
    def n_faces(self) -> int:
        return len(self.faces)


def plant(V, N, ab, theta, h, d_P, d_L, eta: float = ETA):
    """Receivers and lights of paths refracting at `ab` on triangles `(V, N)`, float64.

    `w_P` leaves `M` into the medium at angle `theta` (rad) from `-n_s`, its tangential
    part along `h` projected onto the tangent plane of `n_s`; `w_L = refract(-w_P, -n_s,
    eta)` (math.md §1), `P = M + d_P w_P`, `L = M + d_L w_L`. Returns `(P, L)`.
    """
    n_s = shading_normal(N, ab)
    tangent = unit(h - np.sum(h * n_s, -1, keepdims=True) * n_s)
    w_P = -np.cos(theta)[:, None] * n_s + np.sin(theta)[:, None] * tangent
    return path_endpoints(barycentric_point(V, ab), n_s, w_P, d_P, d_L, eta)


def _surface(sc) -> tuple:
    m = sc.surface
    return (np.asarray(m.vertices, np.float64), np.asarray(m.faces), np.asarray(m.normals, np.float64),
            m.grid)


def _wavy(n_triangles=SMALL_TRIANGLES, seed=0, amplitude=0.05):
    with precision("float64"):
        return _surface(scenes.wavy_pool(n_triangles, seed=seed, amplitude=amplitude, dtype="float64"))


def _flat(n_triangles=SMALL_TRIANGLES):
    with precision("float64"):
        return _surface(scenes.flat_pool(n_triangles, dtype="float64"))


def _case(name, surface, P, L, face, ab) -> StressCase:
    vertices, faces, normals, grid = surface
    return StressCase(category=name, vertices=vertices, faces=faces, normals=normals, grid=grid,
                      P=P, L=L, face=np.asarray(face, np.int32), ab=ab)


def _planted(name, surface, n, seed, **kwargs) -> StressCase:
    p = planted_mesh_paths(NumpyMesh(*surface[:3]), n, seed, eta=ETA, **kwargs)
    return _case(name, surface, p.P, p.L, p.face, p.ab)


def _replanted(name, surface, n, seed, theta, d_P=None, d_L=None) -> StressCase:
    """Faces and points of `planted_mesh_paths`, with new angles and distances."""
    rng = np.random.default_rng(seed + 1)
    mesh = NumpyMesh(*surface[:3])
    p = planted_mesh_paths(mesh, n, seed, eta=ETA)
    V, N = mesh.triangles(p.face)
    d_P = rng.uniform(0.2, 0.9, n) if d_P is None else d_P
    d_L = rng.uniform(1.0, 4.0, n) if d_L is None else d_L
    P, L = plant(V, N, p.ab, theta, rng.normal(size=(n, 3)), d_P, d_L)
    return _case(name, surface, P, L, p.face, p.ab)


def _theta_for_elevation(elevation):
    """Incidence on P's side whose refracted ray leaves `elevation` rad above the tangent plane."""
    return np.arcsin(np.cos(elevation) / ETA)


def _vertex_edge(name, surface, n, seed, aligned: bool) -> StressCase:
    """Solutions at vertices (half) and on edges (half); a quarter at normal incidence."""
    rng = np.random.default_rng(seed + 1)
    mesh = NumpyMesh(*surface[:3])
    p = planted_mesh_paths(mesh, n, seed, eta=ETA)
    k = rng.integers(0, 3, n)
    t = np.where(np.arange(n) % 2 == 0, 0.0, rng.uniform(0.05, 0.95, n))  # even lanes: a vertex
    a = np.where(k == 0, t, np.where(k == 1, 1 - t, 0.0))  # edge parametrisation of barycentric.py
    b = np.where(k == 0, 0.0, t)
    ab = np.stack([a, b], -1)
    V, N = mesh.triangles(p.face)
    theta = np.where(np.arange(n) % 4 == 1, 0.0, rng.uniform(0.0, np.radians(35), n))
    if aligned:  # tangential direction along x, y or the cell diagonal: the conic runs on edges
        axes = np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 1.0, 0]])
        h = axes[rng.integers(0, 3, n)] * rng.choice([-1.0, 1.0], (n, 1))
    else:
        h = rng.normal(size=(n, 3))
    P, L = plant(V, N, ab, theta, h, rng.uniform(0.2, 0.9, n), rng.uniform(1.0, 4.0, n))
    return _case(name, surface, P, L, p.face, ab)


def _sliver_surface(seed):
    """The wavy pool with every odd grid column moved to `w` of the way from its left
    neighbour (`w = 10^-U(1, 7)` per column): needle triangles, some below float32 resolution."""
    vertices, faces, normals, grid = _wavy(seed=seed)
    rng = np.random.default_rng(seed)
    Vg = vertices.reshape(grid.ny + 1, grid.nx + 1, 3).copy()
    Ng = normals.reshape(grid.ny + 1, grid.nx + 1, 3).copy()
    for i in range(1, grid.nx, 2):
        w = 10.0 ** -rng.uniform(1, 7)
        Vg[:, i] = Vg[:, i - 1] + w * (Vg[:, i] - Vg[:, i - 1])
        Ng[:, i] = unit(Ng[:, i - 1] + w * (Ng[:, i] - Ng[:, i - 1]))
    return Vg.reshape(-1, 3), faces, Ng.reshape(-1, 3), None


def _scaled(case: StressCase, s: float, name: str) -> StressCase:
    grid = case.grid and dataclasses.replace(case.grid, x0=case.grid.x0 * s, y0=case.grid.y0 * s,
                                             dx=case.grid.dx * s, dy=case.grid.dy * s)
    return dataclasses.replace(case, category=name, vertices=case.vertices * s, grid=grid,
                               P=case.P * s, L=case.L * s)


def _irregular(seed, amplitude=0.05, half=2.0):
    from .jittered_wave import jittered_heightfield

    with precision("float64"):
        m = jittered_heightfield(32, seed=seed, half=half, jitter=0.3, amplitude=amplitude)
    return (np.asarray(m.vertices, np.float64), np.asarray(m.faces), np.asarray(m.normals, np.float64), None)


def _steep_lagoon(seed):
    with precision("float64"):
        return _surface(scenes.lagoon(SMALL_TRIANGLES, seed=seed, size=(4.0, 4.0), amplitude=0.1, n_waves=2,
                                      wavelength=(0.6, 0.9), dtype="float64"))


def _make(name: str, n: int, seed: int) -> StressCase:
    rng = np.random.default_rng(seed)
    if name == "baseline":
        return _planted(name, _wavy(seed=seed), n, seed)
    if name == "grazing":
        theta = _theta_for_elevation(np.radians(rng.uniform(0.5, 5.0, n)))
        return _replanted(name, _wavy(seed=seed), n, seed, theta, d_L=rng.uniform(0.3, 1.5, n))
    if name == "near_tir":
        theta = CRITICAL - 10.0 ** rng.uniform(-7, -3, n)
        return _replanted(name, _wavy(seed=seed), n, seed, theta, d_L=rng.uniform(0.3, 1.5, n))
    if name == "sliver":
        return _planted(name, _sliver_surface(seed), n, seed)
    if name == "flat":
        return _planted(name, _flat(), n, seed)
    if name == "nearly_flat":
        return _planted(name, _wavy(seed=seed, amplitude=1e-6), n, seed)
    if name == "vertex_edge":
        return _vertex_edge(name, _wavy(seed=seed), n, seed, aligned=False)
    if name == "vertex_edge_flat":
        return _vertex_edge(name, _flat(), n, seed, aligned=True)
    if name == "p_near_surface":
        theta = rng.uniform(0, np.radians(35), n)
        return _replanted(name, _wavy(seed=seed), n, seed, theta, d_P=10.0 ** rng.uniform(-9, -6, n))
    if name == "far_light":
        theta = rng.uniform(0, np.radians(35), n)
        return _replanted(name, _wavy(seed=seed), n, seed, theta, d_L=10.0 ** rng.uniform(5, 6, n))
    if name in ("scale_1e-3", "scale_1e4"):
        return _scaled(_planted(name, _wavy(seed=seed), n, seed), float(name.split("_")[1]), name)
    if name == "large":
        return _planted(name, _wavy(LARGE_TRIANGLES, seed=seed), n, seed)
    if name == "irregular":
        return _planted(name, _irregular(seed), n, seed)
    if name == "irregular_steep":
        return _planted(name, _irregular(seed, amplitude=0.15), n, seed)
    if name == "irregular_fine":
        return _planted(name, _irregular(seed, half=0.6), n, seed)
    if name == "multi_solution":
        return _planted(name, _steep_lagoon(seed), n, seed, depth=(0.5, 2.5), max_angle_deg=30.0)
    raise ValueError(f"unknown stress category {name!r}; known: {CATEGORIES}")


CATEGORIES = ("baseline", "grazing", "near_tir", "sliver", "flat", "nearly_flat", "vertex_edge",
              "vertex_edge_flat", "p_near_surface", "far_light", "scale_1e-3", "scale_1e4", "large",
              "irregular", "irregular_steep", "irregular_fine", "multi_solution")


def stress_case(category: str, n: int = 256, seed: int = 0) -> StressCase:
    """`n` planted paths of one adversarial `category` (see the module table), seeded."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    return _make(category, n, seed)
