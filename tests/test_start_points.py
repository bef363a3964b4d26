"""Properties of start_points: on the segment, inside the face, the first crossing from P."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import caustics_jax as cj
from caustics_jax import barycentric_point
from caustics_jax.accel.start_points import build_bvh, start_points
from caustics_jax.surface.mesh import SurfaceMesh
from caustics_jax.surface.scenes import flat_pool, lagoon, wavy_pool
from caustics_jax.testing import oracle

DTYPES = [jnp.float32, jnp.float64]
N_RAYS = 160

# Steep, short waves and oblique segments, so many segments cross the surface 2-3 times.
SCENES = {
    "steep_wavy": wavy_pool(1000, seed=11, amplitude=0.25, wavelength=(0.3, 0.9)),
    "gentle_wavy": wavy_pool(1000, seed=12),
    "choppy": wavy_pool(1000, seed=13, amplitude=0.2, wavelength=(0.4, 1.0), choppiness=0.6),
    "lagoon": lagoon(1000, seed=14, amplitude=0.2, wavelength=(0.4, 1.0)),
}
GRID_SCENES = ["steep_wavy", "gentle_wavy"]
BVH = {name: build_bvh(s.surface) for name, s in SCENES.items()}

# Distance from M0 to the segment relative to the segment length, and |M0 - M0_ref| over
# the scene size (2.1 m half width), both times |cos| of the angle between the segment and
# the face normal: a grazing segment's crossing is ill-conditioned by 1/|cos| (a float32
# segment at cos = 0.006 measured 3.7e-6 unscaled). Measured maxima of the scaled errors
# over seeds 0-47, both paths: float32 1.2e-7 / 1.6e-7, float64 2.2e-16 / 5.5e-16. Bounds
# keep >= 12x margin.
ON_SEGMENT_TOL = {jnp.float32: 2e-6, jnp.float64: 4e-15}
POINT_TOL = {jnp.float32: 2e-6, jnp.float64: 8e-15}


def _segments(seed, scene, n=N_RAYS):
    """Receivers under the water, lights above or (a tenth) below, many oblique."""
    rng = np.random.default_rng(seed)
    V = np.asarray(scene.surface.vertices)
    lo, hi = V[:, :2].min(0), V[:, :2].max(0)
    P = np.concatenate([rng.uniform(lo, hi, (n, 2)), rng.uniform(-1.0, -0.3, (n, 1))], -1)
    L = np.concatenate([rng.uniform(2 * lo, 2 * hi, (n, 2)), rng.uniform(0.4, 4.0, (n, 1))], -1)
    below = rng.random(n) < 0.1
    L[below, 2] = -0.5
    return P, L


def _reference(mesh, P, L):
    """First crossing by brute force in float64, written independently of the package:
    ray-plane intersection, then barycentrics from the 2x2 normal equations."""
    V = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)]
    V0, e1, e2 = V[:, 0], V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
    n = np.cross(e1, e2)
    d = L - P
    den = d @ n.T  # (rays, faces)
    num = np.einsum("fk,rfk->rf", n, V0[None] - P[:, None])
    ok = np.abs(den) > 1e-300
    s = np.where(ok, num / np.where(ok, den, 1), np.inf)
    X = P[:, None] + s[..., None] * d[:, None] - V0[None]
    g11, g12, g22 = np.sum(e1 * e1, -1), np.sum(e1 * e2, -1), np.sum(e2 * e2, -1)
    r1, r2 = np.sum(X * e1, -1), np.sum(X * e2, -1)
    det = g11 * g22 - g12**2
    a, b = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
    inside = ok & oracle.inside_triangle(np.stack([a, b], -1), 1e-12) & (s >= 0) & (s <= 1)
    s = np.where(inside, s, np.inf)
    found = np.isfinite(s.min(1))
    s_first = np.where(found, s.min(1), 0)
    # Second crossing parameter: how well separated the first one is.
    s_sorted = np.sort(s, axis=1)
    return found, P + s_first[:, None] * d, s_sorted


def _cos_to_face(mesh, face, d):
    n = np.asarray(mesh.face_normals, np.float64)[np.maximum(np.asarray(face), 0)]
    return np.abs(np.sum(n * d, -1)) / np.linalg.norm(d, axis=-1)


def _point(mesh, sp):
    V, _ = mesh.triangle(sp.face)
    return np.asarray(barycentric_point(V, sp.barycentric), np.float64)


@pytest.mark.parametrize("method", ["grid", "cells", "general"])
@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**31 - 1))
def test_start_point_lies_on_the_segment_inside_its_face_and_is_the_first_crossing(
    method, dtype, seed
):
    names = GRID_SCENES if method == "grid" else sorted(SCENES)
    name = names[seed % len(names)]
    scene = SCENES[name]
    mesh = scene.surface.astype(dtype)
    bvh = jax.tree_util.tree_map(
        lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x, BVH[name]
    )
    P, L = _segments(seed, scene)
    sp = start_points(mesh, P.astype(dtype), L.astype(dtype), method=method, bvh=bvh)
    assert sp.barycentric.dtype == dtype and sp.face.dtype == jnp.int32
    found = np.asarray(sp.found)
    face = np.asarray(sp.face)
    ab = np.asarray(sp.barycentric)
    assert np.all((face >= 0) == found)
    assert np.all(np.isfinite(ab))
    # Inside the face: exactly (the kernel projects into the closed triangle).
    assert np.all(ab[found] >= 0) and np.all(ab[found].sum(-1) <= 1)
    assert np.all(ab[~found] == 0)
    # On the segment P -> L.
    M = _point(mesh, sp)
    Pd, Ld = P.astype(dtype).astype(np.float64), L.astype(dtype).astype(np.float64)
    d = Ld - Pd
    s = np.sum((M - Pd) * d, -1) / np.sum(d * d, -1)
    cos = _cos_to_face(mesh, sp.face, d)
    off = np.linalg.norm(M - Pd - s[:, None] * d, axis=-1) / np.linalg.norm(d, axis=-1)
    assert np.max((off * cos)[found], initial=0) <= ON_SEGMENT_TOL[dtype]
    assert np.all((s[found] >= -ON_SEGMENT_TOL[dtype]) & (s[found] <= 1 + ON_SEGMENT_TOL[dtype]))
    # The first crossing from P, against an independent float64 brute force. Segments whose
    # first and second crossings are closer than the float32 resolution may swap them.
    ref_found, ref_M, s_sorted = _reference(mesh, Pd, Ld)
    np.testing.assert_array_equal(found, ref_found)
    gap = np.diff(np.where(ref_found[:, None], s_sorted[:, :2], 0), axis=1)[:, 0]
    clear = ref_found & ~(gap <= 1e-4)  # a gap of inf - s (single crossing) is clear
    err = np.abs(M - ref_M) * cos[:, None]
    assert np.max(err[clear], initial=0) <= POINT_TOL[dtype] * 2.1


def test_the_scenes_above_do_cross_more_than_once():
    # The "first crossing" property above is only tested if segments cross several times.
    P, L = _segments(0, SCENES["steep_wavy"], n=512)
    found, _, s_sorted = _reference(SCENES["steep_wavy"].surface, P, L)
    assert np.sum(np.isfinite(s_sorted[:, 1])) >= 20  # measured: 42 of 512
    assert 0.5 < found.mean() < 0.98  # measured 0.84: some miss (past the edge, or L below)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**31 - 1))
def test_grid_and_general_paths_agree(dtype, seed):
    name = GRID_SCENES[seed % 2]
    mesh = SCENES[name].surface.astype(dtype)
    P, L = _segments(seed, SCENES[name])
    P, L = P.astype(dtype), L.astype(dtype)
    fast = start_points(mesh, P, L, method="grid")
    general = start_points(mesh, P, L, method="general")
    np.testing.assert_array_equal(fast.found, general.found)
    cos = _cos_to_face(mesh, fast.face, (L - P).astype(np.float64))
    err = np.abs(_point(mesh, fast) - _point(mesh, general)) * cos[:, None]
    assert np.max(err, initial=0) <= POINT_TOL[dtype] * 2.1


@pytest.mark.parametrize("method", ["grid", "general"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_segments_through_grid_vertices_and_edges_are_not_lost_between_faces(method, dtype):
    mesh = flat_pool(800).surface.astype(dtype)
    g = mesh.grid
    i = np.arange(3, 13)
    # Vertical segments through vertices, through cell diagonals, and along a cell wall.
    x = np.concatenate([g.x0 + i * g.dx, g.x0 + (i + 0.5) * g.dx, g.x0 + i * g.dx])
    y = np.concatenate([g.y0 + i * g.dy, g.y0 + (i + 0.5) * g.dy, g.y0 + (i + 0.3) * g.dy])
    P = np.stack([x, y, np.full_like(x, -1.0)], -1).astype(dtype)
    L = P + np.array([0, 0, 3.0], dtype)
    sp = start_points(mesh, P, L, method=method)
    assert np.all(np.asarray(sp.found))
    np.testing.assert_allclose(_point(mesh, sp), P * [1, 1, 0], atol=4 * g.dx * 1e-6)


@pytest.mark.parametrize("method", ["grid", "general"])
def test_found_is_false_where_the_segment_does_not_cross(method):
    mesh = SCENES["gentle_wavy"].surface
    P = np.array([[0.1, 0.2, -1.0], [0.1, 0.2, -1.0], [9.0, 9.0, -1.0], [0.3, 0.3, -0.5],
                  [0.0, 0.0, 1.0]])  # fmt: skip
    L = np.array([[0.5, 0.5, -0.2],  # both under the water
                  [0.1, 0.2, -1.0],  # zero length
                  [9.0, 9.0, 3.0],  # beside the pool
                  [0.3, 0.3, -0.5 + 1e-300],  # degenerate, under water
                  [1.0, 1.0, 2.0]])  # fmt: skip  # both above
    sp = start_points(mesh, P, L, method=method)
    assert not np.any(np.asarray(sp.found))
    np.testing.assert_array_equal(sp.face, -1)
    assert np.all(np.asarray(sp.barycentric) == 0)


def test_batch_shapes_broadcast_and_the_core_is_jittable():
    mesh = SCENES["gentle_wavy"].surface
    P, L = _segments(3, SCENES["gentle_wavy"])  # N_RAYS = 160 (shapes compiled above)
    sp = start_points(mesh, P.reshape(10, 16, 3), L[0])
    assert sp.face.shape == (10, 16) and sp.barycentric.shape == (10, 16, 2)
    flat = start_points(mesh, P, np.broadcast_to(L[0], P.shape))
    np.testing.assert_array_equal(np.asarray(sp.face).ravel(), flat.face)
    # Inside a user's jit (traced P, L): same answer, validation of values skipped.
    jitted = jax.jit(lambda m, P, L: start_points(m, P, L))(mesh, P, L)
    direct = start_points(mesh, P, L)
    np.testing.assert_array_equal(jitted.face, direct.face)
    # Heights changed in place (animation): the grid path follows without a rebuild.
    moved = SurfaceMesh(mesh.vertices.at[:, 2].add(0.1), mesh.faces, mesh.normals,
                        mesh.face_normals, mesh.neighbors, mesh.neighbor_edge,
                        mesh.grid)  # fmt: skip
    a = start_points(moved, P, L, method="grid")
    b = start_points(moved, P, L, method="general")
    np.testing.assert_array_equal(a.found, b.found)
    np.testing.assert_allclose(_point(moved, a), _point(moved, b), atol=1e-12)
    assert np.all(_point(moved, a)[np.asarray(a.found), 2] > 0.1 - 0.031)


def test_bad_inputs_raise_before_any_jit_work():
    mesh = SCENES["gentle_wavy"].surface
    P = np.zeros((4, 3)) - [0, 0, 1]
    L = P + [0, 0, 2]
    with pytest.raises(ValueError, match=r"P has NaN or Inf at \(flattened\) rows \[2\]"):
        start_points(mesh, np.where(np.arange(4)[:, None] == 2, np.nan, P), L)
    with pytest.raises(ValueError, match=r"L has NaN or Inf at \(flattened\) rows \[0, 3\]"):
        start_points(mesh, P, np.where(np.isin(np.arange(4), [0, 3])[:, None], np.inf, L))
    with pytest.raises(ValueError, match="float32 but the mesh is float64"):
        start_points(mesh, P.astype(np.float32), L)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        start_points(mesh, P[:, :2], L)
    with pytest.raises(ValueError, match="do not broadcast"):
        start_points(mesh, P, L[:3])
    with pytest.raises(ValueError, match="needs a regular heightfield grid"):
        start_points(SCENES["lagoon"].surface, P, L, method="grid")
    with pytest.raises(ValueError, match="method must be"):
        start_points(mesh, P, L, method="bvh")


# --------------------------------------------------------------------------- issue 14 class 5
# Crossings exactly on a cell wall, an edge or a vertex. The mechanism: the segment-triangle
# test accepted crossings 16 eps (barycentric units) outside a face, while the barycentrics
# carry a rounding error of eps |coordinates| / (triangle height): on the 1M-triangle pool
# (6 mm cells, 2-5 m coordinates) 300-1000x more, so a crossing on a shared edge could be
# rejected by every face around it, and XLA's rounding of a lane differs with the batch
# shape, so it was found alone and lost in a batch. A 6 x 6 grid of 2 mm cells 2 m from
# the origin has the same ratio; with the old tolerance (crossing.C_ROUND = 0) 44 of these
# 512 float32 segments (34 float64) were lost by the grid path, 41 (26) by the binned cells
# and 38 (26) by the BVH.


def _planted_on_walls(dtype, n=512, seed=0, nx=6, cell=2e-3, x0=2.0):
    """A small heightfield far from the origin and segments whose crossing is exactly on a
    vertex, a cell wall (x or y) or a cell diagonal; 30% of them vertical. Slopes are below
    0.2 and segments steeper than 1/2, so each segment crosses the surface once."""
    rng = np.random.default_rng(seed)
    H = 0.05 * cell * rng.uniform(-1, 1, (nx + 1, nx + 1))
    mesh = SurfaceMesh.from_heightfield(H, x0=x0, y0=-x0, dx=cell, dy=cell, dtype=dtype)
    V = np.asarray(mesh.vertices, np.float64)
    i, j = rng.integers(0, nx, n), rng.integers(0, nx, n)
    kind, t = rng.integers(0, 4, n), rng.uniform(0, 1, (n, 1))
    v00, v10 = V[j * (nx + 1) + i], V[j * (nx + 1) + i + 1]
    v01, v11 = V[(j + 1) * (nx + 1) + i], V[(j + 1) * (nx + 1) + i + 1]
    M = np.select([kind[:, None] == k for k in range(4)],
                  [v00, v00 + t * (v01 - v00), v00 + t * (v10 - v00), v00 + t * (v11 - v00)])  # fmt: skip
    w = np.concatenate([rng.uniform(-1, 1, (n, 2)), rng.uniform(1.5, 3, (n, 1))], -1)
    w[rng.random(n) < 0.3, :2] = 0
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    P = M - rng.uniform(0.2, 1.5, (n, 1)) * w
    L = M + rng.uniform(0.5, 3.0, (n, 1)) * w
    return mesh, P.astype(dtype), L.astype(dtype), M


@pytest.mark.parametrize("method", ["grid", "cells", "general"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_crossings_on_cell_walls_edges_and_vertices_are_found(method, dtype):
    mesh, P, L, M = _planted_on_walls(dtype)
    sp = start_points(mesh, P, L, method=method)
    assert np.all(np.asarray(sp.found))
    # The point is the planted one within the rounding of the coordinates (2 m): measured
    # max 2.4e-7 m (float32) and 4.4e-16 m (float64) on every path.
    bound = {jnp.float32: 4e-6, jnp.float64: 8e-15}[dtype]
    assert np.max(np.abs(_point(mesh, sp) - M)) <= bound


def _lanes_alone(mesh, P, L, method):
    """Each lane's start point computed in a batch of one (one compile)."""
    out = [start_points(mesh, P[k : k + 1], L[k : k + 1], method=method) for k in range(len(P))]
    return (np.concatenate([np.asarray(o.found) for o in out]),
            np.concatenate([_point(mesh, o) for o in out]))  # fmt: skip


@pytest.mark.parametrize("dtype", DTYPES)
@settings(max_examples=4)
@given(seed=st.integers(0, 2**31 - 1))
def test_a_lane_gets_the_same_start_point_alone_in_any_batch_and_on_every_path(dtype, seed):
    # 48 lanes (wall, edge and vertex crossings, and random segments that may miss) solved
    # alone, in a batch of 48, in the same batch shuffled (each lane at another position, so
    # XLA's vector and remainder code paths see other lanes) and by the BVH.
    mesh, P, L, _ = _planted_on_walls(dtype, n=24, seed=seed)
    rng = np.random.default_rng(seed)
    Q = rng.uniform([2.0, -2.0, -0.01], [2.012, -1.988, 0.01], (24, 3))
    R = Q + rng.normal(size=(24, 3)) * [0.01, 0.01, 0.05]
    P, L = np.concatenate([P, Q.astype(dtype)]), np.concatenate([L, R.astype(dtype)])
    perm = rng.permutation(len(P))
    batch = start_points(mesh, P, L, method="grid")
    shuffled = start_points(mesh, P[perm], L[perm], method="grid")
    general = start_points(mesh, P, L, method="general")
    found_alone, M_alone = _lanes_alone(mesh, P, L, "grid")
    found = np.asarray(batch.found)
    assert found.sum() >= 24
    np.testing.assert_array_equal(found_alone, found)
    np.testing.assert_array_equal(np.asarray(shuffled.found)[np.argsort(perm)], found)
    np.testing.assert_array_equal(np.asarray(general.found), found)
    # Same crossing within rounding: where a crossing lies on a shared edge, rounding may
    # pick either face, with the same point (measured max difference 0 in these runs).
    bound = {jnp.float32: 4e-6, jnp.float64: 8e-15}[dtype]
    M = _point(mesh, batch)
    for other in (M_alone, _point(mesh, shuffled)[np.argsort(perm)], _point(mesh, general)):
        assert np.max(np.abs(other - M)[found], initial=0) <= bound


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_triangle_crossing_from_a_face_frame_table_equals_the_one_from_vertices(dtype):
    """The cell traversal gathers `face_frames` computed once per call; the test must give
    what the vertices give (same fields), hits and misses alike."""
    from caustics_jax.math.crossing import face_frames, triangle_crossing

    rng = np.random.default_rng(3)
    V = rng.normal(size=(512, 3, 3)).astype(dtype)
    P = rng.normal(size=(512, 3)).astype(dtype)
    d = (V.mean(1) - P + 0.3 * rng.normal(size=(512, 3))).astype(dtype)  # about half hit
    with cj.precision(dtype):
        a = triangle_crossing(jnp.asarray(P), jnp.asarray(d), jnp.asarray(V))
        table = face_frames(jnp.asarray(V))
        b = triangle_crossing(jnp.asarray(P), jnp.asarray(d), table)
    assert 0.2 < float(np.mean(np.asarray(a.inside))) < 0.8
    for field in a._fields:
        np.testing.assert_array_equal(np.asarray(getattr(a, field)), np.asarray(getattr(b, field)), err_msg=field)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_long_cell_lists_continue_in_extra_rows_and_lose_no_face(dtype, monkeypatch):
    """`bin_faces` rows hold all but the longest 0.1% of the cell lists (`row_width`); the
    rest continue in chained rows. Each cell's chain lists the faces of the single-row
    table, and vertical and oblique segments through the vertices of those cells (where
    the valence is highest) find the BVH's crossings."""
    import caustics_jax.accel.face_cells as fc

    mesh = lagoon(4000, seed=0, dtype=dtype).surface
    cells = fc.bin_faces(mesh)
    monkeypatch.setattr(fc, "LONG_CELLS", 0.0)
    single = fc.bin_faces(mesh)
    faces, more, owner = (np.asarray(x) for x in (cells.faces, cells.more, cells.owner))
    n_cells = cells.shape[0] * cells.shape[1]
    assert faces.shape[1] < single.faces.shape[1] and np.sum(more >= 0) >= 1  # the lagoon has long lists
    assert np.array_equal(owner[:n_cells], np.arange(n_cells)) and np.all(owner[more[more >= 0]] == owner[more >= 0])
    long_cells = []
    for c in range(n_cells):
        chain, row = [], c
        while row >= 0:
            chain += [f for f in faces[row] if f >= 0]
            row = more[row]
        expected = [f for f in np.asarray(single.faces)[c] if f >= 0]
        assert chain == expected, c
        if more[c] >= 0:
            long_cells.append(c)
    # Segments through every vertex of the faces listed in the long cells.
    V = np.asarray(mesh.vertices)
    verts = np.unique(np.asarray(mesh.faces)[[f for c in long_cells for f in np.asarray(single.faces)[c] if f >= 0]])
    top = V[verts] + np.array([0.0, 0.0, 2.0])
    P = np.concatenate([V[verts] - [0.0, 0.0, 1.0], V[verts] - [0.4, 0.3, 1.0]]).astype(dtype)
    L = np.concatenate([top, top + [0.4, 0.3, 0.0]]).astype(dtype)
    binned = start_points(mesh, P, L, accel=cells)
    general = start_points(mesh, P, L, method="general")
    np.testing.assert_array_equal(binned.found, general.found)
    assert np.all(np.asarray(binned.found))
    np.testing.assert_allclose(_point(mesh, binned), _point(mesh, general), atol=1e-5 if dtype == "float32" else 1e-12)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name, accel", [("steep_wavy", "own"), ("lagoon", "own"), ("gentle_wavy", "bvh")])
def test_solves_block_program_finds_the_start_points_of_start_points(name, accel, dtype):
    """`solve` finds each block's start points in a block program (`blocks.on_devices`,
    compiled with the project's XLA options): the same crossings as `start_points` on grid
    cells, binned cells and a BVH, and the options reach that program."""
    from caustics_jax.runtime import compilation
    from caustics_jax.solvers._solve import _block_start_points

    scene = SCENES[name]
    prep = cj.prepare(scene.surface.astype(dtype)).local
    if accel == "bvh":
        prep = prep.with_accel(build_bvh(prep.mesh))
    P, L = (jnp.asarray(x, dtype) for x in _segments(3, scene, n=256))
    ref = prep.start_points(P, L)
    got = _block_start_points(prep, P, L)
    found = np.asarray(ref.found)
    assert found.sum() > 100
    np.testing.assert_array_equal(np.asarray(got.found), found)
    # The same crossing within rounding (the two programs' vector code may differ; measured
    # identical on 32,768 lanes of three scenes); a crossing on a shared edge may pick either face.
    M_ref, M = _point(prep.mesh, ref), _point(prep.mesh, got)
    assert np.max(np.abs(M - M_ref)[found], initial=0) <= {jnp.float32: 4e-6, jnp.float64: 8e-15}[dtype]
    if jax.default_backend() == "cpu":
        with compilation.using_xla_options({"xla_no_such_option_here": True}):
            with pytest.raises(Exception, match="xla_no_such_option_here"):
                _block_start_points(prep, P, L)
