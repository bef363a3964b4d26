"""Scene features (`caustics_jax.surface.features`): the flags, and that `features="auto"` gives the
same statuses, points and irradiance as the general path (`features=None`).

Every scene here has 256 receivers and a 512-face surface, so the general and the
compacted batches share one lane bucket and one mesh bucket: one walk compile per dtype.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import caustics_jax as cj
from caustics_jax import scenes
from caustics_jax.runtime.blocks import lanes_per_block
from caustics_jax.solvers import Status, Walk, solve
from caustics_jax.surface.features import SceneFeatures, features
from caustics_jax.testing import flat_interface_irradiance, partly_covered_floor
from caustics_jax.transport import irradiance

DTYPES = [jnp.float32, jnp.float64]
UP = np.array([0.0, 0.0, 1.0])
# On a flat surface "auto" returns the exact root (bisection to the last bit) and the walk
# a point with |f| <= tol (1e-5 float32, 1e-10 float64), so their points differ by the
# walk's error, not by rounding. Measured on the flat pool below: max 6.6e-6 m (float32),
# 4.2e-11 m (float64). Bounds with margin; elsewhere the points are bit-identical.
FLAT_POINT_TOL = {jnp.float32: 5e-5, jnp.float64: 1e-9}
FLAT_E_RTOL = {jnp.float32: 1e-3, jnp.float64: 1e-8}


def make_scene(name, dtype):
    if name == "partly_covered":
        return partly_covered_floor(dtype)
    make = scenes.flat_pool if name == "flat" else scenes.wavy_pool
    scene = make(512, n_receivers=16, dtype=dtype)
    return scene.surface, scene.receivers, scene.lights.endpoint(scene.receivers)


def test_features_flags():
    """Each flag is set exactly on the scenes that have the property."""
    flat, wavy = scenes.flat_pool(512).surface, scenes.wavy_pool(512).surface
    assert features(flat) == SceneFeatures(flat=True, compact_lanes=True)
    assert features(wavy) == SceneFeatures(flat=False, compact_lanes=True)
    # Lights are validated but change nothing the solvers skip.
    assert features(flat, scenes.flat_pool(512, light="directional").lights) == features(flat)
    assert features(flat, np.array([0.4, -0.3, 3.0])) == features(flat)
    # A tilted flat square (no grid): flat. An L-shaped flat mesh (not convex: the walk
    # from M0 can leave it where the closed form would not): not flat.
    n = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    u = np.cross(n, [1.0, 0, 0])
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    grid = np.array([(i, j) for j in range(3) for i in range(3)], float)
    square = [(0, 1, 4), (0, 4, 3), (1, 2, 5), (1, 5, 4), (3, 4, 7), (3, 7, 6), (4, 5, 8), (4, 8, 7)]
    def mesh(tris):
        V = (0.5 + grid[:, :1] * u + grid[:, 1:] * w)[: np.max(tris) + 1]
        return cj.SurfaceMesh.from_arrays(V, np.array(tris), normals=np.broadcast_to(n, V.shape))
    f_square = features(mesh(square))
    assert f_square.flat
    assert not features(mesh(square[:6])).flat


def test_bad_features_raise_value_error():
    scene = scenes.flat_pool(128, n_receivers=2)
    P, L = scene.receivers, scene.lights.endpoint(scene.receivers)
    with pytest.raises(ValueError, match="features must be"):
        solve(scene.surface, P, L, features="fast")
    with pytest.raises(ValueError, match="features must be"):
        irradiance(scene.surface, P, L, intensity=1.0, receiver_normal=UP, features=True)
    with pytest.raises(ValueError, match="lights_or_L"):
        features(scene.surface, np.array([[0.0, np.nan, 1.0]]))
    with pytest.raises(ValueError, match="lights_or_L"):
        features(scene.surface, "sun")
    with pytest.raises(ValueError, match="SurfaceMesh"):
        features(np.zeros((3, 3)))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", ["flat", "partly_covered", "wavy"])
def test_auto_gives_the_general_paths_statuses_points_and_irradiance(name, dtype):
    """`features="auto"` and `None` agree lane by lane: statuses exactly, points to rounding
    (to the walk's tolerance on the flat pool, where "auto" is exact), irradiance alike."""
    mesh, P, L = make_scene(name, dtype)
    E_g, g = irradiance(mesh, P, L, intensity=2.0, receiver_normal=UP, features=None,
                        return_solution=True)
    E_a, a = irradiance(mesh, P, L, intensity=2.0, receiver_normal=UP, return_solution=True)
    np.testing.assert_array_equal(np.asarray(a.status), np.asarray(g.status))
    np.testing.assert_array_equal(np.asarray(a.found), np.asarray(g.found))
    found = np.asarray(g.found)
    assert found.sum() > 100
    if name == "partly_covered":
        assert np.sum(np.asarray(g.status) == Status.NO_CROSSING) > 64
    for field in ("start_point", "point", "barycentric", "residual", "triangle"):
        x, y = np.asarray(getattr(a, field)), np.asarray(getattr(g, field))
        assert x.dtype == y.dtype
        if name == "flat" and field in ("point", "barycentric", "residual"):
            np.testing.assert_allclose(x, y, rtol=0, atol=FLAT_POINT_TOL[dtype])
        elif name == "flat" and field == "triangle":
            continue  # a point on a shared edge may be reported in either face
        else:
            np.testing.assert_array_equal(x, y)
    E_a, E_g = np.asarray(E_a), np.asarray(E_g)
    assert E_a.dtype == E_g.dtype == dtype
    np.testing.assert_array_equal(E_a[~found], 0)
    if name == "flat":
        np.testing.assert_allclose(E_a, E_g, rtol=FLAT_E_RTOL[dtype])
    else:
        np.testing.assert_array_equal(E_a, E_g)


def test_auto_gives_the_general_paths_newton_solution_on_a_partly_covered_floor():
    """Newton (`n_starts=1`) is compacted the same way: every field identical."""
    mesh, P, L = partly_covered_floor(jnp.float64)
    g = solve(mesh, P, L, method="newton", features=None)
    a = solve(mesh, P, L, method="newton")
    assert np.sum(np.asarray(g.status) == Status.NO_CROSSING) > 64 and np.asarray(g.found).sum() > 64
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(g), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("dtype", DTYPES)
def test_flat_auto_matches_the_walk_for_random_lights_and_eta(dtype):
    """Low and oblique lights and large eta (M0 in total internal reflection for some
    lanes): the closed form settles exactly the lanes the walk finds, at the same points."""
    rng = np.random.default_rng(7)
    scene = scenes.flat_pool(512, n_receivers=16, dtype=dtype)
    P = scene.receivers
    for _ in range(4):
        L = jnp.broadcast_to(jnp.asarray([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0.5, 5)],
                                         dtype), P.shape)
        eta = rng.uniform(1.05, 1.6)
        g = solve(scene.surface, P, L, eta=eta, features=None)
        a = solve(scene.surface, P, L, eta=eta)
        np.testing.assert_array_equal(np.asarray(a.status), np.asarray(g.status))
        np.testing.assert_allclose(np.asarray(a.point), np.asarray(g.point), rtol=0,
                                   atol=FLAT_POINT_TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_flat_closed_form_matches_the_independent_flat_interface_reference(dtype):
    """The closed-form points equal the numpy float64 Snell bisection of
    `testing.flat_interface_irradiance` (an independent implementation) to rounding."""
    scene = scenes.flat_pool(512, n_receivers=16, dtype=dtype)
    P, L = scene.receivers, scene.lights.endpoint(scene.receivers)
    sol = solve(scene.surface, P, L)
    _, M_ref = flat_interface_irradiance(np.asarray(P, np.float64), np.asarray(L, np.float64)[0],
                                         0.0, 1.333, return_point=True)
    found = np.asarray(sol.found)
    assert found.all()
    err = np.abs(np.asarray(sol.point, np.float64) - M_ref).max()
    # float64: bisection to the last bit (the reference's own bisection ends near 1e-15);
    # float32: a few ulps of the 2 m coordinates.
    assert err <= (2e-6 if dtype == jnp.float32 else 1e-12), err


def test_lanes_that_need_no_solve_never_enter_the_solver(monkeypatch):
    """The walk steps only lanes with a start point, and none on a flat pool: lanes come in
    one fixed-size block (`blocks.lanes_per_block`), the others marked not found, which the
    pool scheduler never steps (`WalkSolver.stages` map only the found lanes)."""
    seen = []
    solve_block = Walk.solve_block

    def spy(self, mesh, P, L, eta, start, lane_id):
        seen.append((P.shape[0], int(np.sum(np.asarray(start[2])))))
        return solve_block(self, mesh, P, L, eta, start, lane_id)

    monkeypatch.setattr(Walk, "solve_block", spy)
    mesh, P, L = partly_covered_floor(jnp.float64, n=32, half=6.0)
    crossing = int(np.sum(np.asarray(cj.start_points(mesh, P, L).found)))
    assert 0 < crossing <= 256 < P.shape[0]
    solve(mesh, P, L)
    assert seen == [(lanes_per_block(), crossing)]
    seen.clear()
    scene = scenes.flat_pool(512, n_receivers=16, dtype=jnp.float64)
    sol = solve(scene.surface, scene.receivers, scene.lights.endpoint(scene.receivers))
    assert seen == [(lanes_per_block(), 0)] and np.asarray(sol.found).all()
