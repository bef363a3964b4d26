"""A small heightfield with jittered vertices and 5 cm waves, on which an exhaustive
reference that samples `f` along the arcs loses planted paths (docs/solvers.md "The
certified reference")."""

from __future__ import annotations

import numpy as np


def jittered_heightfield(n: int = 12, *, seed: int = 0, half: float = 2.0, jitter: float = 0.3,
                         amplitude: float = 0.05, normals: str = "computed", dtype="float64"):
    """An `n x n`-cell heightfield over `[-half, half]^2` whose interior vertices are moved
    in xy by up to `jitter` of a cell (uniform, seeded), with heights of three fixed
    cosine waves (wavelengths 0.9, 1.4, 0.7 m) of total amplitude `amplitude` (m).

    `normals="computed"`: the mesh's angle-weighted vertex normals (`SurfaceMesh.from_arrays`
    default); `"analytic"`: the waves' own normals. The grid's connectivity with moved
    vertices is a general mesh (no `GridInfo`). With 300 planted paths
    (`planted_mesh_paths(mesh, 300, seed)`) it holds the cases a sampling reference misses;
    their seeds are in docs/solvers.md, "Measurements behind the code".
    """
    from ..surface.mesh import GridInfo, SurfaceMesh

    if normals not in ("computed", "analytic"):
        raise ValueError(f"normals must be 'computed' or 'analytic', got {normals!r}")
    rng = np.random.default_rng(seed)
    h = 2 * half / n
    x = np.linspace(-half, half, n + 1)
    X, Y = np.meshgrid(x, x, indexing="xy")
    xy = np.stack([X.ravel(), Y.ravel()], -1)
    interior = (np.abs(xy[:, 0]) < half - 1e-9) & (np.abs(xy[:, 1]) < half - 1e-9)
    xy[interior] += rng.uniform(-jitter, jitter, (interior.sum(), 2)) * h
    k = 2 * np.pi / np.array([0.9, 1.4, 0.7])
    d = np.array([[1.0, 0.3], [0.2, 1.0], [-0.7, 0.6]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    A = amplitude * np.array([0.5, 0.3, 0.2])
    theta = k * (xy @ d.T)
    z = np.cos(theta) @ A
    gx, gy = -(np.sin(theta) * A * k) @ d[:, 0], -(np.sin(theta) * A * k) @ d[:, 1]
    N = np.stack([-gx, -gy, np.ones_like(gx)], -1)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    faces = GridInfo(n, n, -half, -half, h, h).faces()
    V = np.concatenate([xy, z[:, None]], -1)
    return SurfaceMesh.from_arrays(V, faces, N if normals == "analytic" else None, dtype=dtype)
