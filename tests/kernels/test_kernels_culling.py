"""Energy culling of seed 003 (kernels/culling.py): throughput, mid-trace, final and
throughput cull. Random batches, one compile per dtype and shape."""

import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax.kernels import CullStatus, energy_cull, photon_cull, throughput, throughput_cull

DTYPES = [jnp.float32, jnp.float64]
EPS = {jnp.float32: np.finfo(np.float32).eps, jnp.float64: np.finfo(np.float64).eps}
AIR_TO_WATER = 1 / 1.333


@pytest.mark.parametrize("dtype", DTYPES)
def test_throughput_is_normal_incidence_transmittance_times_beer_lambert(dtype):
    # at normal incidence T = 1 - ((n1 - n2)/(n1 + n2))^2 in closed form (Hecht), independent
    # of the kernel's Fresnel formula; exp(-sigma t) from numpy
    t = np.linspace(0, 5, 64)
    beta = np.asarray(throughput(jnp.ones(64, dtype), jnp.asarray(t, dtype), AIR_TO_WATER, 0.3))
    T0 = 1 - ((1.333 - 1) / (1.333 + 1)) ** 2
    np.testing.assert_allclose(beta, T0 * np.exp(-0.3 * t), rtol=16 * EPS[dtype])
    assert beta.dtype == dtype


@pytest.mark.parametrize("dtype", DTYPES)
def test_throughput_falls_with_path_length_and_grazing_incidence_and_clips_negative_t(dtype):
    rng = np.random.default_rng(0)
    cos_i = np.sort(rng.uniform(0, 1, 512))
    t = rng.uniform(0, 4, 512)
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    beta = np.asarray(throughput(c(cos_i), c(t), AIR_TO_WATER, 0.5))
    further = np.asarray(throughput(c(cos_i), c(t + 0.25), AIR_TO_WATER, 0.5))
    assert np.all(further < beta) and np.all((beta >= 0) & (beta <= 1))
    at_t = np.asarray(throughput(c(cos_i), c(np.full(512, 1.0)), AIR_TO_WATER, 0.5))
    assert np.all(np.diff(at_t) >= -4 * EPS[dtype])  # more grazing (smaller cos) transmits less
    np.testing.assert_array_equal(np.asarray(throughput(c(cos_i), c(-t), AIR_TO_WATER, 0.5)),
                                  np.asarray(throughput(c(cos_i), c(0 * t), AIR_TO_WATER, 0.5)))
    assert float(throughput(c(0.0), c(0.0), AIR_TO_WATER, 0.0)) == 0  # grazing: nothing enters


@pytest.mark.parametrize("dtype", DTYPES)
def test_energy_cull_keeps_what_reaches_the_threshold_and_culls_nan(dtype):
    e = np.array([0.0, 0.1, 0.2, 0.3, np.nan, 1.0])
    thr = np.array([0.0, 0.2, 0.2, 0.2, 0.0, np.nan])
    kept, keep = energy_cull(jnp.asarray(e, dtype), jnp.asarray(thr, dtype))
    np.testing.assert_array_equal(np.asarray(keep), [True, False, True, True, False, False])
    np.testing.assert_array_equal(np.asarray(kept), np.asarray([0.0, 0, 0.2, 0.3, 0, 0], dtype))


@pytest.mark.parametrize("dtype", DTYPES)
def test_photon_cull_statuses_partition_the_energy(dtype):
    rng = np.random.default_rng(1)
    n = 4096
    energy, albedo = rng.uniform(0, 1, n), rng.uniform(0, 1, n)
    mid, final = rng.uniform(0, 0.5, n), rng.uniform(0, 0.3, n)
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    stored, status = (np.asarray(x) for x in photon_cull(c(energy), c(albedo), c(mid), c(final)))
    e32 = energy.astype(dtype)
    want = np.where(e32 < mid.astype(dtype), CullStatus.MID,
                    np.where(albedo.astype(dtype) * e32 < final.astype(dtype), CullStatus.FINAL, CullStatus.STORED))
    # away from the thresholds (the product's rounding decides within an ulp of them)
    clear = (np.abs(albedo * energy - final) > 8 * EPS[dtype]) & (np.abs(energy - mid) > 8 * EPS[dtype])
    np.testing.assert_array_equal(status[clear], want[clear])
    assert set(np.unique(status)) == {0, 1, 2} and status.dtype == np.int32
    np.testing.assert_array_equal(stored, np.where(status == CullStatus.STORED, e32, 0))
    # no thresholds: every photon is stored, its energy unchanged
    all_kept, none_culled = photon_cull(c(energy), c(albedo), c(0 * mid), c(0 * final))
    np.testing.assert_array_equal(np.asarray(all_kept), e32)
    assert np.all(np.asarray(none_culled) == CullStatus.STORED)


@pytest.mark.parametrize("dtype", DTYPES)
def test_throughput_cull_is_monotone_in_its_threshold(dtype):
    rng = np.random.default_rng(2)
    cos_i, d = rng.uniform(0.05, 1, 2048), rng.uniform(0.5, 6, 2048)
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    kept = [np.asarray(throughput_cull(c(cos_i), c(d), c(np.full(2048, m)), AIR_TO_WATER, 0.4)[1])
            for m in (0.0, 0.1, 0.3, 0.6)]
    assert kept[0].all() and not kept[-1].all()
    for looser, tighter in zip(kept, kept[1:], strict=False):
        assert np.all(looser | ~tighter)  # a tighter threshold never keeps a lane a looser one culled
    beta_hat, _ = throughput_cull(c(cos_i), c(d), c(np.zeros(2048)), AIR_TO_WATER, 0.4)
    np.testing.assert_array_equal(np.asarray(beta_hat), np.asarray(throughput(c(cos_i), c(d), AIR_TO_WATER, 0.4)))


@pytest.mark.parametrize("dtype", DTYPES)
def test_throughput_at_oblique_incidence_is_the_textbook_fresnel_transmittance(dtype):
    # Snell and the Fresnel amplitude coefficients written here from n1 = 1 (air), n2 = 1.333
    # (water): at normal incidence T is the same for eta and 1/eta, so only oblique angles
    # tell an inverted index ratio (water to air: total internal reflection below cos 0.66)
    cos_i = np.array([0.2, 0.5, 0.8])
    n1, n2 = 1.0, 1.333
    cos_t = np.sqrt(1 - (n1 / n2) ** 2 * (1 - cos_i**2))
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    want = 1 - (rs**2 + rp**2) / 2
    got = np.asarray(throughput(jnp.asarray(cos_i, dtype), jnp.zeros(3, dtype), n1 / n2, 0.0))
    np.testing.assert_allclose(got, want, rtol=64 * EPS[dtype])
    assert np.all(want < 0.99) and want[0] < 0.75  # oblique enough to matter
