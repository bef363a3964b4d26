"""Meshes that did not come from the scene generators, as a user would load them: a grid
with its vertices jittered (irregular), and a fan. Shared by tests and experiments."""

from __future__ import annotations

import numpy as np

from ..surface.mesh import SurfaceMesh
from ..surface.scenes import wavy_pool


def jittered_grid(n_triangles: int, jitter: float, *, seed: int = 0, flat: bool = False,
                  dtype=np.float64) -> SurfaceMesh:  # fmt: skip
    """The wavy pool's surface with every interior vertex moved by up to `jitter` cells in x
    and in y (uniform), loaded with `SurfaceMesh.from_arrays` (no `grid`): an irregular mesh
    over the same square. `jitter <= 0.2` keeps every triangle counter-clockwise (two
    vertices approach by at most `0.4 sqrt 2 < 1 / sqrt 2` of the hypotenuse height).
    `flat=True` sets every height to 0. The boundary stays straight."""
    surface = wavy_pool(n_triangles, seed=seed).surface
    g = surface.grid
    V = np.asarray(surface.vertices, np.float64).copy()
    i, j = np.tile(np.arange(g.nx + 1), g.ny + 1), np.repeat(np.arange(g.ny + 1), g.nx + 1)
    inner = (i > 0) & (i < g.nx) & (j > 0) & (j < g.ny)
    rng = np.random.default_rng(seed)
    V[inner, :2] += jitter * np.array([g.dx, g.dy]) * rng.uniform(-1, 1, (int(inner.sum()), 2))
    if flat:
        V[:, 2] = 0
    return SurfaceMesh.from_arrays(V, np.asarray(surface.faces), dtype=dtype)


def fan(n: int = 96, *, dtype=np.float64) -> SurfaceMesh:
    """A unit disc triangulated as a fan around its centre, with a gentle ripple: every
    face touches the centre, so a uniform grid over it would list all of them in one cell."""
    t = 2 * np.pi * np.arange(n) / n
    V = np.concatenate([[[0.0, 0.0, 0.0]], np.stack([np.cos(t), np.sin(t), 0.05 * np.sin(3 * t)], -1)])
    F = np.stack([np.zeros(n, np.int64), 1 + np.arange(n), 1 + (np.arange(n) + 1) % n], -1)
    return SurfaceMesh.from_arrays(V, F, dtype=dtype)
