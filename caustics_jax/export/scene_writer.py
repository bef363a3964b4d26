"""Writing a scene file: surface, face cells, lanes, the float32 solver's per-lane results and
the float64 reference (DESIGN.md "Reference data for shader tests"; docs/export.md "Scenes").

`export_scene(spec, lanes, seed, solver=...)` builds the scene (`scene_registry.SceneData`),
rounds the surface and lanes to float32 once, and on exactly those values runs

- the start point through the face cells written to the file, and the solver in float32:
  the curve walk (`solve(..., method=Walk(fallback="none"), features=None)`: the general
  walk, no closed form, as a shader runs it; seed 001 §3.4) or the one-step Newton on the
  half-vector constraint (`NEWTON`, `newton-hv-step`); then `D` (seed 001 eq. 26-33) and the
  irradiance (eq. 25, math.md §6) at its point: the `output` fields a port must reproduce;
- the same solver in float64 on the float32 values cast exactly to float64: the `reference`
  fields (`M_ref` + `M_ref_lo` is the float64 point in two float32 parts), and the
  refraction-angle error of that point (`testing.oracle.refraction_angle_error`);
- the tolerances of conformance: per lane the distance within which two accepted points can
  lie (`M_tol`: the walk's from `df/ds` along the curve at the float32 point, in float64;
  the Newton's measured, from the float32 points' distance to the float64 roots they polish
  to), the float32 error of `D` and `E` near the lane's point (`D_err`, `E_err`), per scene
  the measured float32 error of `D` and `E` at the testbed's points, and which lanes float32
  decides (`conditioned`).

Same arguments, same bytes (the tolerance digits are measured on the exporting machine).
"""

from __future__ import annotations

import zlib

import jax
import jax.numpy as jnp
import numpy as np

from ..accel.face_cells import FaceCells, bin_faces
from ..accel.prepared import prepare
from ..accel.start_points import start_points
from ..curve.arcs import project_to_conic
from ..math.barycentric import barycentric_point
from ..math.conic import conic_coefficients, conic_tangent, edge_quadratics, tangent_to_world
from ..math.crossing import triangle_crossing
from ..math.objectives import ObjectiveStatus, bracket_objective
from ..runtime.arguments import check_int
from ..runtime.precision import precision
from ..solvers import Newton, Status, Walk, solve
from ..solvers.newton import MAX_PROJECTION_CROSSINGS, MIN_BETA
from ..surface.mesh import SurfaceMesh
from ..testing.oracle import NumpyMesh, refraction_angle_error, refraction_rounding_bound
from ..transport.contribution import path_irradiance
from ..transport.differentials import ray_differential_D
from .records import CASES, FORMAT_VERSION
from .scene_records import BRACKETS, CELL_KINDS, SOLVERS, pack_scene
from .scene_registry import SceneSpec
from .tolerance import SAFETY

#: Where the scene's math comes from (papers and math.md; never Python modules).
EQUATIONS = ("start point: first crossing of segment P -> L with the surface (seed 001 §3.4.2); "
             "walk: coplanarity conic (seed 001 eq. 10-12, math.md §2), tangent (eq. 13-15 with the symmetric "
             "part, math.md §2), edge crossings (eq. 22-24 corrected, math.md §3), signed sine in the 'plane' and "
             "'line' orientations (eq. 19-21, math.md §4), walk and dichotomy (§3.4.3-3.4.4) with Illinois false "
             "position; D by ray differentials (eq. 26-33, signs of math.md §6); irradiance "
             "E = eta^2 T A cos(theta_P) I_e / D (eq. 25 corrected, math.md §6)")
#: Where a Newton scene file's math comes from.
NEWTON_EQUATIONS = ("start point: as the walk's (seed 001 §3.4.2); one-step Newton on the half-vector constraint "
                    "(Walter et al. 2009; Hanika et al. 2015 MNEE §4.3; math.md §4) with its closed-form Jacobian "
                    "(math.md §4), the step projected back onto the surface along the ray from P (Cycles' "
                    "mnee_newton_solver), beta halved on a failed projection and doubled back to 1; acceptance "
                    "|f| <= tol on the signed sine (eq. 19-21, 'plane'); D and E as the walk's (eq. 25-33)")
#: Step (m) of the central difference of f along the curve that sizes `M_tol`.
CURVE_STEP = 1e-5
#: Runs of the float32 walk on inputs moved by one ulp that decide whether a lane is `stable`.
PERTURBATIONS = 4


def _nudged(x: np.ndarray, rng) -> np.ndarray:
    """float32 `x` with each coordinate moved by -1, 0 or +1 ulp at random."""
    step = rng.integers(-1, 2, x.shape)
    up, down = np.nextafter(x, np.float32(np.inf)), np.nextafter(x, np.float32(-np.inf))
    return np.where(step > 0, up, np.where(step < 0, down, x)).astype(np.float32)


def _nudged_mesh(mesh, rng) -> SurfaceMesh:
    """The float32 surface with every vertex moved by about one float32 rounding of the
    scene's size and every normal turned by about `eps` (a line conic, whose curvature
    terms vanish exactly, gets rounding-sized ones: what a port's own arithmetic gives it).
    Without the grid: the start points take the general path."""
    V, N = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.normals, np.float64)
    eps = float(np.finfo(np.float32).eps)
    V = V + rng.uniform(-1, 1, V.shape) * eps * np.abs(V).max()
    N = N + rng.uniform(-1, 1, N.shape) * eps
    return SurfaceMesh.from_arrays(V, np.asarray(mesh.faces), N, dtype="float32")


def _df_ds(V, N, P, L, ab, eta):
    """`|df/ds|` per lane: the signed sine's rate of change along the conic per metre of arc,
    by a central difference of `CURVE_STEP` (both ends projected back onto the conic),
    float64."""
    coef = conic_coefficients(V, N, P, L)
    t = conic_tangent(coef, ab)
    length = jnp.linalg.norm(tangent_to_world(V, t), axis=-1)
    step = jnp.where(length > 0, CURVE_STEP / jnp.where(length > 0, length, 1), 0)[..., None] * t
    ends = jax.vmap(lambda c, x: jax.vmap(lambda y: project_to_conic(c, y))(x))(
        coef, jnp.stack([ab - step, ab + step], 1))
    f, st, _ = jax.vmap(bracket_objective)(V, N, P, L, ends, jnp.broadcast_to(eta, P.shape[:1]))
    ok = jnp.all(st == ObjectiveStatus.OK, -1) & (length > 0)
    return jnp.where(ok, jnp.abs(f[:, 1] - f[:, 0]) / (2 * CURVE_STEP), 0)


#: Lanes per call of `_tie_crossings` (fixed, so one compile per neighbour-table width).
_TIE_CHUNK = 4096


@jax.jit
def _tie_crossings(P, d, V0, V_near):
    """`(inside, close, ab)` of each lane's segment with its neighbour faces `V_near`
    (`(n, w, 3, 3)`): in the face within its rounding bound, and at the start face's `s`
    (`V0`) within both bounds (`crossing.triangle_crossing`)."""
    c0 = triangle_crossing(P, d, V0)
    c = triangle_crossing(P[:, None], d[:, None], V_near)
    close = jnp.abs(c.s - c0.s[:, None]) <= c.s_tol + c0.s_tol[:, None]
    return c.inside, close, c.ab


def _ties_agree(mesh, P, L, start, status, eta, walk) -> np.ndarray:
    """Per lane, whether the walk ends with `status` from every face that ties with the
    start face, and from points a few ulps around each tied start: another face sharing a
    vertex with the start face that holds the crossing within its rounding tolerance and
    within both tolerances of the start's `s` (`crossing.triangle_crossing`, float32 as the
    testbed's). At a shared edge or vertex the face is a tie that a port breaks its own way
    (its traversal, its tolerance: the GLSL start point takes the lowest `s` at a fixed
    16 eps), and the walk from the next face may end otherwise (FOUND from the testbed's
    face, LEFT_MESH from the port's). The JAX walk from the port's face mostly ends as the
    port does, but a lane can also flip with one ulp of the start point, hence the nudges
    (docs/export.md, "Measurements behind the code")."""
    faces = np.asarray(mesh.faces)
    face0, found = np.asarray(start.face), np.asarray(start.found)
    lanes = np.flatnonzero(found)
    agree = np.ones(len(found), bool)
    if lanes.size == 0:
        return agree
    # faces sharing a vertex with each start face, one padded row per face used (host, once)
    flat = faces.ravel()
    order = np.argsort(flat, kind="stable")
    first = np.searchsorted(flat[order], np.arange(int(np.asarray(mesh.vertices).shape[0]) + 1))
    used, row_of = np.unique(face0[lanes], return_inverse=True)
    near = [np.unique(np.concatenate([order[first[v]:first[v + 1]] // 3 for v in faces[f]])) for f in used]
    width = -(-max(len(x) for x in near) // 16) * 16  # a multiple of 16: few compiles
    table = np.full((len(used), width), -1)
    for row, x in enumerate(near):
        table[row, :len(x)] = x
    cand = table[row_of]
    P_np, L_np = np.asarray(P), np.asarray(L)
    V = np.asarray(mesh.vertices)[faces]
    tie = np.zeros(cand.shape, bool)
    ab = np.zeros(cand.shape + (2,), np.float64)
    for lo in range(0, lanes.size, _TIE_CHUNK):  # fixed-size chunks: one compile per width
        part = lanes[lo:lo + _TIE_CHUNK]
        pad = np.r_[part, np.full(_TIE_CHUNK - part.size, part[0])]
        P_c, d_c = P_np[pad], L_np[pad] - P_np[pad]
        rows = np.r_[np.arange(lo, lo + part.size), np.full(_TIE_CHUNK - part.size, lo)]
        inside, close, ab_c = (np.asarray(x) for x in _tie_crossings(
            P_c, d_c, V[face0[pad]], V[np.maximum(cand[rows], 0)]))
        n = part.size
        tie[lo:lo + n] = inside[:n] & close[:n] & (cand[lo:lo + n] >= 0) & (cand[lo:lo + n] != face0[part][:, None])
        ab[lo:lo + n] = ab_c[:n]
    rows, cols = np.nonzero(tie)
    if rows.size == 0:
        return agree
    idx = lanes[rows]
    ab = ab[rows, cols]
    delta = 8 * float(np.finfo(np.float32).eps)
    for nudge in NUDGES[:5]:
        x = _moved_into_face(ab, delta, nudge)
        other = solve(mesh, P_np[idx], L_np[idx], eta=eta, method=walk, features=None,
                      start=(cand[rows, cols].astype(np.int32), x, np.ones(rows.size, bool)))
        np.logical_and.at(agree, idx, np.asarray(other.status) == np.asarray(status)[idx])
    return agree


def _transport(mesh, sol, P, L, n_P, intensity, sigma_t, eta):
    """`D`, its validity and `E` at the solution's points, 0 where the lane is not FOUND."""
    V, N = mesh.triangle(sol.triangle)
    D, valid = ray_differential_D(V, N, P, L, sol.barycentric, eta)
    E, _ = path_irradiance(V, N, P, L, sol.barycentric, eta, intensity, n_P, sigma_t)
    found = sol.status == Status.FOUND
    return (np.asarray(jnp.where(found, D, 0)), np.asarray(found & valid).astype(np.uint32),
            np.asarray(jnp.where(found, E, 0)))


#: Offsets, in units of `TRANSPORT_NUDGE` float32 epsilons of `(a, b)`, of the points at which
#: each lane's float32 error of `D` and `E` is measured (`_nudged_points`).
NUDGES = ((0, 0), (1, 1), (-1, -1), (1, -1), (-1, 1), (2, 0), (0, 2), (-2, 0), (0, -2))
TRANSPORT_NUDGE = 4


def _moved_into_face(ab: np.ndarray, delta: float, nudge) -> np.ndarray:
    """float32 barycentrics `ab + delta nudge`, projected into the closed triangle."""
    x = np.maximum(np.asarray(ab, np.float64) + delta * np.asarray(nudge, np.float64), 0)
    return (x / np.maximum(x.sum(-1, keepdims=True), 1)).astype(np.float32)


def _nudged_points(ab32: np.ndarray) -> list[np.ndarray]:
    """float32 barycentrics `ab32` moved by each of `NUDGES` (into the closed triangle)."""
    delta = TRANSPORT_NUDGE * float(np.finfo(np.float32).eps)
    return [_moved_into_face(ab32, delta, nudge) for nudge in NUDGES]


def _transport_at(mesh, face, points, P, L, n_P, intensity, sigma_t, eta) -> tuple[np.ndarray, np.ndarray]:
    """`D` and `E` `(len(points), n)` at each barycentric array of `points` on `face`, in
    the mesh's dtype (the inputs cast to it)."""
    V, N = mesh.triangle(jnp.asarray(np.maximum(face, 0)))
    dt = mesh.dtype
    P, L, n_P, intensity, sigma_t = (jnp.asarray(np.asarray(x), dt) for x in (P, L, n_P, intensity, sigma_t))
    Ds, Es = [], []
    for ab in points:
        ab = jnp.asarray(ab, dt)
        D, _ = ray_differential_D(V, N, P, L, ab, eta)
        E, _ = path_irradiance(V, N, P, L, ab, eta, intensity, n_P, sigma_t)
        Ds.append(np.asarray(D, np.float64))
        Es.append(np.asarray(E, np.float64))
    return np.stack(Ds), np.stack(Es)


def _lane_error(x32: np.ndarray, x64: np.ndarray) -> np.ndarray:
    """Per lane, the largest relative float32 error over the nudged points (0 where `x64` is 0)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(np.abs(x64) > 0, np.abs(x32 - x64) / np.abs(x64), 0.0)
    return rel.max(0)


def _mesh(vertices, faces, normals, grid, dtype):
    """The surface in `dtype`; a grid whose float32-rounded vertices fail its check is dropped
    (only the float64 reference rebuilds from rounded values; it then takes the general path)."""
    try:
        return SurfaceMesh.from_arrays(vertices, faces, normals, grid=grid, dtype=dtype)
    except ValueError:
        if grid is None:
            raise
        return SurfaceMesh.from_arrays(vertices, faces, normals, dtype=dtype)


def _split(x64: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 as two float32 parts `hi + lo` (about 48 significant bits)."""
    hi = x64.astype(np.float32)
    return hi, (x64 - hi.astype(np.float64)).astype(np.float32)


def _stats(x: np.ndarray) -> dict:
    x = np.asarray(x, np.float64)
    if x.size == 0:
        return {"n": 0}
    return {"n": int(x.size), "max": float(x.max()), "p99": float(np.quantile(x, 0.99)),
            "median": float(np.median(x))}


#: The Newton a scene file can hold: the project's strongest baseline (`newton-hv-step`:
#: half-vector constraint, one Newton step then re-projection; docs/solvers.md), the one
#: the GLSL Newton (`newton.glsl`) ports. `initial_step` 0.1 is Cycles' MNEE step control.
NEWTON = Newton(stepping="one_step", constraint="half_vector")


def check_scene_solver(solver: str, walk=None, newton=None):
    """The solver object of a scene file from `export_scene`'s arguments (`solver` "walk"
    or "newton", the options `walk` or `newton`, None for the defaults), or ValueError."""
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {', '.join(map(repr, SOLVERS))}, got {solver!r}")
    if solver == "walk":
        if walk is not None and not isinstance(walk, Walk):
            raise ValueError(f"walk must be None or a caustics_jax.Walk, got {walk!r}")
        if walk is not None and walk.fallback != "none":
            raise ValueError("the exported lanes are the GLSL walk's reference, and the GLSL walk has no Newton "
                             f"fallback: pass Walk(fallback='none', ...), got fallback={walk.fallback!r}")
        return Walk(fallback="none") if walk is None else walk
    if newton is not None and not isinstance(newton, Newton):
        raise ValueError(f"newton must be None or a caustics_jax.Newton, got {newton!r}")
    newton = NEWTON if newton is None else newton
    if (newton.stepping, newton.constraint, newton.n_starts) != ("one_step", "half_vector", 1):
        raise ValueError("the GLSL Newton ports the one-step half-vector Newton from M0 (newton-hv-step): pass "
                         "Newton(stepping='one_step', constraint='half_vector', n_starts=1, ...), got "
                         f"stepping={newton.stepping!r}, constraint={newton.constraint!r}, "
                         f"n_starts={newton.n_starts}")
    return newton


def _reference_method(method):
    """The float64 reference solver: the same options (its own default `tol` in float64)."""
    if isinstance(method, Walk):
        return Walk(max_steps=method.max_steps, bracket=method.bracket, ellipse_samples=method.ellipse_samples,
                    fallback="none")
    return Newton(stepping="one_step", constraint="half_vector", max_patches=method.max_patches,
                  initial_step=method.initial_step)


def _export_cells(mesh) -> FaceCells:
    """The face cells of the exported start points: the testbed's own (`prepare(mesh).accel`),
    or, where the testbed would take its BVH, faces binned without a cap on the list length
    (a shader has no BVH of the testbed's; a long list continues over rows)."""
    accel = prepare(mesh).accel
    if isinstance(accel, FaceCells):
        return accel
    cells = bin_faces(mesh, max_cell_faces=2**31 - 1)
    assert cells is not None  # (bin_faces returns None only above max_cell_faces)
    return cells


def _cell_records(mesh, cells: FaceCells) -> tuple[dict, dict]:
    """The `cell_lines`, `cell_faces` and `cell_rows` buffers and the scene record's cell
    members (scene_records.py), numpy float32: each cell's height range is the min and
    max of its listed faces' vertex coordinates along the projection axis (exact)."""
    nu, nv = cells.shape
    table, more = np.asarray(cells.faces), np.asarray(cells.more)
    owner = np.asarray(cells.owner)
    w = cells.axes[2]
    z = np.asarray(mesh.vertices)[:, w][np.asarray(mesh.faces)]  # (F, 3)
    listed = table >= 0
    face_lo = np.where(listed, z.min(1)[np.maximum(table, 0)], np.inf).min(1)
    face_hi = np.where(listed, z.max(1)[np.maximum(table, 0)], -np.inf).max(1)
    cell_lo, cell_hi = np.full(nu * nv, np.inf), np.full(nu * nv, -np.inf)
    np.minimum.at(cell_lo, owner, face_lo)
    np.maximum.at(cell_hi, owner, face_hi)
    big = float(np.finfo(np.float32).max)
    row_lo = np.minimum(cell_lo[owner], big).astype(np.float32)  # empty cells: met by no segment
    row_hi = np.maximum(cell_hi[owner], -big).astype(np.float32)
    zw = np.asarray(mesh.vertices)[:, w]
    scene = {"cell_nu": [nu], "cell_nv": [nv], "cell_width": [table.shape[1]], "cell_rows": [table.shape[0]],
             "cell_kind": [CELL_KINDS[cells.kind]], "cell_axis_u": [cells.axes[0]], "cell_axis_v": [cells.axes[1]],
             "cell_axis_w": [w], "cell_w_lo": [zw.min()], "cell_w_hi": [zw.max()]}
    buffers = {"cell_lines": {"x": np.concatenate([np.asarray(cells.u_lines), np.asarray(cells.v_lines)])},
               "cell_faces": {"face": table.reshape(-1)},
               "cell_rows": {"more": more, "z_lo": row_lo, "z_hi": row_hi}}
    return scene, buffers


def _polish_distance(mesh64, sol, P64, L64, eta, method):
    """Per lane, the distance of each FOUND float32 point from the root the float64 Newton
    polishes it to (started at that point: the root it converged to, to float64); 0
    elsewhere. Newton's point tolerance is `2 x SAFETY` times its largest value over the
    conditioned lanes: a port and the testbed each lie within float32's error of the root."""
    found = np.asarray(sol.status) == Status.FOUND
    dist = np.zeros(len(found))
    lanes = np.flatnonzero(found)
    if lanes.size:
        face = jnp.asarray(np.asarray(sol.triangle)[lanes])
        ab = jnp.asarray(np.asarray(sol.barycentric, np.float64)[lanes])
        polished = solve(mesh64, P64[lanes], L64[lanes], eta=eta, method=_reference_method(method), features=None,
                         start=(face, ab, jnp.ones(lanes.size, bool)))
        ok = np.asarray(polished.status) == Status.FOUND
        d = np.linalg.norm(np.asarray(sol.point, np.float64)[lanes] - np.asarray(polished.point), axis=-1)
        dist[lanes] = np.where(ok, d, 0.0)
    return dist


def export_scene(spec: SceneSpec, lanes: int, seed: int, walk: Walk | None = None, *, solver: str = "walk",
                 newton: Newton | None = None):  # fmt: skip
    """`(manifest, bytes)` of one scene file with `lanes` lanes (module docstring) for
    `solver` `"walk"` (`walk`, default `Walk(fallback="none")`) or `"newton"` (`newton`,
    default `NEWTON`, the one-step half-vector Newton; `initial_step=0.1` for Cycles' MNEE
    step control); `lanes` in [1, 2^20] and `seed` non-negative, as `export` requires:
    `ValueError` otherwise. Same surface, lanes and start points for both solvers."""
    if not isinstance(spec, SceneSpec):
        raise ValueError(f"spec must be an export SceneSpec (export.SCENES[name]), got {type(spec).__name__}")
    lanes = check_int("lanes", lanes, 1, 2**20)
    seed = check_int("seed", seed, 0, 2**63 - 1)
    method = check_scene_solver(solver, walk, newton)
    is_walk = solver == "walk"
    rng = np.random.default_rng([seed, zlib.crc32(spec.name.encode())])
    data = spec.build(rng, lanes)
    eta = float(np.float32(data.eta))
    with precision("float32"):
        mesh = _mesh(data.vertices, data.faces, data.normals, data.grid, "float32")
        V32, N32 = np.asarray(mesh.vertices), np.asarray(mesh.normals)
        f32 = {k: np.asarray(getattr(data, k), np.float32) for k in ("P", "L", "receiver_normal", "intensity",
                                                                        "sigma_t")}
        P, L = jnp.asarray(f32["P"]), jnp.asarray(f32["L"])
        cells = _export_cells(mesh)
        start = start_points(mesh, P, L, accel=cells)
        sol = solve(mesh, P, L, eta=eta, method=method, features=None, start=start)
        tol = float(np.float32(method.tolerance(jnp.float32)))
        # A lane whose status the testbed itself changes when P and L move by one ulp, or
        # the surface by one rounding, is decided by rounding: no port can be required to
        # reproduce it (`conditioned` = 0).
        nudge = np.random.default_rng([seed, zlib.crc32(spec.name.encode()), 1])
        stable = np.ones(lanes, bool)
        for i in range(PERTURBATIONS):
            moved = _nudged_mesh(mesh, nudge) if i % 2 else mesh
            other = solve(moved, jnp.asarray(_nudged(f32["P"], nudge)), jnp.asarray(_nudged(f32["L"], nudge)),
                          eta=eta, method=method, features=None)
            stable &= np.asarray(other.status) == np.asarray(sol.status)
        stable &= _ties_agree(mesh, P, L, start, sol.status, eta, method)
        D, D_valid, E = _transport(mesh, sol, P, L, jnp.asarray(f32["receiver_normal"]),
                                   jnp.asarray(f32["intensity"]), jnp.asarray(f32["sigma_t"]), eta)
        # D's and E's float32 error near each lane's point: a lane where they cancel (near a
        # caustic) gets its own wider tolerance, measured (conformance: `D_err`, `E_err`).
        nudged = _nudged_points(np.asarray(sol.barycentric))
        transport_args = (f32["P"], f32["L"], f32["receiver_normal"], f32["intensity"], f32["sigma_t"], eta)
        D32_k, E32_k = _transport_at(mesh, np.asarray(sol.triangle), nudged, *transport_args)
    x64 = {k: v.astype(np.float64) for k, v in f32.items()}
    with precision("float64"):
        mesh64 = _mesh(V32.astype(np.float64), np.asarray(mesh.faces), N32.astype(np.float64), mesh.grid, "float64")
        P64, L64 = jnp.asarray(x64["P"]), jnp.asarray(x64["L"])
        ref = solve(mesh64, P64, L64, eta=eta, method=_reference_method(method), features=None)
        found = np.asarray(sol.status) == Status.FOUND
        face32 = np.maximum(np.asarray(sol.triangle), 0)
        V, N = mesh64.triangle(jnp.asarray(face32))
        ab32 = jnp.asarray(np.asarray(sol.barycentric), jnp.float64)
        slope = np.asarray(_df_ds(V, N, P64, L64, ab32, eta)) if is_walk else None
        polish = None if is_walk else _polish_distance(mesh64, sol, P64, L64, eta, method)
        D64_k, E64_k = _transport_at(mesh64, np.asarray(sol.triangle), nudged, *transport_args)
        D64, _, E64 = _transport(mesh64, jax.tree.map(lambda x: x.astype(jnp.float64)
                                                      if jnp.issubdtype(x.dtype, jnp.floating) else x, sol),
                                 P64, L64, jnp.asarray(x64["receiver_normal"]), jnp.asarray(x64["intensity"]),
                                 jnp.asarray(x64["sigma_t"]), eta)
    face_ref = np.asarray(ref.triangle)
    has_ref = face_ref >= 0
    angle = np.full(lanes, -1.0)
    if has_ref.any():
        angle[has_ref] = refraction_angle_error(mesh64, face_ref[has_ref], np.asarray(ref.barycentric)[has_ref],
                                                x64["P"][has_ref], x64["L"][has_ref], eta)
    # Nor one where refract's float32 rounding at the solution (eta^2 eps / sqrt(k), math.md §1)
    # exceeds tol: there float32 cannot decide |f| <= tol (near the critical angle, P on the
    # surface). The point: the float64 reference's solution, else the testbed's point.
    ref_found = np.asarray(ref.status) == Status.FOUND
    where = np.where(ref_found, face_ref, np.asarray(sol.triangle))
    at = np.where(ref_found[:, None], np.asarray(ref.barycentric, np.float64), np.asarray(sol.barycentric, np.float64))
    bound = np.zeros(lanes)
    has = where >= 0
    if has.any():
        bound[has] = refraction_rounding_bound(NumpyMesh.from_mesh(mesh64), where[has], at[has], x64["P"][has], eta,
                                               np.float32)
    # Nor (the walk) one whose conic contains an edge of its start triangle to float32
    # resolution (a line conic along a grid line of a flat pool): that edge's quadratic is
    # rounding noise, and so is the root the walk reads on it (XLA's fused multiply-adds and
    # a port's separate ones put it far apart on the same edge: docs/export.md "Scenes").
    on_edge = np.zeros(lanes, bool)
    if is_walk:
        with precision("float64"):
            V0, N0 = mesh64.triangle(jnp.asarray(np.maximum(np.asarray(start.face), 0)))
            coef0 = conic_coefficients(V0, N0, P64, L64)
            quad = np.abs(np.asarray(edge_quadratics(coef0))).max(-1)
            scale0 = np.abs(np.asarray(coef0)).max(-1)
        on_edge = np.asarray(start.found) & np.any(quad <= 64 * float(np.finfo(np.float32).eps) * scale0[:, None], -1)
    # Nor one whose receiver lies within float32's rounding of the surface at its start or end
    # point: w_P = (P - M) / |P - M| is then rounding noise (its error eps (|P| + |M|) / |P - M|
    # exceeds tol), and so is every decision taken from it (`stress_p_near_surface`).
    with precision("float64"):
        V0s, _ = mesh64.triangle(jnp.asarray(np.maximum(np.asarray(start.face), 0)))
        M_start = np.asarray(barycentric_point(V0s, jnp.asarray(np.asarray(start.barycentric), jnp.float64)))
    eps32 = float(np.finfo(np.float32).eps)
    near_P = np.zeros(lanes, bool)
    for M_x, has_x in ((M_start, np.asarray(start.found)), (np.asarray(sol.point, np.float64), found)):
        gap = np.linalg.norm(x64["P"] - M_x, axis=-1)
        scale = np.abs(x64["P"]).max(-1) + np.abs(M_x).max(-1)
        with np.errstate(divide="ignore"):
            near_P |= has_x & ~(eps32 * scale <= tol * gap)
    conditioned = stable & (bound <= tol) & ~on_edge & ~near_P
    M32 = np.asarray(sol.point, np.float64)
    rounding = 16 * float(np.finfo(np.float32).eps) * (np.abs(M32).max(-1) + 1)
    if slope is not None:  # the walk
        # Two points that both pass |f| <= tol lie within 2 tol / |df/ds| of each other along
        # the curve; SAFETY covers the curvature of f over that stretch. Plus float32 rounding.
        with np.errstate(divide="ignore"):
            M_tol = np.where(found & (slope > 0), SAFETY * 2 * tol / slope, np.inf) + rounding
        M_rule = ("where both FOUND: |M - M_port| <= M_tol per lane (2 tol / |df/ds| along the curve, "
                  f"times {SAFETY}, plus 16 float32 ulps of |M|)")
        polish_stats = {}
    else:
        assert polish is not None  # (the Newton's)
        M_tol = np.where(found, 2 * SAFETY * float(polish[found & conditioned].max(initial=0.0)), np.inf) + rounding
        M_rule = (f"where both FOUND: |M - M_port| <= M_tol per lane (2 x {SAFETY} x the largest distance, over "
                  "the conditioned FOUND lanes, of the testbed's float32 point from the float64 root the float64 "
                  "Newton polishes it to, plus 16 float32 ulps of |M|)")
        polish_stats = {"float32_point_to_float64_root_m": _stats(polish[found & conditioned])}
    M_tol = np.minimum(M_tol, np.float32(np.finfo(np.float32).max)).astype(np.float32)
    M_hi, M_lo = _split(np.asarray(ref.point, np.float64))

    g = mesh.grid
    cell_scene, cell_buffers = _cell_records(mesh, cells)
    scene_rec = {
        "n_vertices": [len(V32)], "n_faces": [len(data.faces)], "n_lanes": [lanes], "has_grid": [int(g is not None)],
        "grid_nx": [g.nx if g else 0], "grid_ny": [g.ny if g else 0], "grid_x0": [g.x0 if g else 0.0],
        "grid_y0": [g.y0 if g else 0.0], "grid_dx": [g.dx if g else 0.0], "grid_dy": [g.dy if g else 0.0],
        "grid_x1": [g.x0 + g.nx * g.dx if g else 0.0], "grid_y1": [g.y0 + g.ny * g.dy if g else 0.0],
        "z_min": [V32[:, 2].min()], "z_max": [V32[:, 2].max()], "tol": [tol],
        "max_steps": [method.max_steps if is_walk else method.max_patches],
        "bracket": [BRACKETS[method.bracket] if is_walk else 0],
        "ellipse_samples": [method.ellipse_samples if is_walk else 0],
        **cell_scene, "solver": [SOLVERS[solver]], "initial_step": [0.0 if is_walk else method.initial_step],
    }
    faces = np.asarray(mesh.faces)
    lane_rec = {
        **f32, "eta": np.full(lanes, eta),
        "start_face": np.asarray(start.face), "start_ab": np.asarray(start.barycentric),
        "start_found": np.asarray(start.found).astype(np.uint32),
        "face": np.asarray(sol.triangle), "ab": np.asarray(sol.barycentric), "M": np.asarray(sol.point),
        "status": np.asarray(sol.status), "crossed": np.asarray(sol.crossed), "iterations": np.asarray(sol.iterations),
        "residual": np.asarray(sol.residual), "D": D, "D_valid": D_valid, "E": E,
        "M_ref": M_hi, "M_ref_lo": M_lo, "face_ref": face_ref,
        "ab_ref": np.asarray(ref.barycentric, np.float64),
        "status_ref": np.asarray(ref.status), "angle_error": angle, "M_tol": M_tol,
        "D_err": np.where(found, _lane_error(D32_k, D64_k), 0.0),
        "E_err": np.where(found, _lane_error(E32_k, E64_k), 0.0),
        "conditioned": conditioned.astype(np.uint32),
        "case_tag": data.case,
    }
    buffers, raw = pack_scene({
        "scene": scene_rec, "vertices": {"position": V32, "normal": N32},
        "faces": {"v": faces, "neighbor": np.asarray(mesh.neighbors), "neighbor_edge": np.asarray(mesh.neighbor_edge)},
        "lanes": lane_rec, **cell_buffers})

    def rel_err(a32, a64):  # over the conditioned lanes: near TIR D -> 0 and its relative error explodes
        keep = found & conditioned & (np.abs(a64) > 0)
        return np.abs(a32[keep].astype(np.float64) - a64[keep]) / np.abs(a64[keep])

    err_D, err_E = rel_err(D, np.asarray(D64)), rel_err(E, np.asarray(E64))
    statuses = np.asarray(sol.status)
    from .._version import __version__

    if is_walk:
        options = {"method": "walk", "dtype": "float32", "tol": tol, "max_steps": method.max_steps,
                   "bracket": method.bracket, "ellipse_samples": method.ellipse_samples}
        conditioning_extra = (", and the conic contains no edge of the start triangle to float32 resolution")
    else:
        options = {"method": "newton", "dtype": "float32", "tol": tol, "stepping": "one_step",
                   "constraint": "half_vector", "max_patches": method.max_patches,
                   "initial_step": method.initial_step, "min_step": MIN_BETA,
                   "max_projection_crossings": MAX_PROJECTION_CROSSINGS}
        conditioning_extra = ""
    options["start_points"] = (f"face cells ({cells.kind}: {cells.shape[0]} x {cells.shape[1]} cells of "
                               f"{np.asarray(cells.faces).shape[1]} faces per row), 2D DDA, first crossing")
    options["reference"] = {"dtype": "float64", "tol": float(_reference_method(method).tolerance(np.float64))}
    manifest = {
        "scene": spec.name,
        "solver": solver,
        "description": spec.description,
        "source": data.source,
        "equations": EQUATIONS if is_walk else NEWTON_EQUATIONS,
        "endianness": "little",
        "layout": "std430, vec3 padded to 16 bytes; buffers at multiples of 256 bytes",
        "buffers": buffers,
        "grid": None if g is None else {"nx": g.nx, "ny": g.ny, "x0": g.x0, "y0": g.y0, "dx": g.dx, "dy": g.dy,
                                        "layout": "vertex (i, j) = j (nx + 1) + i; cell (i, j) holds faces "
                                                  "2 (j nx + i) (v00 v10 v11) and 2 (j nx + i) + 1 (v00 v11 v01)"},
        "eta": eta,
        "options": options,
        "status": [{"code": int(s), "name": s.name, "meaning": s.message} for s in Status],
        "objective_status": [{"code": int(s), "name": s.name} for s in ObjectiveStatus],
        "tolerance": {
            "status": {"agreement": 0.999, "rule": "status equal on at least this fraction of the conditioned "
                                                   "lanes (conditioned = 1: the testbed's status does not change when "
                                                   "P and L move by one ulp and, every other try, the surface by one "
                                                   f"rounding, {PERTURBATIONS} random tries, nor from the faces that "
                                                   "tie with the start face, and "
                                                   "refract's float32 rounding bound at the solution is at most tol, "
                                                   "and w_P's float32 rounding, eps (|P| + |M|) / |P - M| at the start "
                                                   "and end points, is at most tol"
                                                   f"{conditioning_extra}); "
                                                   "the other lanes are decided by rounding and only reported"},
            "M": {"rule": M_rule, **polish_stats},
            "angle": {"rule": "every FOUND point of a port: refraction-angle error (float64, at the port's face "
                              "and barycentrics) <= tol + 4 x the first-order rounding bound of refract in float32"},
            "D": {"rel": SAFETY * max(float(err_D.max(initial=0.0)), 1e-6), "measured_float32": _stats(err_D),
                  "rule": "where a port is FOUND on a conditioned lane: |D - D64| <= max(rel, 4 D_err) |D64|, D64 "
                          "the float64 D at the port's point (rel: 4 x the testbed's float32 error at its own points, "
                          "conditioned lanes, at least 4e-6; D_err per lane: the testbed's largest relative float32 "
                          f"error at its point and at {len(NUDGES) - 1} points {TRANSPORT_NUDGE} float32 epsilons of "
                          "(a, b) around it, which is large where D cancels)"},
            "E": {"rel": SAFETY * max(float(err_E.max(initial=0.0)), 1e-6), "measured_float32": _stats(err_E),
                  "rule": "as D, for the irradiance"},
        },
        "summary": {
            "status": {s.name: int(np.sum(statuses == s)) for s in Status if np.any(statuses == s)},
            "status_ref": {s.name: int(np.sum(face_ref * 0 + np.asarray(ref.status) == s)) for s in Status
                           if np.any(np.asarray(ref.status) == s)},
            "found_M_vs_ref_m": _stats(np.linalg.norm(M32 - np.asarray(ref.point), axis=-1)[
                found & (np.asarray(ref.status) == Status.FOUND)]),
            "M_tol_m": _stats(M_tol[found]),
            "stable": int(stable.sum()),
            "conditioned": int(conditioned.sum()),
            "conic_on_an_edge": int(on_edge.sum()),
            "refract_rounding_above_tol": int(np.sum(bound > tol)),
            "P_within_rounding_of_surface": int(near_P.sum()),
        },
        "cases": {name: {"code": code, "count": int(np.sum(data.case == code))} for name, code in CASES.items()},
        "seed": seed,
        "version": {"format": FORMAT_VERSION, "caustics_jax": __version__},
    }
    return manifest, raw


#: The solvers a scene is exported for, by default (`write_scenes`).
SOLVER_NAMES = tuple(SOLVERS)


def scene_stem(scene: str, solver: str = "walk") -> str:
    """The file stem of a scene file: `<scene>` for the walk, `<scene>.<solver>` otherwise
    (`wavy_gentle.newton.json`)."""
    return scene if solver == "walk" else f"{scene}.{solver}"


def write_scenes(out, specs, lanes: int, seed: int, solvers=SOLVER_NAMES, newton: Newton | None = None) -> list:
    """Write `<stem>.json` and `<stem>.bin` per scene of `specs` (`SceneSpec`s: registered
    ones or a mesh file's, `scene_cases.mesh_file_scene`) and per solver of `solvers`
    (`scene_stem`; the Newton's options `newton`, default `NEWTON`), and `caustics_scene.h`,
    into the existing directory `out`; returns the paths written."""
    import json
    from pathlib import Path

    from .scene_records import scene_c_header

    out = Path(out)
    written = []
    for spec in specs:
        for solver in solvers:
            stem = scene_stem(spec.name, solver)
            manifest, raw = export_scene(spec, lanes, seed, solver=solver, newton=newton)
            (out / f"{stem}.json").write_text(json.dumps(manifest, indent=1) + "\n")
            (out / f"{stem}.bin").write_bytes(raw)
            written += [out / f"{stem}.json", out / f"{stem}.bin"]
    (out / "caustics_scene.h").write_text(scene_c_header())
    written.append(out / "caustics_scene.h")
    return written
