"""SurfaceMesh: the refractive surface the solvers walk on, its adjacency and edge crossing.

A triangle mesh with per-vertex unit normals oriented outward (toward the light, math.md
§1), geometric face normals, and an adjacency buffer: `neighbors[f, k]` is the face across
edge `k` of face `f` (edge `k` joins vertices `k` and `k + 1 mod 3`, as in
`barycentric.py`), `-1` on a boundary, and `neighbor_edge[f, k]` is which edge of that
neighbour it is, so a walk crosses an edge in O(1) (`cross_edge`).

Everything that can fail (NaN coordinates, bad indices, degenerate faces, non-manifold
edges, inconsistent winding, zero normals) is checked in numpy by `from_arrays`, which
raises a `ValueError` naming the offending faces or vertices before any jitted work.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..math.barycentric import edge_barycentric, edge_param_from_vertex_order
from ..runtime.arguments import check_choice, check_real, real_array, warn_user
from ..runtime.kernel_contract import float_inputs
from ..runtime.precision import check_float_dtype, check_mesh_dtype, default_float_dtype

_MAX_NAMED = 10  # how many offending indices an error message lists


@dataclasses.dataclass(frozen=True)
class GridInfo:
    """Static layout of a regular heightfield grid (hashable: usable as a static field).

    The surface is `z = h(x, y)` sampled at vertex `(i, j)` = `(x0 + i dx, y0 + j dy)`,
    `i in [0, nx]`, `j in [0, ny]`, vertex index `j (nx + 1) + i`. Cell `(i, j)`
    (`i < nx`, `j < ny`) holds faces `2 (j nx + i)` ("lower", vertices
    `v00, v10, v11`) and `2 (j nx + i) + 1` ("upper", vertices `v00, v11, v01`), both
    counter-clockwise seen from +z, split along the diagonal `v00 -> v11`.
    Only the xy layout is static: heights live in `SurfaceMesh.vertices` and may change
    (animated water, `eqx.tree_at`) without recompiling anything keyed on the layout.
    `dx`, `dy` may be negative (the start-point cells are then walked in reverse,
    `grid.grid_layout`); with exactly one of them negative the faces are clockwise seen
    from +z, so their normals point down.
    """

    nx: int
    ny: int
    x0: float
    y0: float
    dx: float
    dy: float

    def vertex_xy(self) -> np.ndarray:
        """`(V, 2)` float64 xy positions of the grid vertices, in vertex order."""
        x = self.x0 + self.dx * np.arange(self.nx + 1)
        y = self.y0 + self.dy * np.arange(self.ny + 1)
        X, Y = np.meshgrid(x, y, indexing="xy")
        return np.stack([X.ravel(), Y.ravel()], axis=-1)

    def faces(self) -> np.ndarray:
        """`(2 nx ny, 3)` int32 faces in the layout above."""
        i, j = np.meshgrid(np.arange(self.nx), np.arange(self.ny), indexing="xy")
        v00 = (j * (self.nx + 1) + i).ravel()
        v10, v01 = v00 + 1, v00 + self.nx + 1
        v11 = v01 + 1
        lower = np.stack([v00, v10, v11], axis=-1)
        upper = np.stack([v00, v11, v01], axis=-1)
        return np.stack([lower, upper], axis=1).reshape(-1, 3).astype(np.int32)

    def cell_faces(self, i, j):
        """Indices of the (lower, upper) faces of cell `(i, j)` (works on jax or numpy ints)."""
        f = 2 * (j * self.nx + i)
        return f, f + 1


class SurfaceMesh(eqx.Module):
    """Triangle mesh with interpolated normals and O(1) adjacency; a pytree usable in `jit`.

    Attributes:
        vertices: `(V, 3)` positions.
        faces: `(F, 3)` int32 vertex indices, counter-clockwise seen from outside.
        normals: `(V, 3)` unit vertex normals, outward (toward the light).
        face_normals: `(F, 3)` unit geometric normals `(V1 - V0) x (V2 - V0) / |.|`.
        neighbors: `(F, 3)` int32, face across edge `k` (vertices `k`, `k+1 mod 3`), -1 on
            a boundary.
        neighbor_edge: `(F, 3)` int32, index of that shared edge within the neighbour, -1
            on a boundary.
        grid: static `GridInfo` when the surface is a regular heightfield grid, else None.
    """

    vertices: Float[Array, "V 3"]
    faces: Int[Array, "F 3"]
    normals: Float[Array, "V 3"]
    face_normals: Float[Array, "F 3"]
    neighbors: Int[Array, "F 3"]
    neighbor_edge: Int[Array, "F 3"]
    grid: GridInfo | None = eqx.field(static=True, default=None)

    @classmethod
    def from_arrays(
        cls,
        vertices,
        faces,
        normals=None,
        *,
        normal_weighting: str = "angle",
        grid: GridInfo | None = None,
        dtype=None,
    ) -> SurfaceMesh:
        """Validate, build adjacency and normals, and return a mesh (numpy work, no jit).

        `normals=None` computes vertex normals from the faces: `normal_weighting="angle"`
        (default; each incident face's unit normal weighted by the face's corner angle at
        the vertex, Thürmer & Wüthrich 1998, independent of how a region is tessellated) or
        `"area"` (weighted by face area, i.e. the sum of unnormalised cross products).
        Given normals are normalised. The winding defines "outward": a given normal that
        points against every incident face is rejected. `dtype` defaults to the input's
        float dtype (float64 only when x64 is on, else float32). `grid`, when given, is
        checked against the vertices and faces.
        """
        check_choice("normal_weighting", normal_weighting, ("angle", "area"))
        if grid is not None and not isinstance(grid, GridInfo):
            raise ValueError(f"grid must be None or a caustics_jax.surface.mesh.GridInfo, got {type(grid).__name__}")
        V64, F = _validate_geometry(vertices, faces)
        dtype = default_float_dtype(vertices, dtype)
        _check_fits(V64, dtype)
        neighbors, neighbor_edge = _adjacency(F)
        face_n = np.cross(V64[F[:, 1]] - V64[F[:, 0]], V64[F[:, 2]] - V64[F[:, 0]])
        face_n /= np.linalg.norm(face_n, axis=-1, keepdims=True)
        if normals is None:
            N = _vertex_normals(V64, F, normal_weighting)
            _check_normals(N, F, face_n, what="computed")
        else:
            N = real_array("normals", normals)
            if N.shape != V64.shape:
                raise ValueError(
                    f"normals must have shape {V64.shape} (one per vertex), got {N.shape}"
                )
            _check_normals(N, F, face_n, what="given")
        N = N / np.linalg.norm(N, axis=-1, keepdims=True)
        if grid is not None:
            _check_grid(grid, V64, F)
        _warn_if_inward(V64, F, neighbors)
        return cls(
            vertices=jnp.asarray(V64, dtype=dtype),
            faces=jnp.asarray(F, dtype=jnp.int32),
            normals=jnp.asarray(N, dtype=dtype),
            face_normals=jnp.asarray(face_n, dtype=dtype),
            neighbors=jnp.asarray(neighbors, dtype=jnp.int32),
            neighbor_edge=jnp.asarray(neighbor_edge, dtype=jnp.int32),
            grid=grid,
        )

    @classmethod
    def from_trimesh(cls, mesh, normals=None, **kwargs) -> SurfaceMesh:
        """Mesh from a `trimesh.Trimesh` (so OBJ/PLY/STL/GLB load through `trimesh.load`).

        A `trimesh.Scene` (GLB, multi-object OBJ) is concatenated into one mesh. Vertex
        normals are recomputed (`normal_weighting`, default angle) unless `normals` is
        given: trimesh invents normals for files that have none, and merges or splits
        vertices on load, so its own normals are not trusted.
        """
        import trimesh

        if not isinstance(mesh, trimesh.Trimesh | trimesh.Scene):
            raise ValueError(f"mesh must be a trimesh.Trimesh or trimesh.Scene (e.g. trimesh.load(path)), "
                             f"got {type(mesh).__name__}")
        if isinstance(mesh, trimesh.Scene):
            if not mesh.geometry:
                raise ValueError("mesh is a trimesh.Scene without geometry")
            mesh = (
                mesh.to_geometry() if hasattr(mesh, "to_geometry") else mesh.dump(concatenate=True)
            )
        return cls.from_arrays(np.asarray(mesh.vertices), np.asarray(mesh.faces), normals, **kwargs)

    @classmethod
    def from_heightfield(
        cls,
        heights,
        *,
        x0: float,
        y0: float,
        dx: float,
        dy: float,
        normals=None,
        dtype=None,
        **kwargs,
    ) -> SurfaceMesh:
        """Regular grid mesh of `z = heights[j, i]` at `(x0 + i dx, y0 + j dy)` (`GridInfo` layout).

        `heights` has shape `(ny + 1, nx + 1)`; `normals`, if given, `(ny + 1, nx + 1, 3)`.
        """
        H = real_array("heights", heights)
        x0, y0 = check_real("x0", x0), check_real("y0", y0)
        for name, step in (("dx", dx), ("dy", dy)):
            if check_real(name, step) == 0:
                raise ValueError(f"{name} must be a finite non-zero real number, got {step!r}")
        if H.ndim != 2 or min(H.shape) < 2:
            raise ValueError(
                f"heights must have shape (ny + 1, nx + 1) with nx, ny >= 1, got {H.shape}"
            )
        if not np.all(np.isfinite(H)):
            bad = np.flatnonzero(~np.isfinite(H.ravel()))
            raise ValueError(f"heights contain NaN or Inf at vertices {_name(bad)}")
        grid = GridInfo(
            nx=H.shape[1] - 1,
            ny=H.shape[0] - 1,
            x0=float(x0),
            y0=float(y0),
            dx=float(dx),
            dy=float(dy),
        )
        out_dtype = default_float_dtype(heights, dtype)
        _check_fits(H.reshape(-1, 1), out_dtype, "heights")
        _check_fits(grid.vertex_xy(), out_dtype, "grid positions x0 + i dx, y0 + j dy")
        V = np.concatenate([grid.vertex_xy(), H.reshape(-1, 1)], axis=-1)
        if normals is not None:
            # Exactly the heights' layout: a reshape alone would take a transposed
            # (nx + 1, ny + 1, 3) array, or a flat one, and scramble the normals silently.
            normals = real_array("normals", normals)
            if normals.shape != H.shape + (3,):
                raise ValueError(f"normals must have shape {H.shape + (3,)} (heights' (ny + 1, nx + 1) followed "
                                 f"by 3, normals[j, i] at vertex (i, j)), got {normals.shape}")
            normals = normals.reshape(-1, 3)
        return cls.from_arrays(
            V, grid.faces(), normals, grid=grid, dtype=default_float_dtype(heights, dtype), **kwargs
        )

    @property
    def dtype(self):
        return self.vertices.dtype

    def check_arrays(self) -> SurfaceMesh:
        """`self` when its arrays are still what the constructors built, else a `ValueError`
        naming what is wrong: a mesh edited after construction (`eqx.tree_at`, the way to
        animate heights) is not validated again, and a NaN height or an out-of-range index
        had surfaced as "P has NaN" or an `IndexError` deep inside. O(V + F) numpy checks:
        concrete arrays (JAX or numpy), shapes, one float dtype, finite vertices and
        normals, indices in range. `prepare` (so `solve`, `irradiance`, ...) calls it once
        per mesh object before its analysis, `features` on every call."""
        fields = {f: getattr(self, f) for f in ("vertices", "faces", "normals", "face_normals", "neighbors",
                                                "neighbor_edge")}
        for name, x in fields.items():
            if not isinstance(x, jax.Array | np.ndarray) or isinstance(x, jax.core.Tracer):
                raise ValueError(f"mesh.{name} must be a concrete array (eqx.tree_at(..., mesh, jnp.asarray(new)) "
                                 f"edits a mesh), got {type(x).__name__}")
        n_v, n_f = fields["vertices"].shape[0], fields["faces"].shape[0]
        shapes = {"vertices": (n_v, 3), "normals": (n_v, 3), "faces": (n_f, 3), "face_normals": (n_f, 3),
                  "neighbors": (n_f, 3), "neighbor_edge": (n_f, 3)}
        for name, shape in shapes.items():
            if fields[name].shape != shape:
                raise ValueError(f"mesh.{name} must have shape {shape}, got {fields[name].shape}")
        for name in ("vertices", "normals", "face_normals"):
            if fields[name].dtype != self.dtype or self.dtype not in (jnp.float32, jnp.float64):
                raise ValueError(f"mesh.{name} is {fields[name].dtype}: vertices, normals and face_normals "
                                 "must share one float dtype (float32 or float64; mesh.astype converts all)")
            bad = np.flatnonzero(~np.all(np.isfinite(np.asarray(fields[name])), axis=-1))
            if bad.size:
                raise ValueError(f"mesh.{name} contain NaN or Inf: rows {_name(bad)}")
        limits = {"faces": (0, n_v - 1), "neighbors": (-1, n_f - 1), "neighbor_edge": (-1, 2)}
        for name, (lo, hi) in limits.items():
            x = np.asarray(fields[name])
            if not np.issubdtype(x.dtype, np.integer):
                raise ValueError(f"mesh.{name} must hold integer indices, got dtype {x.dtype}")
            bad = np.flatnonzero(np.any((x < lo) | (x > hi), axis=-1))
            if bad.size:
                raise ValueError(f"mesh.{name} out of range [{lo}, {hi}]: rows {_name(bad)}")
        return self

    def triangle(
        self, face: Int[Array, "*batch"]
    ) -> tuple[Float[Array, "*batch 3 3"], Float[Array, "*batch 3 3"]]:
        """Vertex positions `V` and unit vertex normals `N` of faces, rows V0, V1, V2.

        Negative (invalid) face indices gather face 0, so masked lanes stay finite.
        """
        idx = self.faces[jnp.maximum(jnp.asarray(face), 0)]
        return self.vertices[idx], self.normals[idx]

    def translated(self, offset) -> SurfaceMesh:
        """The same mesh moved by `offset` (`(3,)` metres): vertices `V + offset` added in
        float64 and rounded once to the mesh's dtype, normals and adjacency unchanged, a
        `grid` moved with it. Exact when `offset` is a multiple of every vertex
        coordinate's spacing (`frames.local_origin` picks such offsets)."""
        check_mesh_dtype(self.dtype)  # (else its vertices would come back float32, its normals float64)
        offset = real_array("offset", offset)
        if offset.shape != (3,) or not np.all(np.isfinite(offset)):
            raise ValueError(f"offset must be 3 finite real numbers, got {offset!r}")
        V = np.asarray(self.vertices, np.float64) + offset
        _check_fits(V, self.dtype)
        grid = self.grid if self.grid is None else dataclasses.replace(
            self.grid, x0=self.grid.x0 + float(offset[0]), y0=self.grid.y0 + float(offset[1]))
        return dataclasses.replace(self, vertices=jnp.asarray(V, self.dtype), grid=grid)

    def grid_deviation(self) -> float:
        """Largest distance (m, in x or y) of a vertex from its position on `grid` (0.0
        without a grid); a `ValueError` when the vertex count does not fit the layout.
        Rounding puts it at about half a spacing of the largest coordinate in the dtype the
        xy values were last rounded to (which may be an earlier dtype or position:
        `astype`, `translated`); the start points use the grid's exact cells only within
        rounding, and `prepare` warns about a grid moved after it was built
        (`frames.grid_state`)."""
        if self.grid is None:
            return 0.0
        g = self.grid
        xy = np.asarray(self.vertices, np.float64)[:, :2]
        if len(xy) != (g.nx + 1) * (g.ny + 1):
            raise ValueError(f"the mesh's vertices do not follow its GridInfo layout {g}")
        return float(np.max(np.abs(xy - g.vertex_xy()), initial=0.0))

    def without_grid(self) -> SurfaceMesh:
        """The same arrays without the static `grid` (start points then bin the faces)."""
        return dataclasses.replace(self, grid=None)

    def astype(self, dtype) -> SurfaceMesh:
        """The same mesh with float fields in `dtype` (float32 or float64)."""
        dtype = check_float_dtype(dtype)
        return dataclasses.replace(
            self,
            vertices=self.vertices.astype(dtype),
            normals=self.normals.astype(dtype),
            face_normals=self.face_normals.astype(dtype),
        )


@float_inputs(params=("t",), ints=("face", "edge"))
def cross_edge(
    mesh: SurfaceMesh,
    face: Int[Array, "*batch"],
    edge: Int[Array, "*batch"],
    t: Float[Array, "*batch"],
):
    """Cross edge `edge` of `face` at edge parameter `t` into the neighbouring face.

    `edge` is 0, 1 or 2 (or -1 where `face < 0`, as returned on a boundary; a `ValueError`
    otherwise, on concrete input; inside jit it is clipped) and `t` the `barycentric.py`
    edge parameter of the exit point. Returns
    `(next_face, next_edge, next_t, next_ab)`: the neighbour, the index of the shared
    edge within it, the entry point's parameter on that edge (same convention) and its
    barycentrics `(a, b)` in the neighbour, which give the same world point. On a boundary
    (or for `face < 0`) `next_face = next_edge = -1` and `next_t, next_ab` are the
    exit point's own `t` and barycentrics.
    """
    if not all(hasattr(mesh, a) for a in ("neighbors", "neighbor_edge", "dtype")):  # (duck-typed: the export
        raise ValueError(f"cross_edge: mesh must be a caustics_jax.SurfaceMesh (its adjacency), "  # passes arrays)
                         f"got {type(mesh).__name__}")
    check_mesh_dtype(mesh.dtype)
    face, edge = jnp.asarray(face), jnp.asarray(edge)
    n_faces = mesh.neighbors.shape[0]
    # (inside jit the edge is clipped to [0, 2]; on the host a wrong one is refused, not clipped)
    if not isinstance(edge, jax.core.Tracer) and not isinstance(face, jax.core.Tracer):
        f_np, e_np = np.broadcast_arrays(np.asarray(face), np.asarray(edge))
        bad = e_np[(e_np > 2) | (e_np < np.where(f_np >= 0, 0, -1))]
        if bad.size:
            raise ValueError(f"cross_edge: edge must be 0, 1 or 2 (edge k joins vertices k and k + 1 mod 3; "
                             f"-1 too where face < 0, as cross_edge returns on a boundary), got {int(bad[0])}")
    if not isinstance(face, jax.core.Tracer) and face.size and int(np.max(face)) >= n_faces:
        raise ValueError(f"cross_edge: face must lie below the mesh's {n_faces} faces (or be < 0: no face), "
                         f"got {int(np.max(face))}")
    t = jnp.asarray(t, dtype=mesh.dtype)
    valid_in = face >= 0
    f, k = jnp.maximum(face, 0), jnp.clip(edge, 0, 2)
    g = jnp.where(valid_in, mesh.neighbors[f, k], -1)
    k_next = jnp.where(g >= 0, mesh.neighbor_edge[f, k], -1)
    # s = 0 at vertex k of this face; consistent winding runs the shared edge the other
    # way in the neighbour, so there the same point sits at 1 - s from vertex k_next.
    s = edge_param_from_vertex_order(k, t)
    t_next = edge_param_from_vertex_order(jnp.maximum(k_next, 0), 1 - s)
    crossed = g >= 0
    t_out = jnp.where(crossed, t_next, t)
    ab = edge_barycentric(jnp.where(crossed, k_next, k), t_out)
    return g.astype(jnp.int32), k_next.astype(jnp.int32), t_out, ab


# --------------------------------------------------------------------------- validation


def _name(idx, limit: int = _MAX_NAMED) -> str:
    idx = np.unique(np.asarray(idx).ravel())
    shown = ", ".join(str(int(i)) for i in idx[:limit])
    return f"[{shown}{', ...' if len(idx) > limit else ''}] ({len(idx)} in all)"


def _validate_geometry(vertices, faces):
    V = real_array("vertices", vertices)
    if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] < 3:
        raise ValueError(f"vertices must have shape (V, 3) with V >= 3, got {V.shape}")
    try:
        F = np.asarray(faces)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"faces must be an (F, 3) array of vertex indices: {exc}") from None
    if F.ndim != 2 or F.shape[1] != 3 or F.shape[0] == 0:
        raise ValueError(f"faces must have shape (F, 3) with F >= 1, got {F.shape}")
    if not np.issubdtype(F.dtype, np.integer):
        raise ValueError(f"faces must be integer vertex indices, got dtype {F.dtype}")
    bad_v = np.flatnonzero(~np.all(np.isfinite(V), axis=-1))
    if bad_v.size:
        raise ValueError(f"vertices contain NaN or Inf coordinates: vertices {_name(bad_v)}")
    bad_f = np.flatnonzero(np.any((F < 0) | (F >= len(V)), axis=-1))
    if bad_f.size:
        one_based = F.min() == 1 and F.max() == len(V)  # OBJ numbers vertices from 1
        hint = (f"; the indices run from 1 to {len(V)}, as in an OBJ file: pass faces - 1 (indices from 0)"
                if one_based else "")
        raise ValueError(f"face vertex indices out of range [0, {len(V)}): faces {_name(bad_f)}{hint}")
    F = F.astype(np.int64)
    repeated = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    if repeated.any():
        raise ValueError(
            f"degenerate faces (repeated vertex index): faces {_name(np.flatnonzero(repeated))}"
        )
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    e3 = V[F[:, 2]] - V[F[:, 1]]
    twice_area = np.linalg.norm(np.cross(e1, e2), axis=-1)
    longest_sq = np.max(np.stack([np.sum(e * e, -1) for e in (e1, e2, e3)]), axis=0)
    # Zero area relative to the face's own size: a sliver whose area is at the float64
    # rounding level of its edge lengths has no usable normal.
    zero = twice_area <= 64 * np.finfo(np.float64).eps * longest_sq
    if zero.any():
        raise ValueError(f"degenerate faces (zero area): faces {_name(np.flatnonzero(zero))}")
    return V, F


def _adjacency(F: np.ndarray):
    """`neighbors, neighbor_edge` by sorting undirected edge keys (vectorised, O(F log F))."""
    n_f = len(F)
    a = F.reshape(-1)  # half-edge h = 3 f + k runs from F[f, k] to F[f, k + 1 mod 3]
    b = F[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (int(F.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    k_sorted = key[order]
    start = np.flatnonzero(np.r_[True, k_sorted[1:] != k_sorted[:-1]])
    count = np.diff(np.r_[start, len(k_sorted)])
    if (count > 2).any():
        bad_h = order[np.repeat(count > 2, count)]
        edges = sorted({(int(lo[h]), int(hi[h])) for h in bad_h[: 3 * _MAX_NAMED]})
        raise ValueError(
            "non-manifold edges (shared by more than two faces): "
            f"vertex pairs {edges[:_MAX_NAMED]}, "
            f"faces {_name(bad_h // 3)}; {int((count > 2).sum())} such edges in all"
        )
    pair = start[count == 2]
    h0, h1 = order[pair], order[pair + 1]
    same_direction = a[h0] == a[h1]
    if same_direction.any():
        bad = np.concatenate([h0[same_direction], h1[same_direction]]) // 3
        raise ValueError(
            "inconsistent winding (a shared edge runs the same way in both faces, so their "
            f"normals disagree): faces {_name(bad)}"
        )
    neighbors = np.full(3 * n_f, -1, dtype=np.int64)
    neighbor_edge = np.full(3 * n_f, -1, dtype=np.int64)
    neighbors[h0], neighbor_edge[h0] = h1 // 3, h1 % 3
    neighbors[h1], neighbor_edge[h1] = h0 // 3, h0 % 3
    return neighbors.reshape(n_f, 3), neighbor_edge.reshape(n_f, 3)


def _vertex_normals(V, F, weighting: str):
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    if weighting == "area":
        w = np.ones((len(F), 3))
        n_face = cross  # |cross| = 2 area: the area weight comes for free
    elif weighting == "angle":
        n_face = cross / np.linalg.norm(cross, axis=-1, keepdims=True)
        w = np.empty((len(F), 3))
        for k in range(3):  # three corners, vectorised over faces
            u = V[F[:, (k + 1) % 3]] - V[F[:, k]]
            v = V[F[:, (k + 2) % 3]] - V[F[:, k]]
            w[:, k] = np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, -1))
    else:
        raise ValueError(f"normal_weighting must be 'angle' or 'area', got {weighting!r}")
    N = np.zeros_like(V)
    for k in range(3):
        np.add.at(N, F[:, k], w[:, k : k + 1] * n_face)
    return N


def _check_normals(N, F, face_n, *, what: str):
    bad = np.flatnonzero(~np.all(np.isfinite(N), axis=-1))
    if bad.size:
        raise ValueError(f"{what} normals contain NaN or Inf: vertices {_name(bad)}")
    length = np.linalg.norm(N, axis=-1)
    zero = np.flatnonzero(length <= np.finfo(np.float64).tiny ** 0.5)
    if zero.size:
        hint = " (unreferenced vertices, or incident faces cancel)" if what == "computed" else ""
        raise ValueError(f"{what} normals are zero{hint}: vertices {_name(zero)}")
    if what == "given":
        # Outward is defined by the winding: a normal against all incident faces is flipped.
        agree = np.full(len(N), -np.inf)
        for k in range(3):
            np.maximum.at(agree, F[:, k], np.sum(N[F[:, k]] * face_n, -1))
        flipped = np.flatnonzero(agree <= 0)
        if flipped.size:
            raise ValueError(
                f"given normals point against the face winding at vertices {_name(flipped)} "
                "(outward = counter-clockwise seen from outside)"
            )


def _check_grid(grid: GridInfo, V, F):
    if len(V) != (grid.nx + 1) * (grid.ny + 1) or not np.array_equal(F, grid.faces()):
        raise ValueError(f"vertices/faces do not follow the GridInfo layout {grid}")
    off = np.flatnonzero(
        np.any(np.abs(V[:, :2] - grid.vertex_xy()) > 1e-9 * max(abs(grid.dx), abs(grid.dy)), axis=-1)
    )
    if off.size:
        raise ValueError(f"vertices off the regular grid xy positions: vertices {_name(off)}")


def _check_fits(V: np.ndarray, dtype, what: str = "vertices") -> None:
    """Vertices must stay finite in the mesh's dtype: 1e39 is a float64 but overflows float32."""
    with np.errstate(over="ignore"):
        bad = np.flatnonzero(~np.all(np.isfinite(V.astype(dtype)), axis=-1))
    if bad.size:
        raise ValueError(f"{what} overflow {np.dtype(dtype).name} (|coordinate| > "
                         f"{float(np.finfo(dtype).max):.3g}): vertices {_name(bad)}; build the mesh in "
                         "float64 or rescale it")


def _warn_if_inward(V: np.ndarray, F: np.ndarray, neighbors: np.ndarray) -> None:
    """Warn when the winding makes the outward normals point away from where lights are.

    "Outward" is toward the light (math.md §1); a mesh alone does not say where the light
    is, so only two unambiguous cases warn:

    - a closed mesh (no boundary edge) whose signed volume `sum V0 . (V1 x V2) / 6`
      (divergence theorem) is negative: every normal points into the solid;
    - an open mesh whose vector area `sum (V1 - V0) x (V2 - V0) / 2` points down by more
      than half its total area: a surface seen from above, wound clockwise (its normals
      point to -z, away from a light above it).

    A closed mesh wound outward, a vertical wall, a bowl or a box open at the top do not
    warn. A surface lit from below is legitimate and warns: silence it with
    `warnings.filterwarnings("ignore", message="surface normals")`.
    """
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    cross = np.cross(e1, e2)
    total = float(np.sum(np.linalg.norm(cross, axis=-1)))
    if np.all(neighbors >= 0):
        c = V.mean(0)  # about the centroid: the volume sum then does not cancel large offsets
        volume = float(np.sum(np.einsum("ij,ij->i", V[F[:, 0]] - c, np.cross(V[F[:, 1]] - c, V[F[:, 2]] - c))))
        scale = total * float(np.max(np.linalg.norm(V - c, axis=-1)))
        if volume < -1e-9 * scale:
            warn_user(
                "surface normals point into the closed mesh (negative enclosed volume): faces are wound "
                "clockwise seen from outside, so every lane would end TIR or LEFT_MESH. Reverse the face "
                "winding, e.g. SurfaceMesh.from_arrays(vertices, faces[:, ::-1])")
        return
    down = float(np.sum(cross[:, 2]))
    if down < -0.5 * total:
        warn_user(
            f"surface normals point mostly down (-z: {100 * -down / total:.0f}% of the area faces down): "
            "normals must face the light (math.md §1), so with a light above, every lane would end TIR or "
            "LEFT_MESH. Reverse the face winding, e.g. SurfaceMesh.from_arrays(vertices, faces[:, ::-1]); "
            "if the light really is below the surface, ignore this warning")
