"""The one-step Newton's two small formulas, batched (one compile per dtype): the 2x2
step by Cramer's rule solves `J dx = r` and refuses a singular or non-finite system; the
ray-plane intersection of the re-projection returns the barycentrics of the point the ray
from `P` through `T` meets, and says when the plane lies behind `P`."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax.math.barycentric import barycentric_point, ray_plane_barycentric
from caustics_jax.math.geometry import newton_step_2x2

# Bounds from the errors measured on these inputs (2026-12-02), about 4-10x above them:
# the 2x2 step's residual 7.6e-6 (float32) and 1.6e-15 (float64) against |r| <= 3.2; the
# ray-plane barycentrics off by 3.5e-5 and 5.6e-14 where the ray meets the plane at more
# than ~12 degrees.
STEP_TOL = {"float32": 3e-5, "float64": 1e-14}
HIT_TOL = {"float32": 2e-4, "float64": 5e-13}


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_newton_step_2x2_solves_and_refuses_singular_systems(dtype):
    rng = np.random.default_rng(11)
    n = 256
    Q = rng.standard_normal((n, 2, 2))
    J = Q + 3 * np.eye(2)  # conditioned: det away from 0
    r = rng.standard_normal((n, 2))
    J[-4] = [[1.0, 2.0], [2.0, 4.0]]  # singular
    J[-3] = [[np.nan, 0.0], [0.0, 1.0]]
    r[-2] = [np.inf, 0.0]
    J[-1] = 0.0
    dx, ok = jax.jit(jax.vmap(newton_step_2x2))(jnp.asarray(J, dtype), jnp.asarray(r, dtype))
    dx, ok = np.asarray(dx, np.float64), np.asarray(ok)
    assert ok[:-4].all() and not ok[-4:].any()
    np.testing.assert_array_equal(dx[-4:], 0)
    resid = np.einsum("nij,nj->ni", J[:-4], dx[:-4]) - r[:-4]
    assert np.abs(resid).max() < STEP_TOL[dtype], np.abs(resid).max()


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_ray_plane_barycentric_finds_the_hit_and_rejects_a_plane_behind(dtype):
    rng = np.random.default_rng(12)
    n = 256
    V = rng.uniform(-1, 1, (n, 3, 3)) + np.array([0, 0, 0.5])
    ab = rng.uniform(0, 0.5, (n, 2))
    M = np.asarray(barycentric_point(jnp.asarray(V), jnp.asarray(ab)))
    P = M + rng.uniform(0.5, 2, (n, 1)) * rng.standard_normal((n, 3))
    s = rng.uniform(0.1, 0.9, (n, 1))
    ahead = P + s * (M - P)  # between P and the plane: the hit is ahead of P
    behind = P - s * (M - P)  # the ray points away from the plane
    fn = jax.jit(jax.vmap(ray_plane_barycentric))
    args = [jnp.asarray(x, dtype) for x in (V, P)]
    got, hit = fn(*args, jnp.asarray(ahead, dtype))
    _, hit_behind = fn(*args, jnp.asarray(behind, dtype))
    # conditioning: the ray's angle to the plane; keep lanes that are not grazing
    nrm = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    d = (M - P) / np.linalg.norm(M - P, axis=-1, keepdims=True)
    cos = np.abs(np.sum(nrm * d, -1)) / np.linalg.norm(nrm, axis=-1)
    good = cos > 0.2
    assert good.sum() > n // 2
    assert np.asarray(hit).all() and not np.asarray(hit_behind).any()
    err = np.abs(np.asarray(got, np.float64) - ab)[good].max()
    assert err < HIT_TOL[dtype], err
