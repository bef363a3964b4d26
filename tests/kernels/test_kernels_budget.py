"""The adaptive photon budget of seed 003 (kernels/budget.py)."""

import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax.kernels import photon_budget

DTYPES = [jnp.float32, jnp.float64]


@pytest.mark.parametrize("dtype", DTYPES)
def test_the_budget_sums_to_the_total_keeps_its_floor_and_follows_the_footprint(dtype):
    rng = np.random.default_rng(0)
    s = rng.uniform(0, 2, (32, 32)) * (rng.uniform(0, 1, (32, 32)) < 0.7)  # 30% of texels reach nothing
    total, floor = 65536.0, 0.25
    rtol = 64 * np.finfo(dtype).eps
    for gamma in (0.0, 1 / 3, 1.0):
        n = np.asarray(photon_budget(jnp.asarray(s, dtype), total, gamma, floor))
        assert n.dtype == dtype and n.shape == s.shape
        np.testing.assert_allclose(n.sum(), total, rtol=rtol)
        base = total * floor / s.size
        np.testing.assert_allclose(n[s == 0], base, rtol=rtol)  # unreached texels: the floor only
        extra = n[s > 0] - base
        w = s[s > 0] ** gamma
        np.testing.assert_allclose(extra, total * (1 - floor) * w / w.sum(), rtol=rtol * 4)
    # gamma = 1: the extra photons per unit footprint are the same everywhere (equal density)
    n = np.asarray(photon_budget(jnp.asarray(s, dtype), total, 1.0, floor))
    ratio = (n[s > 0] - total * floor / s.size) / s[s > 0]
    np.testing.assert_allclose(ratio, ratio[0], rtol=rtol * 8)


@pytest.mark.parametrize("dtype", DTYPES)
def test_no_footprint_or_nan_spreads_the_budget_uniformly(dtype):
    z = jnp.zeros((4, 4), dtype)
    np.testing.assert_allclose(np.asarray(photon_budget(z, 160.0, 1.0)), 10.0, rtol=1e-6)
    s = jnp.asarray([np.nan, -1.0, 0.0, 3.0], dtype)
    n = np.asarray(photon_budget(s, 100.0, 1.0, 0.2))
    np.testing.assert_allclose(n, [5.0, 5.0, 5.0, 85.0], rtol=1e-6)
