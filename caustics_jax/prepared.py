"""A surface prepared once for many solves: padded arrays, bounds, static features and the
start-point acceleration structure (DESIGN.md "Host work happens once per scene").

`prepare(mesh)` does the host analysis a solve needs and caches it per mesh object, so
repeated `solve` / `irradiance` calls on the same mesh do no host analysis at all:

- `padded`: the mesh padded to power-of-two face and vertex counts (`lanes.padded_mesh`),
  what the jitted solvers take, so jit compiles once per mesh size class;
- `features`: `features.features(mesh)` (flat closed form, lane compaction);
- `lo`, `hi`, `pad`: the float64 bounding box and a conservative margin, to keep lanes
  whose segment cannot reach the surface out of the start-point search;
- `bvh`: the general start-point path's BVH (`start_points.build_bvh`), built on first
  use for meshes without a regular grid.

`solve` and `irradiance` accept a `PreparedSurface` wherever they accept a `SurfaceMesh`.
The cache holds a weak reference to the mesh: a prepared surface lives as long as its mesh.
A mesh changed with `eqx.tree_at` (animated water) is a new object and is prepared anew.
"""

from __future__ import annotations

import weakref

import numpy as np

from .features import SceneFeatures, features
from .lanes import padded_mesh
from .mesh import SurfaceMesh
from .start_points import FaceBVH, StartPoint, build_bvh, start_points


class _Analysis:
    """What `prepare` computes from a mesh; holds no reference to the mesh object itself,
    so the cache below can drop it when the mesh dies."""

    def __init__(self, mesh: SurfaceMesh):
        self.padded = padded_mesh(mesh)
        self.features: SceneFeatures = features(mesh)
        V = np.asarray(mesh.vertices, np.float64)
        self.lo, self.hi = V.min(0), V.max(0)
        self.pad = 1e-4 * float(np.max(self.hi - self.lo) + np.max(np.abs(V)) + 1)
        self.bvh: FaceBVH | None = None


class PreparedSurface:
    """A `SurfaceMesh` with the host analysis of `prepare` (module docstring).

    Attributes:
        mesh: the surface as given.
        padded: the mesh padded to power-of-two sizes (the solvers' jit argument).
        features: its `SceneFeatures`.
        lo, hi: `(3,)` float64 bounding box of the vertices.
        pad: a margin (m) added to the box so rounding never drops a crossing.
    """

    def __init__(self, mesh: SurfaceMesh, analysis: _Analysis | None = None):
        if not isinstance(mesh, SurfaceMesh):
            raise ValueError(f"mesh must be a caustics_jax.SurfaceMesh, got {type(mesh).__name__}")
        self.mesh = mesh
        self._a = analysis if analysis is not None else _Analysis(mesh)
        self.padded, self.features = self._a.padded, self._a.features
        self.lo, self.hi, self.pad = self._a.lo, self._a.hi, self._a.pad

    @property
    def dtype(self):
        return self.mesh.dtype

    @property
    def bvh(self) -> FaceBVH | None:
        """The general start-point path's BVH (None for a regular grid, which needs none)."""
        if self.mesh.grid is not None:
            return None
        if self._a.bvh is None:
            self._a.bvh = build_bvh(self.mesh)
        return self._a.bvh

    def start_points(self, P, L) -> StartPoint:
        """`start_points.start_points` with this surface's acceleration structure."""
        return start_points(self.mesh, P, L, bvh=self.bvh)

    def may_cross(self, P: np.ndarray, L: np.ndarray) -> np.ndarray:
        """`(N,)` False where the segment's bounding box misses the surface's: those lanes
        cannot cross it (receiver and light both above the water, or both beside it)."""
        lo, hi = self.lo - self.pad, self.hi + self.pad
        return np.all((np.maximum(P, L) >= lo) & (np.minimum(P, L) <= hi), -1)


_CACHE: dict[int, tuple[weakref.ref, _Analysis]] = {}


def prepare(mesh: SurfaceMesh | PreparedSurface) -> PreparedSurface:
    """The `PreparedSurface` of `mesh`, analysed on first use and cached per mesh object."""
    if isinstance(mesh, PreparedSurface):
        return mesh
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"mesh must be a caustics_jax.SurfaceMesh, got {type(mesh).__name__}")
    key = id(mesh)
    hit = _CACHE.get(key)
    if hit is not None and hit[0]() is mesh:
        return PreparedSurface(mesh, hit[1])
    analysis = _Analysis(mesh)
    _CACHE[key] = (weakref.ref(mesh, lambda _, key=key, cache=_CACHE: cache.pop(key, None)), analysis)
    return PreparedSurface(mesh, analysis)
