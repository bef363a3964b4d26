"""A surface prepared once for many solves: padded arrays, bounds, static features and the
start-point acceleration structure (DESIGN.md "Skipping what a scene does not need": the
analysis runs once per scene, eagerly, even when first asked for inside a user's jit).

`prepare(mesh)` does the host analysis a solve needs and caches it per mesh object, so
repeated `solve` / `irradiance` calls on the same mesh do no host analysis at all:

- `padded`: the mesh padded to power-of-two face and vertex counts (`prepared.padded_mesh`),
  what the jitted solvers take, so jit compiles once per mesh size class;
- `features`: `features.mesh_features(mesh)`, the flags of `features(mesh)` (flat closed form,
  lane compaction); `prepare` checks the arrays first (`mesh.check_arrays()`);
- `lo`, `hi`, `pad`: the float64 bounding box and a conservative margin, to keep lanes
  whose segment cannot reach the surface out of the start-point search;
- `accel`: the start-point acceleration structure (`start_points.build_accel`: the exact
  cells of a regular heightfield grid, given by `mesh.grid` or recognised from the
  arrays by `grid.detect_grid`; else the faces binned over the plane; else a BVH), built
  on first use and shared by `start_points` and `occlusion.segment_blocked`.

- `origin`, `local`: the point the solvers work about and the surface moved there
  (`frames.local_origin`, `frames.local_mesh`): a mesh far from the coordinate origin is
  solved near it, so float32 keeps the digits its triangles need.

`solve` and `irradiance` accept a `PreparedSurface` wherever they accept a `SurfaceMesh`.
`start_points` here is the package's `caustics_jax.accel.start_points`: the module function of
`caustics_jax.accel.start_points` with the structure kept per mesh (`kept_accel`, which
`transport.surface_hits` uses too, for meshes `cacheable` holds).
The cache holds a weak reference to the mesh: a prepared surface lives as long as its mesh.
A mesh changed with `eqx.tree_at` (animated water) is a new object and is prepared anew.
"""

from __future__ import annotations

import copy
import dataclasses
import weakref

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..runtime.arguments import check_points, warn_user
from ..runtime.lanes import power_of_two_bucket
from ..runtime.precision import check_mesh_dtype
from ..surface.features import SceneFeatures, mesh_features
from ..surface.frames import grid_state, local_mesh, local_origin
from ..surface.lights import Directional, light_points, scene_size
from ..surface.mesh import SurfaceMesh
from .start_points import Accel, FaceBVH, StartPoint, build_accel, build_bvh, check_segments
from .start_points import start_points as start_points_on_mesh  # (this module's `start_points` wraps it)


class _Analysis:
    """What `prepare` computes from a mesh; holds no reference to the mesh object itself,
    so the cache below can drop it when the mesh dies."""

    def __init__(self, mesh: SurfaceMesh):
        self.grid = grid_state(mesh)
        if self.grid == "stale":
            warn_user(f"the mesh's vertices are up to {mesh.grid_deviation():.3g} m off its regular grid "
                      f"{mesh.grid}: its xy changed after the grid was built (eqx.tree_at on vertices? only "
                      "heights may change). The start points bin the faces instead of trusting the grid; "
                      "rebuild it with SurfaceMesh.from_arrays or from_heightfield, or move it with "
                      "mesh.translated(offset)")
        self.padded = padded_mesh(mesh)
        self.features: SceneFeatures = mesh_features(mesh)
        V = np.asarray(mesh.vertices, np.float64)
        self.lo, self.hi = V.min(0), V.max(0)
        self.pad = 1e-4 * float(np.max(self.hi - self.lo) + np.max(np.abs(V)) + 1)
        self.accel: Accel | None = None
        self.bvh: FaceBVH | None = None
        self.origin = local_origin(V, mesh.dtype)
        self.local: PreparedSurface | None = None



def padded_mesh(mesh: SurfaceMesh) -> SurfaceMesh:
    """The mesh padded to power-of-two face and vertex counts, so jit compiles once per bucket.

    The static `grid` layout is dropped (the solvers never read it; only start points do,
    and as a static field it would make every pool size its own compile). Padding faces
    are `(0, 0, 0)` with no neighbours and are never referenced by a real face's
    adjacency, so no walk can enter them; padding vertices are zeros.
    """
    F, V = mesh.faces.shape[0], mesh.vertices.shape[0]
    Fb, Vb = power_of_two_bucket(F), power_of_two_bucket(V)
    mesh = dataclasses.replace(mesh, grid=None)
    if (F, V) == (Fb, Vb):
        return mesh

    def pad(x, n, value):
        return jnp.concatenate([x, jnp.full((n - x.shape[0],) + x.shape[1:], value, x.dtype)])

    return eqx.tree_at(
        lambda m: (m.vertices, m.normals, m.faces, m.face_normals, m.neighbors, m.neighbor_edge),
        mesh,
        (pad(mesh.vertices, Vb, 0), pad(mesh.normals, Vb, 0), pad(mesh.faces, Fb, 0),
         pad(mesh.face_normals, Fb, 0), pad(mesh.neighbors, Fb, -1), pad(mesh.neighbor_edge, Fb, -1)),
    )


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
    def origin(self) -> np.ndarray:
        """`(3,)` float64 `local_origin` of the mesh (zero near the origin)."""
        return self._a.origin

    @property
    def local(self) -> PreparedSurface:
        """The surface the solvers run on, built on first use: this one moved by `-origin`,
        without a grid whose exact cells no longer fit its vertices there (`grid_state`:
        the far grid's rounding is 1.5e-5 m at 300 m in float32, many ulps near the
        origin); itself for a mesh near the origin with an exact grid or none. `solve`,
        `irradiance` and the rest run here on `P - origin`, `L - origin` and move the
        points they return back. `prepare(prep.local.mesh)` is `prep.local`."""
        if not np.any(self._a.origin) and self._a.grid in ("none", "exact"):
            return self
        if self._a.local is None:
            with jax.ensure_compile_time_eval():  # (see `_cached`)
                self._a.local = _cached(local_mesh(self.mesh, self._a.origin))
        return self._a.local

    def to_local(self, X) -> np.ndarray:
        """Points `X` (`(..., 3)`) in `local`'s frame, float64: `X - origin`."""
        return np.asarray(X, np.float64) - self._a.origin

    @property
    def accel(self) -> Accel:
        """The start-point acceleration structure (`build_accel`: the grid's cells only
        where they fit the vertices, `frames.grid_state`), built on first use."""
        if self._a.accel is None:
            with jax.ensure_compile_time_eval():  # (see `_cached`)
                self._a.accel = build_accel(self.mesh)
        return self._a.accel

    @property
    def bvh(self) -> FaceBVH:
        """The general (reference) path's BVH, built on first use (`accel` is faster)."""
        if self._a.bvh is None:
            accel = self._a.accel  # (not built for this: a binned or grid structure is no BVH)
            with jax.ensure_compile_time_eval():  # (see `_cached`)
                self._a.bvh = accel if isinstance(accel, FaceBVH) else build_bvh(self.mesh)
        return self._a.bvh

    def with_accel(self, accel: Accel) -> PreparedSurface:
        """This surface with another start-point structure (e.g. `build_bvh(mesh)`, the
        reference path), for comparisons; the cached analysis is not changed. Only where
        `local` is this surface (near the origin, with an exact grid or none): elsewhere the
        solvers run on `local`, which builds its own structure."""
        if self.local is not self:
            raise ValueError("with_accel needs a surface the solvers run on as it is (`local` is itself); this "
                             f"one is solved about {self._a.origin.tolist()} or without its grid: use "
                             "prepare(mesh).local.with_accel(...)")
        analysis = copy.copy(self._a)
        analysis.accel = accel
        return PreparedSurface(self.mesh, analysis)

    def start_points(self, P, L) -> StartPoint:
        """`start_points.start_points` with this surface's acceleration structure, run on
        `local` (`P`, `L` moved by `-origin` in their dtype, exactly for points near the
        mesh); faces and barycentrics are the same in both frames."""
        local = self.local
        if local is not self:  # checked as start_points checks them, then moved
            P, L = check_segments(self.mesh, P, L)
            shift = jnp.asarray(self._a.origin, self.dtype)
            return local.start_points(P - shift, L - shift)
        return start_points_on_mesh(self.mesh, P, L, accel=self.accel)

    def may_cross(self, P: np.ndarray, L: np.ndarray) -> np.ndarray:
        """`(N,)` False where the segment's bounding box misses the surface's: those lanes
        cannot cross it (receiver and light both above the water, or both beside it)."""
        lo, hi = self.lo - self.pad, self.hi + self.pad
        return np.all((np.maximum(P, L) >= lo) & (np.minimum(P, L) <= hi), -1)


_CACHE: dict[int, tuple[weakref.ref, _Analysis]] = {}


def prepare(mesh: SurfaceMesh | PreparedSurface) -> PreparedSurface:
    """The `PreparedSurface` of `mesh`, analysed on first use and cached per mesh object (a
    mesh holding numpy arrays, which can change in place, is analysed on every call:
    `jax.device_put(mesh)` once to have it cached)."""
    if isinstance(mesh, PreparedSurface):
        check_mesh_dtype(mesh.dtype)
        return mesh
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"mesh must be a caustics_jax.SurfaceMesh, got {type(mesh).__name__}")
    hit = _CACHE.get(id(mesh))
    if hit is not None and hit[0]() is mesh:
        check_mesh_dtype(mesh.dtype)  # (x64 may have been switched off since)
        return PreparedSurface(mesh, hit[1])
    mesh.check_arrays()  # a mesh edited after construction (eqx.tree_at skips the constructors' checks)
    check_mesh_dtype(mesh.dtype)
    if not cacheable(mesh):
        # numpy arrays (jax.device_get(mesh), eqx.tree_at with one) can change in place: a
        # cached analysis would go stale (a pool moved in place had found no start point), so
        # such a mesh is copied to JAX arrays and analysed on every call, never cached.
        with jax.ensure_compile_time_eval():
            copied: SurfaceMesh = jax.tree.map(jnp.asarray, mesh)
            return PreparedSurface(copied, _Analysis(copied))
    return _cached(mesh)


def cacheable(mesh: SurfaceMesh) -> bool:
    """Whether `prepare` keeps `mesh`'s analysis: its arrays are concrete JAX arrays
    (immutable), not numpy arrays, which can change in place, nor traced ones."""
    return not any(isinstance(x, np.ndarray | jax.core.Tracer) for x in jax.tree.leaves(mesh))


def kept_accel(mesh: SurfaceMesh) -> Accel | None:
    """`prepare(mesh).accel` (built once per mesh object and kept) for a concrete mesh
    holding JAX arrays; None for a traced mesh or one holding numpy arrays, for which the
    caller builds a structure per call (`start_points.first_crossing` does)."""
    return prepare(mesh).accel if cacheable(mesh) else None


def start_points(mesh: SurfaceMesh | PreparedSurface, P, L, *, method: str = "auto", bvh: FaceBVH | None = None,
                 accel: Accel | None = None) -> StartPoint:  # fmt: skip
    """`caustics_jax.accel.start_points`: `start_points.start_points` (same arguments, checks and
    results; its docstring) with the acceleration structure `prepare(mesh)` keeps per mesh
    object, so repeated calls on one mesh build nothing on the host.

    With `method="auto"` and neither `accel` nor `bvh`, a mesh holding JAX arrays (or a
    `PreparedSurface`) takes `prepare(mesh).start_points` (run about `prepare(mesh).origin`,
    as `solve` runs). Otherwise, and for a mesh holding numpy arrays or traced ones, the
    structure is built for this call, as `start_points.start_points` builds it. A kept
    structure takes the host work (binning, checking grid cells against the vertices,
    copying them to the device) out of every call after the first; what a call still
    pays is the traversal on the traced heights (`face_cells.first_hit_cells`)
    (docs/mesh.md, "Measurements behind the code").

    What the first call on a mesh does is `prepare(mesh)`'s (kept as long as the mesh
    lives): the padded copy, the features, a local copy for a mesh far from the origin;
    it checks the arrays (`mesh.check_arrays()`: NaN vertices are a `ValueError`) and
    warns once about a grid its vertices left. Inside a user's `jit` the analysis is still
    computed eagerly (`jax.ensure_compile_time_eval`).

    `L` may be a `Directional` (the sun): its point on each receiver's ray toward the light,
    as `solve` places it (`surface.lights.light_points`, math.md §9)."""
    if isinstance(L, Directional):
        V = mesh.mesh.vertices if isinstance(mesh, PreparedSurface) else mesh.vertices
        P_np = check_points("P", P, mesh.dtype).reshape(-1, 3)
        L = jnp.asarray(light_points(L, P_np, scene_size(np.asarray(V), P_np), mesh.dtype).points, mesh.dtype)
        P = jnp.asarray(P_np, mesh.dtype)
    if isinstance(mesh, PreparedSurface):
        if method == "auto" and bvh is None and accel is None:
            return mesh.start_points(P, L)
        mesh = mesh.mesh
    elif method == "auto" and bvh is None and accel is None and isinstance(mesh, SurfaceMesh) and cacheable(mesh):
        return prepare(mesh).start_points(P, L)
    return start_points_on_mesh(mesh, P, L, method=method, bvh=bvh, accel=accel)


def _cached(mesh: SurfaceMesh) -> PreparedSurface:
    """`mesh` analysed and entered in the cache (a `local` mesh too, so that `prepare` of
    it, e.g. by the visibility test, finds the same analysis)."""
    # Computed eagerly even when the first use is inside a user's `jit` (`start_points` of a
    # mesh closed over): traced arrays kept here would leak into every later call.
    with jax.ensure_compile_time_eval():
        key, analysis = id(mesh), _Analysis(mesh)
    _CACHE[key] = (weakref.ref(mesh, lambda _, key=key, cache=_CACHE: cache.pop(key, None)), analysis)
    return PreparedSurface(mesh, analysis)
