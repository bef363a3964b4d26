"""prepare(mesh): the start-point acceleration is chosen once per mesh, cached, and gives the
start points of the BVH reference path."""

import importlib

import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax import barycentric_point, solve
from caustics_jax.accel.bvh import FaceBVH
from caustics_jax.accel.face_cells import FaceCells
from caustics_jax.accel.prepared import prepare
from caustics_jax.accel.start_points import start_points
from caustics_jax.surface.mesh import SurfaceMesh
from caustics_jax.surface.scenes import lagoon, wavy_pool
from caustics_jax.testing.meshes import fan, jittered_grid

DTYPES = [jnp.float32, jnp.float64]
# Barycentric and point differences between the cell and BVH paths: measured max 3.3e-6 and
# 7.2e-7 m (float32, lagoon), 0 in float64; bounds 10x (float64: a few ulps).
AB_TOL = {jnp.float32: 3e-5, jnp.float64: 1e-13}
M_TOL = {jnp.float32: 7e-6, jnp.float64: 1e-14}


def test_prepare_picks_grid_cells_bins_or_the_bvh_once_per_mesh():
    pool = wavy_pool(1000, seed=0).surface
    user_grid = SurfaceMesh.from_arrays(np.asarray(pool.vertices), np.asarray(pool.faces))
    cases = [(pool, FaceCells, "grid"), (user_grid, FaceCells, "grid"),
             (jittered_grid(1000, 0.2), FaceCells, "bins"), (lagoon(1000, seed=0).surface, FaceCells, "bins"),
             (fan(), FaceBVH, None)]  # fmt: skip
    for mesh, kind, name in cases:
        accel = prepare(mesh).accel
        assert isinstance(accel, kind) and getattr(accel, "kind", None) == name
        assert prepare(mesh).accel is accel  # cached per mesh object
    assert user_grid.grid is None


def _lanes(mesh, n, seed):
    rng = np.random.default_rng(seed)
    V = np.asarray(mesh.vertices, np.float64)
    lo, hi = V.min(0), V.max(0)
    P = np.concatenate([rng.uniform(lo[:2], hi[:2], (n, 2)), rng.uniform(-1, -0.2, (n, 1))], -1)
    L = np.concatenate([rng.uniform(2 * lo[:2], 2 * hi[:2], (n, 2)), rng.uniform(0.3, 3, (n, 1))], -1)
    return P, L


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", ["jittered", "jittered_flat", "lagoon", "fan"])
def test_prepared_start_points_equal_the_bvh_path(dtype, name):
    mesh = {"jittered": lambda: jittered_grid(1000, 0.2, dtype=dtype),
            "jittered_flat": lambda: jittered_grid(1000, 0.2, flat=True, dtype=dtype),
            "lagoon": lambda: lagoon(1000, seed=2, amplitude=0.2, wavelength=(0.4, 1.0), dtype=dtype).surface,
            "fan": lambda: fan(dtype=dtype)}[name]()  # fmt: skip
    P, L = _lanes(mesh, 512, seed=5)
    P, L = P.astype(dtype), L.astype(dtype)
    fast = prepare(mesh).start_points(P, L)
    ref = start_points(mesh, P, L, method="general")
    found = np.asarray(ref.found)
    assert 0.3 < found.mean() < 1
    np.testing.assert_array_equal(np.asarray(fast.found), found)
    # Same face (a tie on a shared edge may pick either face: none in these lanes) and the
    # same barycentrics within rounding (the two paths compile the kernel differently).
    np.testing.assert_array_equal(np.asarray(fast.face), np.asarray(ref.face))
    d_ab = np.max(np.abs(np.asarray(fast.barycentric, np.float64) - np.asarray(ref.barycentric, np.float64)))
    M = [np.asarray(barycentric_point(mesh.triangle(s.face)[0], s.barycentric), np.float64) for s in (fast, ref)]
    d_M = np.max(np.abs(M[0] - M[1]))
    assert d_ab <= AB_TOL[dtype] and d_M <= M_TOL[dtype]


def test_a_mesh_changed_in_place_is_prepared_anew():
    import equinox as eqx

    mesh = jittered_grid(500, 0.2)
    moved = eqx.tree_at(lambda m: m.vertices, mesh, mesh.vertices.at[:, 0].add(0.5))
    assert prepare(moved).accel is not prepare(mesh).accel
    assert not np.array_equal(np.asarray(prepare(moved).accel.u_lines), np.asarray(prepare(mesh).accel.u_lines))


# --------------------------------------------------------------------------- a far mesh
# float32 keeps ~7 digits of a coordinate: solved where it lies, the 512-triangle pool moved
# by (300, -300, 0) m found 45 of 256 lanes (TIR 55, LEFT_MESH 17, NOT_CONVERGED 139), 1 of
# 256 at 3 km. `prepare` moves such a mesh near the origin (`local_origin`) and `solve` moves
# the points back (tests/test_invariance.py checks the lanes).


def test_a_mesh_near_the_origin_is_solved_where_it_is():
    for mesh in (wavy_pool(512).surface, lagoon(512).surface, jittered_grid(512, 0.2)):
        prep = prepare(mesh)
        assert not np.any(prep.origin) and prep.local is prep  # lanes bit for bit as before


@pytest.mark.parametrize("dtype", DTYPES)
def test_the_local_origin_moves_a_far_mesh_exactly(dtype):
    base = np.asarray(wavy_pool(512, dtype="float64").surface.vertices, np.float64)
    faces = np.asarray(wavy_pool(512).surface.faces)
    rng = np.random.default_rng(0)
    for _ in range(8):
        t = rng.uniform(-1, 1, 3) * 10.0 ** rng.uniform(1, 5, 3)
        mesh = SurfaceMesh.from_arrays(base + t, faces, dtype=dtype)
        prep = prepare(mesh)
        far = np.abs(t) > 4.2  # the axes whose centre lies beyond the pool's 4.2 m side
        assert np.array_equal(prep.origin != 0, far), (t, prep.origin)
        V, V_local = np.asarray(mesh.vertices, np.float64), np.asarray(prep.local.mesh.vertices, np.float64)
        np.testing.assert_array_equal(V_local + prep.origin, V)  # exact: the same triangles
        assert np.max(np.abs(V_local)) <= 1.5 * 4.2 + 1e-3  # an axis left alone: centre within one side
        np.testing.assert_array_equal(np.asarray(prep.local.mesh.normals), np.asarray(mesh.normals))


def test_a_grid_mesh_moves_with_its_grid_and_a_grid_off_its_vertices_is_not_trusted():
    import equinox as eqx

    from caustics_jax.surface.frames import grid_state

    sc = wavy_pool(512, dtype="float32")
    pool = sc.surface
    P = np.asarray(sc.receivers)
    L = np.broadcast_to(np.asarray(sc.lights.position[0]), P.shape)
    t = np.array([300.0, -300.0, 20.0])
    moved = pool.translated(t)
    assert moved.grid.x0 == pool.grid.x0 + 300 and prepare(moved).accel.kind == "grid"
    a, b = solve(moved, P + t, L + t), solve(pool, P, L)
    np.testing.assert_array_equal(np.asarray(a.status), np.asarray(b.status))
    assert np.all(np.asarray(b.found))
    # 0.5 ulp of 300 m in float32 is 1.5e-5 m: the moved vertices' rounding
    err = np.abs(np.asarray(a.point, np.float64) - (np.asarray(b.point, np.float64) + t)).max()
    assert err <= 2 * np.spacing(np.float32(300)), err
    # Rounding from an earlier dtype or position: the grid's cells are not trusted, silently.
    for m in (pool.astype("float64"), moved.translated(-t)):
        assert grid_state(m) == "rounded" and prepare(m).local.mesh.grid is None
        assert np.all(np.asarray(solve(m, P, L).found))
    assert grid_state(wavy_pool(512, dtype="float64").surface.astype("float32")) == "exact"
    # Moved in xy after the grid was built: the faces are binned, with a warning.
    stale = eqx.tree_at(lambda m: m.vertices, pool, pool.vertices + jnp.asarray([1.0, 0, 0], "float32"))
    assert grid_state(stale) == "stale"
    with pytest.warns(UserWarning, match="off its regular grid"):
        got = solve(stale, P + (1, 0, 0), L + (1, 0, 0))  # had found no start point: NO_CROSSING, silently
    np.testing.assert_array_equal(np.asarray(got.status), np.asarray(b.status))
    heights = eqx.tree_at(lambda m: m.vertices, pool, pool.vertices.at[:, 2].add(0.01))
    assert grid_state(heights) == "exact" and np.all(np.asarray(solve(heights, P, L).found))


def test_a_far_float32_grid_finds_crossings_next_to_its_cell_walls():
    """The far grid's vertices keep the rounding of their far coordinates: moved near the
    origin, its exact cells are 1.5e-5 m off them (300 m) and a crossing next to a cell
    wall was lost (2 of 2000 lanes at 3 km, 19 at 10 km: NO_CROSSING on segments that
    cross). `frames.local_mesh` drops such a grid: every start point is found, as without a
    grid."""
    g64 = wavy_pool(512, dtype="float64").surface
    g = g64.grid
    H = np.asarray(g64.vertices)[:, 2].reshape(g.ny + 1, g.nx + 1)
    rng = np.random.default_rng(0)
    n = 2000
    i, j = rng.integers(1, g.nx, n), rng.integers(1, g.ny, n)
    side = lambda: rng.choice([-1, 1], n) * 10.0 ** rng.uniform(-7, -3, n)  # noqa: E731
    P = np.c_[g.x0 + i * g.dx + side(), g.y0 + j * g.dy + side(), np.full(n, -1.0)]
    L = P + np.c_[rng.normal(0, 0.05, (n, 2)), np.full(n, 4.0)]
    t = np.array([1e4, -1e4, 0.0])
    grid = SurfaceMesh.from_heightfield(H, x0=g.x0 + t[0], y0=g.y0 + t[1], dx=g.dx, dy=g.dy, dtype="float32")
    plain = SurfaceMesh.from_arrays(np.asarray(grid.vertices, np.float64), np.asarray(grid.faces), dtype="float32")
    a, b = solve(grid, P + t, L + t), solve(plain, P + t, L + t)
    for sol in (a, b):
        assert not np.any(np.asarray(sol.status) == 1)  # every segment crosses the pool
    # (the two meshes' normals differ in the last bits: computed from exact and from rounded
    # xy; measured 1 lane of 2000 FOUND in one, NOT_CONVERGED in the other)
    assert abs(int(np.sum(np.asarray(a.found))) - int(np.sum(np.asarray(b.found)))) <= 3


def test_every_entry_point_answers_a_far_scene_in_the_callers_frame():
    """irradiance (one path, every path, returned solutions), the exhaustive reference and
    the photon map run about `prepare(mesh).origin` and answer where the scene lies:
    points moved back (zeros kept where a lane has none), irradiance unchanged."""
    import caustics_jax as cj

    sc = wavy_pool(512, dtype="float64", n_receivers=6)
    base = sc.surface
    t = np.array([3000.0, -3000.0, 1500.0])
    far = SurfaceMesh.from_arrays(np.asarray(base.vertices) + t, np.asarray(base.faces), np.asarray(base.normals))
    assert np.any(prepare(far).origin)
    P = np.array(sc.receivers, np.float64)
    P[:4, 2] = 0.5  # above the water: no start point, zeros in the result
    L = np.broadcast_to(np.asarray(sc.lights.position[0], np.float64), P.shape)
    kw = dict(intensity=2.0, receiver_normal=(0, 0, 1), return_solution=True)

    def same(a, b):  # a: the far scene's, b: the base scene's
        np.testing.assert_array_equal(np.asarray(a.status), np.asarray(b.status))
        for field in ("point", "start_point"):
            x, y = np.asarray(getattr(a, field)), np.asarray(getattr(b, field))
            has = np.any(y != 0, -1)
            assert has.sum() >= len(P) - 4
            np.testing.assert_array_equal(x[~has], 0)
            np.testing.assert_allclose(x[has], y[has] + t, rtol=0, atol=4 * np.spacing(5000.0))

    for extra in ({}, {"all_paths": True, "visibility": True}):
        (E1, s1), (E0, s0) = cj.irradiance(far, P + t, L + t, **kw, **extra), cj.irradiance(base, P, L, **kw, **extra)
        np.testing.assert_allclose(np.asarray(E1), np.asarray(E0), rtol=1e-11)
        assert np.count_nonzero(np.asarray(E0)) >= len(P) - 4
        same(s1, s0)
    a, b = (cj.solve(m, P + s, L + s, method="exhaustive", return_all=True) for m, s in ((far, t), (base, 0)))
    same(a.solution, b.solution)
    has = np.asarray(b.all_triangles) >= 0
    np.testing.assert_array_equal(np.asarray(a.all_triangles), np.asarray(b.all_triangles))
    np.testing.assert_array_equal(a.all_points[~has], 0)
    np.testing.assert_allclose(a.all_points[has], b.all_points[has] + t, rtol=0, atol=4 * np.spacing(5000.0))
    grid = dict(x0=-1.0, x1=1.0, y0=-1.0, y1=1.0, nx=6, ny=6)
    moved = dict(z=-1.0 + t[2], x0=-1.0 + t[0], x1=1.0 + t[0], y0=-1.0 + t[1], y1=1.0 + t[1], nx=6, ny=6)
    light = np.asarray(sc.lights.position[0], np.float64)
    p1 = cj.photon_irradiance(far, light + t, intensity=2.0, receiver=cj.ReceiverGrid(**moved), n_photons=1 << 14)
    p0 = cj.photon_irradiance(base, light, intensity=2.0, receiver=cj.ReceiverGrid(z=-1.0, **grid), n_photons=1 << 14)
    assert p0.hits.sum() > 1000
    np.testing.assert_array_equal(p1.hits, p0.hits)
    np.testing.assert_allclose(p1.irradiance, p0.irradiance, rtol=1e-9)


def test_far_surfaces_check_their_start_point_inputs_and_moved_grids_do_not_warn():
    import warnings

    from caustics_jax.surface.frames import grid_state

    pool = wavy_pool(512, dtype="float32").surface
    far = pool.translated((3e3, -3e3, 0.0))
    P = np.array([[3e3, -3e3, -1.0]], np.float32)
    L = P + np.float32(4.0) * np.array([[0, 0, 1]], np.float32)
    for bad, match in ((P.astype(np.float64), "float64 but the mesh is float32"), (P.astype(bool), "bool"),
                       (P[0, 0], "shape"), (np.full((1, 3), np.nan, np.float32), "NaN")):
        for surface in (pool, far):  # the far one had cast them silently (its local frame)
            with pytest.raises(ValueError, match=match):
                prepare(surface).start_points(bad, L)
    # Built far, moved to the origin: rounding of the far position (1.5-2.3% of a spacing),
    # not a grid moved after it was built: binned without a warning.
    for x0, dx in ((1e5, 0.26), (1e4, 0.02), (300.0, 0.001)):
        H = np.zeros((9, 9))
        m = SurfaceMesh.from_heightfield(H, x0=x0, y0=x0, dx=dx, dy=dx, dtype="float32").translated((-x0, -x0, 0))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert grid_state(m) == "rounded" and prepare(m).local.mesh.grid is None


def test_public_start_points_build_the_structure_once_per_mesh(monkeypatch):
    """`caustics_jax.start_points` (and `transport.surface_hits`) keep `prepare(mesh)`'s
    structure: a second call on the same mesh builds nothing on the host (it had rebuilt the
    jittered mesh's bins on every call, 150 ms at 32k triangles), and gives what a structure built for the call gives. A
    mesh holding numpy arrays, which can change in place, still builds one per call."""
    import jax

    import caustics_jax as cj
    import caustics_jax.accel.prepared as prepared_module

    start_points_module = importlib.import_module("caustics_jax.accel.start_points")  # (cj.start_points: the function)
    built = []
    real = start_points_module.build_accel
    for module in (prepared_module, start_points_module):  # (prepared imports it by name)
        monkeypatch.setattr(module, "build_accel", lambda mesh: built.append(1) or real(mesh))
    mesh = jax.device_put(jittered_grid(1000, 0.2, seed=3, dtype=np.float32))
    P, L = _lanes(mesh, 64, 3)
    P, L = P.astype(np.float32), L.astype(np.float32)
    first = cj.start_points(mesh, P, L)
    again = cj.start_points(mesh, P, L)
    also = cj.start_points(prepare(mesh), P, L)  # a PreparedSurface is accepted too
    hits = [cj.transport.surface_hits(mesh, L[0], P) for _ in range(2)]  # (it had binned the faces per call)
    assert len(built) == 1
    assert 8 < np.asarray(hits[0][2]).sum() and np.array_equal(np.asarray(hits[0][0]), np.asarray(hits[1][0]))
    fresh = start_points(mesh, P, L)  # the module's function: a structure built for this call
    assert len(built) == 2 and np.asarray(fresh.found).sum() > 32
    for sp in (first, again, also):
        for field in ("face", "barycentric", "found"):
            np.testing.assert_array_equal(np.asarray(getattr(sp, field)), np.asarray(getattr(fresh, field)))
    numpy_mesh = jax.device_get(mesh)
    built.clear()
    cj.start_points(numpy_mesh, P, L)
    cj.start_points(numpy_mesh, P, L)
    assert len(built) == 2


def test_public_start_points_first_called_inside_jit_keep_no_tracers():
    """A mesh closed over by a user's `jit`: the first `caustics_jax.accel.start_points` (and
    `surface_hits`) call prepares it inside the trace. The kept analysis is computed
    eagerly, so later calls outside `jit` work (traced arrays kept in the cache would
    leak into them)."""
    import jax

    import caustics_jax as cj

    mesh = jax.device_put(jittered_grid(1000, 0.2, seed=4, dtype=np.float32))
    P, L = (x.astype(np.float32) for x in _lanes(mesh, 32, 4))
    inside = jax.jit(lambda P, L: cj.start_points(mesh, P, L))(P, L)
    hits = jax.jit(lambda X: cj.transport.surface_hits(mesh, L[0], X))(P)
    prep = prepare(mesh)
    leaves = jax.tree.leaves((prep.accel, prep.padded, prep.bvh))
    assert leaves and not any(isinstance(x, jax.core.Tracer) for x in leaves)
    outside = cj.start_points(mesh, P, L)
    for field in ("face", "barycentric", "found"):
        np.testing.assert_array_equal(np.asarray(getattr(inside, field)), np.asarray(getattr(outside, field)))
    np.testing.assert_array_equal(np.asarray(hits[0]), np.asarray(cj.transport.surface_hits(mesh, L[0], P)[0]))
    assert np.asarray(outside.found).any()  # (`solve` reads the same kept analysis: `prep.padded` above)


def test_public_start_points_route_by_method_and_frame():
    """A `PreparedSurface` with another method runs on its mesh (the BVH here); a mesh far
    from the origin is searched about its centre, as `prepare(mesh).start_points` does."""
    import caustics_jax as cj

    mesh = jittered_grid(1000, 0.2, seed=5, dtype=np.float32)
    P, L = (x.astype(np.float32) for x in _lanes(mesh, 64, 5))
    general = cj.start_points(prepare(mesh), P, L, method="general")
    want = start_points(mesh, P, L, method="general")
    for field in ("face", "barycentric", "found"):
        np.testing.assert_array_equal(np.asarray(getattr(general, field)), np.asarray(getattr(want, field)))
    shift = np.array([300.0, -200.0, 0.0], np.float32)
    far = mesh.translated(shift)
    prep = prepare(far)
    assert np.any(prep.origin)
    got, kept = cj.start_points(far, P + shift, L + shift), prep.start_points(P + shift, L + shift)
    for field in ("face", "barycentric", "found"):
        np.testing.assert_array_equal(np.asarray(getattr(got, field)), np.asarray(getattr(kept, field)))
    assert np.asarray(got.found).sum() > 16
