"""Setup mistakes that would leave every lane failing without an error are named: the light
below the surface or the receivers above it (every lane NO_CROSSING), OBJ-style 1-based
faces, and photon estimates of nothing (no photons, an empty receiver grid)."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import caustics_jax as cj

N = 64


@pytest.fixture(scope="module")
def pool():
    sc = cj.scenes.flat_pool(512, n_receivers=8, dtype=jnp.float32)  # flat: the closed form, nothing to compile
    rng = np.random.default_rng(0)
    P = np.column_stack([rng.uniform(-1.5, 1.5, (N, 2)), np.full(N, -1.0)]).astype(np.float32)
    return sc.surface, P


def _no_crossing_warnings(record):
    return [str(w.message) for w in record if issubclass(w.category, UserWarning) and "NO_CROSSING" in str(w.message)]


@pytest.mark.parametrize("case", ["light below", "receivers above"])
def test_every_lane_missing_the_surface_warns_with_its_cause_in_solve_and_irradiance(pool, case):
    mesh, P = pool
    if case == "light below":
        L, want = np.array([0.3, -0.2, -0.5], np.float32), "the light is below the surface"
    else:
        P, L, want = P + np.float32([0, 0, 1.5]), np.array([0.3, -0.2, 3.0], np.float32), "receivers are above"
    with pytest.warns(UserWarning, match=want) as record:
        sol = cj.solve(mesh, P, L)
    assert np.all(np.asarray(sol.status) == cj.Status.NO_CROSSING)
    assert len(_no_crossing_warnings(record)) == 1  # once, not once per block or per layer
    assert f"{N} of the {N} lanes" in _no_crossing_warnings(record)[0]
    with pytest.warns(UserWarning, match=want):
        E = cj.irradiance(mesh, P, L, intensity=1.0, receiver_normal=[0, 0, 1])
    assert not np.any(np.asarray(E))


def test_a_well_posed_scene_and_a_few_lanes_beside_the_surface_do_not_warn(pool):
    mesh, P = pool
    L = np.array([0.3, -0.2, 3.0], np.float32)
    beside = P.copy()
    beside[:2, :2] = 50.0  # two receivers far outside the pool: NO_CROSSING, as asked
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        sol = cj.solve(mesh, beside, L)
    assert np.sum(np.asarray(sol.status) == cj.Status.NO_CROSSING) == 2
    assert _no_crossing_warnings(record) == []


def test_one_based_faces_get_a_hint_and_zero_based_ones_build():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    cj.SurfaceMesh.from_arrays(V, F)
    with pytest.raises(ValueError, match=r"from 1 to 4, as in an OBJ file: pass faces - 1"):
        cj.SurfaceMesh.from_arrays(V, F + 1)
    with pytest.raises(ValueError, match=r"out of range \[0, 4\): faces \[1\] \(1 in all\)$"):  # not 1-based: no hint
        cj.SurfaceMesh.from_arrays(V, np.array([[0, 1, 2], [1, 4, 2]]))
