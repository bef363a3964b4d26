"""A surface prepared once for many solves: padded arrays, bounds, static features and the
start-point acceleration structure (DESIGN.md "Host work happens once per scene").

`prepare(mesh)` does the host analysis a solve needs and caches it per mesh object, so
repeated `solve` / `irradiance` calls on the same mesh do no host analysis at all:

- `padded`: the mesh padded to power-of-two face and vertex counts (`lanes.padded_mesh`),
  what the jitted solvers take, so jit compiles once per mesh size class;
- `features`: `features.features(mesh)` (flat closed form, lane compaction);
- `lo`, `hi`, `pad`: the float64 bounding box and a conservative margin, to keep lanes
  whose segment cannot reach the surface out of the start-point search;
- `accel`: the start-point acceleration structure (`start_points.build_accel`: the exact
  cells of a regular heightfield grid, given by `mesh.grid` or recognised from the
  arrays by `grid.detect_grid`; else the faces binned over the plane; else a BVH), built
  on first use and shared by `start_points` and `occlusion.segment_blocked`.

`solve` and `irradiance` accept a `PreparedSurface` wherever they accept a `SurfaceMesh`.
The cache holds a weak reference to the mesh: a prepared surface lives as long as its mesh.
A mesh changed with `eqx.tree_at` (animated water) is a new object and is prepared anew.
"""

from __future__ import annotations

import copy
import weakref

import numpy as np

from .features import SceneFeatures, features
from .lanes import padded_mesh
from .mesh import SurfaceMesh
from .start_points import Accel, FaceBVH, StartPoint, build_accel, build_bvh, start_points


class _Analysis:
    """What `prepare` computes from a mesh; holds no reference to the mesh object itself,
    so the cache below can drop it when the mesh dies."""

    def __init__(self, mesh: SurfaceMesh):
        self.padded = padded_mesh(mesh)
        self.features: SceneFeatures = features(mesh)
        V = np.asarray(mesh.vertices, np.float64)
        self.lo, self.hi = V.min(0), V.max(0)
        self.pad = 1e-4 * float(np.max(self.hi - self.lo) + np.max(np.abs(V)) + 1)
        self.accel: Accel | None = None
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
    def accel(self) -> Accel:
        """The start-point acceleration structure (`build_accel`), built on first use."""
        if self._a.accel is None:
            self._a.accel = build_accel(self.mesh)
        return self._a.accel

    @property
    def bvh(self) -> FaceBVH:
        """The general (reference) path's BVH, built on first use (`accel` is faster)."""
        if self._a.bvh is None:
            self._a.bvh = self.accel if isinstance(self.accel, FaceBVH) else build_bvh(self.mesh)
        return self._a.bvh

    def with_accel(self, accel: Accel) -> PreparedSurface:
        """This surface with another start-point structure (e.g. `build_bvh(mesh)`, the
        reference path), for comparisons; the cached analysis is not changed."""
        analysis = copy.copy(self._a)
        analysis.accel = accel
        return PreparedSurface(self.mesh, analysis)

    def start_points(self, P, L) -> StartPoint:
        """`start_points.start_points` with this surface's acceleration structure."""
        return start_points(self.mesh, P, L, accel=self.accel)

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
