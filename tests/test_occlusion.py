"""segment_blocked: planted blocked and unblocked segments on every acceleration structure, in
float32 and float64, an independent brute force, and the API contract."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax.accel.bvh import build_bvh
from caustics_jax.accel.occlusion import segment_blocked
from caustics_jax.accel.prepared import prepare
from caustics_jax.surface.scenes import wavy_pool
from caustics_jax.testing.meshes import jittered_grid

DTYPES = [jnp.float32, jnp.float64]
N = 256  # segments per kind (one lane bucket: one compile per structure and dtype)


def _surface(kind, dtype):
    """A gentle wavy pool (grid cells), the same grid jittered (binned cells), or the pool
    with its BVH forced (general path); `(prepared, accel)`."""
    if kind == "bins":
        mesh = jittered_grid(800, 0.2, seed=4, dtype=dtype)
    else:
        mesh = wavy_pool(800, seed=4).surface.astype(dtype)
    prep = prepare(mesh)
    return prep, (build_bvh(mesh) if kind == "bvh" else None)


def _surface_points(mesh, rng, n):
    """Points on the surface: a third inside faces, a third on edges, a third on vertices;
    with the face each lies on."""
    V = np.asarray(mesh.vertices, np.float64)
    F = np.asarray(mesh.faces)
    face = rng.integers(0, len(F), n)
    ab = rng.dirichlet([1, 1, 1], n)[:, :2]
    where = rng.integers(0, 3, n)
    ab[where == 1, 1] = 0  # on edge V0 V1
    ab[where == 2] = [0, 0]  # on vertex V0
    T = V[F[face]]
    return T[:, 0] + ab[:, :1] * (T[:, 1] - T[:, 0]) + ab[:, 1:] * (T[:, 2] - T[:, 0]), face


def _steep_up(mesh, rng, n):
    """Unit directions rising more than twice as steeply as the steepest face: from a
    point on a heightfield such a ray never meets the surface again (Lipschitz bound)."""
    n_f = np.asarray(mesh.face_normals, np.float64)
    max_slope = np.max(np.hypot(n_f[:, 0], n_f[:, 1]) / n_f[:, 2])
    xy = rng.normal(size=(n, 2))
    xy *= rng.uniform(0, 1 / (2 * max_slope + 1e-9), (n, 1)) / np.linalg.norm(xy, axis=-1, keepdims=True)
    w = np.concatenate([xy, np.ones((n, 1))], -1)
    w[: n // 4, :2] = 0  # a quarter vertical
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


@pytest.mark.parametrize("kind", ["grid", "bins", "bvh"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_planted_blocked_and_unblocked_segments(kind, dtype):
    prep, accel = _surface(kind, dtype)
    mesh = prep.mesh
    rng = np.random.default_rng(7)
    M, face = _surface_points(mesh, rng, N)
    w = _steep_up(mesh, rng, N)
    below = M - rng.uniform(0.2, 1.0, (N, 1)) * w
    above = M + rng.uniform(0.2, 3.0, (N, 1)) * w
    cast = lambda x: jnp.asarray(x, dtype)  # noqa: E731
    blocked = lambda A, B, **kw: np.asarray(segment_blocked(prep, cast(A), cast(B), accel=accel, **kw))  # noqa: E731
    # Through the surface at M (inside a face, on an edge or at a vertex): blocked.
    assert blocked(below, above).all()
    assert blocked(above, below).all()
    # From M up to the light, or from the receiver up to M: the touch at M is no blocker,
    # with or without naming M's face.
    for ends in ((M, above), (above, M), (below, M), (M, below)):
        assert not blocked(*ends).any()
        assert not blocked(*ends, exclude_face=face).any()
    # Both ends on the same side, away from the surface: never blocked.
    assert not blocked(above, above + [0.3, -0.2, 0.5]).any()


@pytest.mark.parametrize("dtype", DTYPES)
def test_exclude_face_and_end_tolerance_ignore_the_crossings_they_name(dtype):
    prep, _ = _surface("grid", dtype)
    mesh = prep.mesh
    rng = np.random.default_rng(8)
    V = np.asarray(mesh.vertices, np.float64)
    F = np.asarray(mesh.faces)
    face = rng.integers(0, len(F), N)
    T = V[F[face]]
    M = T.mean(1)  # face centroids: inside one face only
    w = _steep_up(mesh, rng, N)
    A, B = M - 0.05 * w, M + 0.95 * w  # the crossing at s = 0.05
    A, B = jnp.asarray(A, dtype), jnp.asarray(B, dtype)
    assert np.asarray(segment_blocked(prep, A, B)).all()
    assert not np.asarray(segment_blocked(prep, A, B, exclude_face=face)).any()
    assert np.asarray(segment_blocked(prep, A, B, exclude_face=(face + 1) % len(F))).all()
    assert not np.asarray(segment_blocked(prep, A, B, end_tolerance=0.06)).any()
    assert np.asarray(segment_blocked(prep, A, B, end_tolerance=0.04)).all()
    assert not np.asarray(segment_blocked(prep, B, A, end_tolerance=0.06)).any()


def _brute_force_blocked(mesh, A, B, margin):
    """Independent float64 brute force: the parameters in (0, 1) where A -> B meets each
    face's plane inside the face (numpy, every face); `(blocked, clear)` where `clear`
    marks segments whose crossings are all farther than `margin` from the ends and from
    every face edge (so rounding cannot decide them)."""
    V = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)]
    V0, e1, e2 = V[:, 0], V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
    n = np.cross(e1, e2)
    d = B - A
    den = d @ n.T
    s = np.einsum("fk,rfk->rf", n, V0[None] - A[:, None]) / np.where(den == 0, 1, den)
    X = A[:, None] + s[..., None] * d[:, None] - V0[None]
    g11, g12, g22 = np.sum(e1 * e1, -1), np.sum(e1 * e2, -1), np.sum(e2 * e2, -1)
    r1, r2 = np.sum(X * e1, -1), np.sum(X * e2, -1)
    det = g11 * g22 - g12**2
    a, b = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
    c = 1 - a - b
    on_segment = (den != 0) & (s > 0) & (s < 1)
    inside = on_segment & (a >= 0) & (b >= 0) & (c >= 0)
    near = on_segment & (np.minimum(np.minimum(a, b), c) > -margin) & (
        (np.minimum(np.minimum(a, b), c) < margin) | (s < margin) | (s > 1 - margin))
    return inside.any(1), ~near.any(1)


@pytest.mark.parametrize("kind", ["grid", "bins"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_blocked_agrees_with_a_brute_force_on_random_segments(kind, dtype):
    prep, _ = _surface(kind, dtype)
    mesh = prep.mesh
    rng = np.random.default_rng(9)
    V = np.asarray(mesh.vertices, np.float64)
    lo, hi = V.min(0), V.max(0)
    # Low, nearly horizontal segments over the waves: many cross them, several times.
    A = np.concatenate([rng.uniform(lo[:2], hi[:2], (N, 2)), rng.uniform(-0.05, 0.05, (N, 1))], -1)
    B = A + np.concatenate([rng.normal(0, 0.8, (N, 2)), rng.normal(0, 0.03, (N, 1))], -1)
    A, B = A.astype(dtype), B.astype(dtype)
    got = np.asarray(segment_blocked(prep, A, B))
    ref, clear = _brute_force_blocked(mesh, A.astype(np.float64), B.astype(np.float64), 1e-4)
    assert clear.mean() > 0.9 and 0.2 < ref[clear].mean() < 0.9
    np.testing.assert_array_equal(got[clear], ref[clear])


@pytest.mark.parametrize("dtype", DTYPES)
def test_blocked_runs_inside_jit_and_on_a_single_segment(dtype):
    prep, _ = _surface("grid", dtype)
    A = jnp.asarray([[0.1, 0.2, -0.5], [0.1, 0.2, 0.5]], dtype)
    B = jnp.asarray([[0.3, 0.1, 0.8], [0.3, 0.1, 0.8]], dtype)
    direct = segment_blocked(prep, A, B)
    traced = jax.jit(lambda A, B: segment_blocked(prep, A, B))(A, B)
    np.testing.assert_array_equal(direct, [True, False])
    np.testing.assert_array_equal(traced, direct)
    assert segment_blocked(prep, A[0], B[0]).shape == (1,)
    assert segment_blocked(prep.mesh, A[:0], B[:0]).shape == (0,)


def test_bad_input_is_refused_with_the_argument_named():
    prep, _ = _surface("grid", jnp.float64)
    A = np.zeros((4, 3))
    B = A + [0, 0, 1]
    with pytest.raises(ValueError, match=r"A must have shape \(N, 3\)"):
        segment_blocked(prep, A[:, :2], B)
    with pytest.raises(ValueError, match="B is float32 but the surface is float64"):
        segment_blocked(prep, A, B.astype(np.float32))
    with pytest.raises(ValueError, match="A has NaN or Inf"):
        segment_blocked(prep, np.where(A == 0, np.nan, A), B)
    with pytest.raises(ValueError, match="do not broadcast"):
        segment_blocked(prep, A, B[:3])
    with pytest.raises(ValueError, match=r"end_tolerance must be a number in \[0, 0.5\)"):
        segment_blocked(prep, A, B, end_tolerance=0.5)
    with pytest.raises(ValueError, match=r"exclude_face must be in \[-1, "):
        segment_blocked(prep, A, B, exclude_face=np.full(4, 10**6))
    with pytest.raises(ValueError, match=r"exclude_face must be None or \(4,\) integer"):
        segment_blocked(prep, A, B, exclude_face=np.zeros(3, int))
    with pytest.raises(ValueError, match="surface must be a SurfaceMesh or PreparedSurface"):
        segment_blocked("pool", A, B)


def test_a_far_surface_blocks_the_segments_it_blocks_near_the_origin():
    """`segment_blocked` and `path_visible` run on `prepare(mesh).local` (a far mesh moved
    near the origin): on a steep float32 wave 3 km away, 145 of 4000 segments had been
    judged otherwise than the same (rounded) segments near the origin, 16 at 300 m; now
    none."""
    from caustics_jax.transport.visibility import path_visible

    rng = np.random.default_rng(2)
    base = wavy_pool(2048, amplitude=0.1, n_waves=2, wavelength=(0.6, 0.9), dtype="float32").surface
    n = 4000
    A = np.c_[rng.uniform(-2, 2, (n, 2)), rng.uniform(0.0, 0.12, n)]
    B = A + np.c_[rng.normal(0, 1, (n, 2)), rng.uniform(0.0, 0.2, n)]
    t = np.array([3000.0, -3000.0, 20.0])
    far = base.translated(t)
    # the far scene's float32 segments, and the same rounded segments near the origin
    A_far, B_far = (A + t).astype(np.float32), (B + t).astype(np.float32)
    A_near, B_near = ((X.astype(np.float64) - t).astype(np.float32) for X in (A_far, B_far))
    near_blocked = np.asarray(segment_blocked(base, A_near, B_near))
    assert 0.2 < near_blocked.mean() < 0.5  # measured 0.33
    np.testing.assert_array_equal(np.asarray(segment_blocked(far, A_far, B_far)), near_blocked)
    # path_visible: P -> M -> L with L 3 m above M (both legs tested)
    up = np.float32(3.0)
    L_far, L_near = B_far + np.array([0, 0, up], np.float32), B_near + np.array([0, 0, up], np.float32)
    visible = path_visible(base, A_near, B_near, L_near)
    assert 0.3 < visible.mean() < 0.9
    np.testing.assert_array_equal(path_visible(far, A_far, B_far, L_far), visible)


def test_a_nan_segment_crosses_nothing_and_path_visible_refuses_it():
    """One NaN row had kept the cell and BVH traversals looping forever
    (`first_crossing`, `path_visible`); inside jit such a lane now crosses nothing, and
    `path_visible` refuses it at the boundary."""
    from caustics_jax.accel.start_points import first_crossing
    from caustics_jax.transport.visibility import path_visible

    pool = wavy_pool(512, dtype="float32").surface
    A = jnp.asarray([[0.1, 0.2, -1.0], [np.nan, 0.0, -1.0], [0.3, 0.1, -1.0]], "float32")
    B = jnp.asarray([[0.1, 0.2, 1.0], [0.0, 0.0, 1.0], [0.3, 0.1, 1.0]], "float32")
    jittered = jittered_grid(512, 0.2, dtype=np.float32)  # binned faces
    for kw in ({}, {"bvh": build_bvh(pool)}, {"accel": prepare(jittered).accel}):
        mesh = jittered if "accel" in kw else pool
        face, ab, found = (np.asarray(x) for x in first_crossing(mesh, A, B, **kw))
        np.testing.assert_array_equal(found, [True, False, True])
        assert face[1] == -1 and np.all(np.isfinite(ab))
    with pytest.raises(ValueError, match="NaN"):
        path_visible(pool, A, (A + B) / 2, B)
    with pytest.raises(ValueError, match="float64 but the mesh is float32"):
        path_visible(pool, np.asarray(A[::2], np.float64), (A[::2] + B[::2]) / 2, B[::2])


def test_path_visible_names_the_argument_it_refuses():
    """`path_visible` checks `P -> M` and `M -> L` as segments: an error in `M` names `M`
    (it had said "L has NaN" for a NaN in `M`, "P and L must have shape" for `M` (4, 2))."""
    from caustics_jax.transport.visibility import path_visible

    pool = wavy_pool(128, dtype="float32").surface
    P = np.tile(np.asarray([0.1, 0.2, -1.0], np.float32), (4, 1))
    L = P + np.float32(2.0) * np.asarray([0, 0, 1], np.float32)
    M = (P + L) / 2
    cases = [
        ((P, np.where(M == M[1], np.nan, M), L), r"^M has NaN or Inf"),
        ((P, M[:, :2], L), r"^P and M must have shape \(\.\.\., 3\)"),
        ((P, M, L[:, :2]), r"^M and L must have shape \(\.\.\., 3\)"),
        ((P, M.astype(np.float64), L), r"^M is float64 but the mesh is float32"),
        ((P, M, np.where(L == L[0], np.inf, L)), r"^L has NaN or Inf"),
    ]
    for args, match in cases:
        with pytest.raises(ValueError, match=match):
            path_visible(pool, *args)
