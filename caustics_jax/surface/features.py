"""Scene features: what a mesh and its lights let the solvers skip (DESIGN.md, "Skipping
what a scene does not need").

`features(mesh, lights_or_L)` inspects the scene once, on the host (numpy float64, outside
jit), and returns a `SceneFeatures`: a hashable NamedTuple of booleans. `solve` and
`irradiance` pick their jitted functions from it on the host, so a branch a scene does
not need is never traced or compiled (static configuration, STYLE.md).
It holds no floats of the geometry: the plane of a flat surface, its heights and the
lights stay traced arrays, so moving them never recompiles.

Flags and what `solve` / `irradiance` (with `features="auto"`) do with them:

- `flat`: vertices coplanar, every vertex and face normal equal to the plane normal,
  faces tiling their convex hull. The walk's points come in closed form on the line of
  seed 001 eq. 1-2 (`solvers/flat.py`).
- `compact_lanes` (always True from `features()`): lanes whose segment cannot reach the
  surface skip the start-point search, lanes without a start point skip the solver,
  and `irradiance` computes `D` only on found lanes.

Flags that were recorded but changed nothing were removed: constant normals imply a flat
surface on a connected mesh (shared vertices share their normal), a regular grid is
already read from `mesh.grid` by the start points, and a directional light is a far
point light to every solver.

docs/features.md has the measured identical-output evidence and the speed-ups.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..runtime.arguments import real_array
from ..runtime.precision import check_mesh_dtype
from .mesh import SurfaceMesh

# Coplanarity and equal-normal tolerances, in units of the mesh dtype's epsilon (relative
# to the mesh extent for positions). A float32 flat pool built at z = 0 is exactly flat;
# 64 eps leaves room for a plane that is tilted or offset and rounded per vertex.
_EPS_FACTOR = 64


class SceneFeatures(NamedTuple):
    """Static properties of a scene (hashable: a static argument of the jitted solvers).

    Attributes:
        flat: the surface is one plane with the plane's normal everywhere, and its faces
            tile their convex hull, so the refraction point is found in closed form on the
            line of seed 001 eq. 1-2 and the straight path from `M0` to it never crosses a
            boundary edge.
        compact_lanes: compact batches to the lanes that need the start-point search, the
            solver and the D factor, and scatter the results back.
    """

    flat: bool = False
    compact_lanes: bool = False


GENERAL = SceneFeatures()  # every flag off: the general path


def features(mesh: SurfaceMesh, lights_or_L=None) -> SceneFeatures:
    """Analyse `mesh` (and optionally its lights) once, on the host; see the module table.

    Args:
        mesh: the refractive surface.
        lights_or_L: `None`, a `caustics_jax.surface.scenes.Lights`, or light positions `(3,)` /
            `(N, 3)`; validated, but no property of the lights changes what the solvers
            skip today (a directional light is a far point light to them).

    Raises `ValueError` for anything else, or for non-finite light positions.
    """
    if not isinstance(mesh, SurfaceMesh) and isinstance(getattr(mesh, "mesh", None), SurfaceMesh):
        mesh = mesh.mesh  # a PreparedSurface (caustics_jax.prepare), as solve and irradiance accept
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"mesh must be a caustics_jax.SurfaceMesh, got {type(mesh).__name__}")
    mesh.check_arrays()
    check_mesh_dtype(mesh.dtype)
    _check_lights(lights_or_L)
    return mesh_features(mesh)


def mesh_features(mesh: SurfaceMesh) -> SceneFeatures:
    """`features(mesh)` of a mesh whose arrays are already checked (`mesh.check_arrays()`,
    as `prepare` does before its analysis): the analysis without the checks."""
    eps = float(np.finfo(np.dtype(mesh.dtype)).eps)
    N_unit = np.asarray(mesh.normals)  # unit: SurfaceMesh normalises them in float64
    F = np.asarray(mesh.faces)
    tol_n = _EPS_FACTOR * eps

    def constant(faces):
        N_f = N_unit[faces].astype(np.float64)
        return bool(np.all(np.abs(N_f - N_f[:, :1]) <= tol_n))

    # A curved surface fails on its first faces: "auto" then costs O(4096), not the O(F) of
    # the full check (docs/features.md, "Measurements behind the code").
    constant_normals = constant(F[:4096]) and constant(F)
    return SceneFeatures(
        flat=constant_normals and _is_flat(np.asarray(mesh.vertices, np.float64),
                                           N_unit.astype(np.float64), F,
                                           np.asarray(mesh.face_normals, np.float64), eps),
        compact_lanes=True,
    )


def _check_lights(lights_or_L) -> None:
    if lights_or_L is None:
        return
    from .scenes import Lights

    if isinstance(lights_or_L, Lights):
        return
    try:
        L = real_array("lights_or_L", lights_or_L)
    except ValueError as exc:
        raise ValueError(f"lights_or_L must be None, a Lights or (N, 3) positions: {exc}") from None
    if L.ndim == 0 or L.shape[-1] != 3:
        raise ValueError(f"lights_or_L must be a Lights or have shape (3,) or (N, 3), got {L.shape}")
    if not np.all(np.isfinite(L)):
        raise ValueError("lights_or_L has NaN or Inf coordinates")


def _is_flat(V, N_unit, F, N_face, eps) -> bool:
    """One plane, its normal at every vertex and face, and the faces tile their convex hull."""
    n = N_unit[0]
    extent = float(np.max(np.abs(V - V[0]))) or 1.0
    tol = _EPS_FACTOR * eps
    if np.max(np.abs(N_unit - n)) > tol or np.max(np.abs(N_face - n)) > tol:
        return False
    if np.max(np.abs((V - V[0]) @ n)) > tol * extent:
        return False
    # Convex and without holes: the projected faces (all facing +n, consistently wound,
    # manifold: SurfaceMesh validated that) cover exactly the area of their hull. Then the
    # straight segment from M0 to M never crosses a boundary edge, as the walk would.
    from scipy.spatial import ConvexHull

    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    xy = np.stack([(V - V[0]) @ u, (V - V[0]) @ w], -1)
    T = xy[F]
    e1, e2 = T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
    area = 0.5 * np.sum(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]))
    try:
        hull = ConvexHull(xy).volume  # in 2D, `volume` is the area
    except Exception:  # noqa: BLE001  (qhull: all points on a line, a degenerate mesh)
        return False
    return bool(abs(area - hull) <= 1e-9 * hull)


def check(features_arg) -> None:
    """Raise `ValueError` unless `features_arg` is `"auto"`, `None` or a `SceneFeatures`."""
    if features_arg is None or isinstance(features_arg, SceneFeatures):
        return
    if isinstance(features_arg, str) and features_arg == "auto":
        return
    raise ValueError(
        f"features must be 'auto', None or a SceneFeatures from caustics_jax.surface.features(mesh), "
        f"got {features_arg!r}")
