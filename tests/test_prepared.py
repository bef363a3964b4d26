"""prepare(mesh): the start-point acceleration is chosen once per mesh, cached, and gives the
start points of the BVH reference path."""

import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax import barycentric_point
from caustics_jax.bvh import FaceBVH
from caustics_jax.face_cells import FaceCells
from caustics_jax.mesh import SurfaceMesh
from caustics_jax.prepared import prepare
from caustics_jax.scenes import lagoon, wavy_pool
from caustics_jax.start_points import start_points
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
