"""Planted refracted paths: random triangles and paths `P -> M -> L` with a known `M`.

Everything is drawn with numpy from an integer seed, in float64, then cast, so the same
seed gives the same float64 reference and float32 copy (math.md §4 "verify with planted
solutions"). The geometry (eq. 3, the shading normal, GLSL `refract`) is the oracle's.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .oracle import NumpyMesh, barycentric_point, refract, shading_normal, unit


class PlantedPath(NamedTuple):
    """A refracted path `P -> M -> L` through triangle `(V, N)` at barycentric `ab`.

    Attributes:
        V: `(n, 3, 3)` vertex positions (rows V0, V1, V2).
        N: `(n, 3, 3)` unit vertex normals, outward (+z side, toward the light).
        P: `(n, 3)` receiver below the surface (inside the medium).
        L: `(n, 3)` light above the surface.
        ab: `(n, 2)` barycentric coordinates of `M`, strictly inside the triangle.
        M: `(n, 3)` the refraction point.
        eta: the index ratio the path was planted with.
    """

    V: np.ndarray
    N: np.ndarray
    P: np.ndarray
    L: np.ndarray
    ab: np.ndarray
    M: np.ndarray
    eta: float

    def astype(self, dtype) -> PlantedPath:
        cast = lambda x: np.asarray(x, dtype=dtype)  # noqa: E731
        return self._replace(V=cast(self.V), N=cast(self.N), P=cast(self.P), L=cast(self.L),
                             ab=cast(self.ab), M=cast(self.M))


class PlantedMeshPaths(NamedTuple):
    """Refracted paths planted on a mesh: `P -> M -> L` refracts at `M` (face, ab).

    Attributes: `P`, `L`, `M` `(n, 3)`; `face` `(n,)`; `ab` `(n, 2)` (all float64 numpy).
    """

    P: np.ndarray
    L: np.ndarray
    M: np.ndarray
    face: np.ndarray
    ab: np.ndarray


def random_triangles(rng: np.random.Generator, n: int, *, size: float = 1.0,
                     normal_spread: float = 0.3, min_angle_deg: float = 15.0):
    """`n` random triangles near the plane `z = 0` with perturbed, outward (+z) unit normals.

    Triangles are rejection-sampled to have every angle above `min_angle_deg` (no slivers:
    the stress suite makes those on purpose). Returns `(V, N)` in float64.
    """
    V = np.empty((0, 3, 3))
    while len(V) < n:
        cand = rng.uniform(-size, size, (2 * n, 3, 3))
        cand[..., 2] *= 0.15
        e = [cand[:, (k + 1) % 3] - cand[:, k] for k in range(3)]
        ang = []
        for k in range(3):
            u, w = -e[(k + 2) % 3], e[k]
            c = np.sum(u * w, -1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(w, axis=-1))
            ang.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
        ok = np.min(np.stack(ang, -1), -1) > min_angle_deg
        # counter-clockwise seen from +z, so that the geometric normal points up like N
        nz = np.cross(e[0], -e[2])[:, 2]
        V = np.concatenate([V, cand[ok & (nz > 0)]])[:n]
    N = unit(np.array([0.0, 0.0, 1.0]) + normal_spread * rng.normal(size=(n, 3, 3)))
    N[..., 2] = np.abs(N[..., 2])
    return V, unit(N)


def path_endpoints(M, n_s, w_P, d_P, d_L, eta: float):
    """`P = M + d_P w_P` and `L = M + d_L w_L`, `w_L = refract(-w_P, -n_s, eta)` (math.md §4).

    `M`, `n_s`, `w_P` `(n, 3)` float64 (`w_P` unit, into the medium); `d_P`, `d_L` `(n,)`
    or `(n, 1)` distances. Returns `(P, L)`.
    """
    w_L = unit(refract(-w_P, -n_s, eta))
    return M + np.reshape(d_P, (-1, 1)) * w_P, M + np.reshape(d_L, (-1, 1)) * w_L


def _directions_in_cone(rng: np.random.Generator, n_s, max_angle_deg: float):
    """Unit `w_P` within `max_angle_deg` of `-n_s`: uniform on the spherical cap."""
    n = len(n_s)
    cos_t = rng.uniform(np.cos(np.radians(max_angle_deg)), 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    helper = np.where(np.abs(n_s[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    s = unit(np.cross(n_s, helper))
    t = np.cross(n_s, s)
    sin_t = np.sqrt(1 - cos_t**2)[:, None]
    return -cos_t[:, None] * n_s + sin_t * (np.cos(phi)[:, None] * s + np.sin(phi)[:, None] * t)


def planted_paths(seed: int, n: int, *, eta: float = 1.333, max_angle_deg: float = 40.0,
                  depth: tuple[float, float] = (0.2, 2.0), height: tuple[float, float] = (0.5, 5.0),
                  normal_spread: float = 0.3) -> PlantedPath:
    """`n` refracted paths with known solution `M` (float64).

    Pick a triangle, an interior `ab`, the shading normal `n_s` there, and a direction
    `w_P` into the medium within `max_angle_deg` of `-n_s` (below the critical angle for
    water, 48.6 deg); refract `-w_P` to get `w_L` and place `L = M + d_L w_L`.
    """
    rng = np.random.default_rng(seed)
    V, N = random_triangles(rng, n, normal_spread=normal_spread)
    ab = rng.dirichlet([2.0, 2.0, 2.0], n)[:, 1:]
    M, n_s = barycentric_point(V, ab), shading_normal(N, ab)
    w_P = _directions_in_cone(rng, n_s, max_angle_deg)
    P, L = path_endpoints(M, n_s, w_P, rng.uniform(*depth, (n, 1)), rng.uniform(*height, (n, 1)), eta)
    return PlantedPath(V=V, N=N, P=P, L=L, ab=ab, M=M, eta=eta)


def planted_mesh_paths(mesh, n: int, seed: int, *, eta: float = 1.333, max_angle_deg: float = 35.0,
                       depth: tuple[float, float] = (0.2, 0.9),
                       height: tuple[float, float] = (1.0, 4.0), margin: float = 0.15) -> PlantedMeshPaths:
    """`n` paths with a known refraction point on random faces of `mesh` (float64).

    `mesh` is anything `oracle.NumpyMesh.from_mesh` reads. Faces are drawn among those
    whose centroid lies at least `margin` of the mesh's xy extent inside its bounding box
    (so a walk from `M0` does not start at the boundary). `w_P` lies within
    `max_angle_deg` of `-n_s` (below water's critical angle, 48.6 deg).
    """
    rng = np.random.default_rng(seed)
    m = NumpyMesh.from_mesh(mesh)
    cen = m.vertices[m.faces].mean(1)
    lo, hi = m.vertices.min(0), m.vertices.max(0)
    span = hi - lo
    inner = np.all((cen[:, :2] > lo[:2] + margin * span[:2]) & (cen[:, :2] < hi[:2] - margin * span[:2]), -1)
    faces = rng.choice(np.nonzero(inner)[0], n)
    V, N = m.triangles(faces)
    ab = rng.dirichlet([2.0, 2.0, 2.0], n)[:, 1:]
    M, n_s = barycentric_point(V, ab), shading_normal(N, ab)
    w_P = _directions_in_cone(rng, n_s, max_angle_deg)
    P, L = path_endpoints(M, n_s, w_P, rng.uniform(*depth, (n, 1)), rng.uniform(*height, (n, 1)), eta)
    return PlantedMeshPaths(P=P, L=L, M=M, face=faces.astype(np.int32), ab=ab)


def partly_covered_floor(dtype, *, n_triangles: int = 512, n: int = 16, half: float = 3.5):
    """A wavy pool (water to |x|, |y| = 2.1 m) over an `n x n` receiver grid on a floor to
    `half` m, every 4th receiver 0.3 m above the water: many segments P -> L miss the
    surface (`NO_CROSSING`). Returns `(mesh, P, L)` (shared by the features tests and
    benchmark)."""
    import jax.numpy as jnp

    from ..surface import scenes

    scene = scenes.wavy_pool(n_triangles, n_receivers=16, dtype=dtype)
    u = (np.arange(n) + 0.5) / n * 2 * half - half
    X, Y = np.meshgrid(u, u, indexing="xy")
    z = np.where(np.arange(n * n) % 4 == 0, 0.3, -1.0)
    P = jnp.asarray(np.stack([X.ravel(), Y.ravel(), z], -1), dtype)
    return scene.surface, P, scene.lights.endpoint(P)
