"""SMS-style irradiance estimators (transport/estimators.py) against the certified all-path
reference: the unbiased one is unbiased, the biased one never exceeds the total."""

import functools

import numpy as np
import pytest

import caustics_jax as cj
from caustics_jax import scenes
from caustics_jax.transport.estimators import sms_biased, sms_unbiased, surface_starts

UP = [0.0, 0.0, 1.0]
# A small steep pool (1.26 m square, one 0.1 m wave of 0.6 m, floor 1 m down): receivers
# 2, 8, 15, 24, 28 of its 6 x 6 grid have 3 paths each (the reference's count, equal to the
# distinct forward solutions of Newton started at the centroid of every face; receiver 15,
# under the light, has a line-pair conic on every face, where the reference lost one path
# until `arc_roots.chord_on_conic`), and Newton started at a
# uniformly random surface point reaches each of those paths with probability 0.027-0.12
# (measured over 256 starts per receiver; 10-20% of the starts converge at all).
RECEIVERS = [2, 8, 15, 24, 28]
SEEDS = 512


@functools.cache
def _scene():
    with cj.precision("float64"):
        sc = scenes.wavy_pool(512, half_size=0.6, amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6), n_receivers=6,
                              depth=1.0, light_position=(0.1, -0.1, 3.0), dtype="float64")
        P = np.asarray(sc.receivers)[RECEIVERS]
        L = np.asarray(sc.lights.endpoint(P))
        ref = cj.solve(sc.surface, P, L, method="exhaustive", return_all=True)
        E_ref = np.asarray(cj.irradiance(sc.surface, P, L, intensity=1.0, receiver_normal=UP,
                                         method="exhaustive", all_paths=True))
    return sc.surface, P, L, ref, E_ref


def test_surface_starts_are_uniform_over_the_area():
    with cj.precision("float64"):
        mesh = scenes.wavy_pool(512, amplitude=0.1, dtype="float64").surface
    s = surface_starts(mesh, 200_000, np.random.default_rng(0))
    V = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[np.asarray(s.face)]]
    ab = np.asarray(s.barycentric)
    assert np.all(ab >= 0) and np.all(ab.sum(-1) <= 1)
    M = V[:, 0] + ab[:, :1] * (V[:, 1] - V[:, 0]) + ab[:, 1:] * (V[:, 2] - V[:, 0])
    # The pool is 4.2 m square (x, y uniform on it up to the waves' small slope): each half
    # of each axis holds half the points, within 5 standard errors of a binomial.
    for axis in (0, 1):
        frac = np.mean(M[:, axis] < 0)
        assert abs(frac - 0.5) < 5 * np.sqrt(0.25 / len(M)), frac
    # Within a face, a + b is distributed as a triangle's area: P(a + b <= 1/2) = 1/4.
    assert abs(np.mean(ab.sum(-1) <= 0.5) - 0.25) < 5 * np.sqrt(0.25 * 0.75 / len(ab))


def test_unbiased_sms_mean_matches_the_all_path_reference():
    """Mean over 512 seeds (independent lanes) per receiver within 4 standard errors of the
    reference sum over every path (Zeltner et al. 2020's Bernoulli-trial estimator). Without
    the trial count (weight 1) the mean would be `sum_k p_k E_k`, 5-25% of the reference:
    dozens of standard errors off."""
    mesh, P, L, ref, E_ref = _scene()
    np.testing.assert_array_equal(ref.count, [3, 3, 3, 3, 3])
    n = len(P)
    with cj.precision("float64"):
        est = sms_unbiased(mesh, np.repeat(P, SEEDS, 0), np.repeat(L, SEEDS, 0), seed=1, intensity=1.0,
                           receiver_normal=UP)
    E = est.irradiance.reshape(n, SEEDS)
    mean, se = E.mean(1), E.std(1, ddof=1) / np.sqrt(SEEDS)
    z = (mean - E_ref) / se
    assert np.all(np.abs(z) < 4), (z, mean, E_ref, se)
    # The estimate is a weighted single path, not the sum: single estimates scatter widely.
    assert np.median(np.abs(E - E_ref[:, None]) / E_ref[:, None]) > 0.5
    # Expected solves per estimate: 1, plus (when the first converges) 1/p_k trials.
    assert 1 < est.solves.mean() < 50, est.solves.mean()


def test_biased_sms_never_exceeds_the_total_and_reaches_it_with_many_starts():
    mesh, P, L, ref, E_ref = _scene()
    with cj.precision("float64"):
        few = sms_biased(mesh, P, L, k=4, seed=2, intensity=1.0, receiver_normal=UP)
        many = sms_biased(mesh, P, L, k=256, seed=2, intensity=1.0, receiver_normal=UP)
    # Distinct true paths only: never more than the sum over all of them.
    assert np.all(few.irradiance <= E_ref * (1 + 1e-9))
    assert np.all(many.irradiance <= E_ref * (1 + 1e-9))
    assert np.all(few.paths <= ref.count) and np.all(many.paths <= ref.count)
    # 256 starts find every path of these receivers (measured), 4 starts fewer.
    np.testing.assert_array_equal(many.paths, ref.count)
    np.testing.assert_allclose(many.irradiance, E_ref, rtol=1e-8)
    assert few.paths.sum() < ref.count.sum()


@pytest.mark.parametrize(
    "fn, kwargs, match",
    [
        (sms_biased, dict(k=0, seed=0), "k must"),
        (sms_unbiased, dict(seed=0, max_trials=0), "max_trials"),
        (sms_unbiased, dict(seed=0, receiver_normal=[0.0, 0.0, 0.0]), "receiver_normal"),
        # checked as irradiance checks them (they had given E = 0, inf, or an amplified E)
        (sms_biased, dict(k=2, seed=0, receiver_normal=[0.0, 1.0]), "receiver_normal must have shape"),
        (sms_biased, dict(k=2, seed=0, sigma_t=-1.0), "sigma_t"),
        (sms_biased, dict(k=2, seed=0, sigma_t=float("nan")), "sigma_t"),
        (sms_unbiased, dict(seed=0, intensity=1e39), "intensity overflows float32"),
        (sms_unbiased, dict(seed=0, eta=1e39), "eta overflows float32"),
        (sms_biased, dict(k=2, seed=0, same_radius=-1.0), "same_radius"),
        # seed: numpy's own message (not naming seed) for -1, a TypeError for 1.5
        (sms_biased, dict(k=2, seed=-1), r"seed must be an integer in \[0, 2147483647\], got -1"),
        (sms_unbiased, dict(seed=1.5), r"seed must be an integer in \[0, 2147483647\], got 1.5"),
        (sms_unbiased, dict(seed=True), "seed must be an integer"),
        (sms_biased, dict(k=2, seed="7"), "seed must be an integer"),
        # solve's own arguments are not Newton options (they had given a TypeError from
        # solve: "got multiple values for keyword argument 'method'")
        (sms_biased, dict(k=2, seed=0, method="walk"), r"unknown newton option\(s\) \['method'\]"),
        (sms_unbiased, dict(seed=0, start=None), r"unknown newton option\(s\) \['start'\]"),
        (sms_biased, dict(k=2, seed=0, features="fast"), "features"),
        # P and L as solve takes them (a (2, 2, 3) P had been flattened to 4 lanes; an L of
        # 3 lanes for 1 P had given JAX's broadcasting error)
        (sms_biased, dict(k=2, seed=0, P=np.zeros((2, 2, 3)) - 1), r"P and L must broadcast to \(N, 3\)"),
        (sms_unbiased, dict(seed=0, L=np.ones((3, 3)), P=np.zeros((2, 3)) - 1), "do not broadcast"),
    ],
)
def test_bad_estimator_arguments_raise_value_error(fn, kwargs, match):
    mesh = scenes.flat_pool(64, dtype="float32").surface
    kwargs = {"intensity": 1.0, "receiver_normal": UP, "P": np.array([[0.0, 0.0, -1.0]]),
              "L": np.array([[0.0, 0.0, 1.0]]), **kwargs}
    P, L = kwargs.pop("P"), kwargs.pop("L")
    with pytest.raises(ValueError, match=match):
        fn(mesh, P, L, **kwargs)


def test_estimators_take_a_receiver_normal_of_any_length():
    """As `irradiance`: normalised on the host in float64 (float32 `[0, 0, 1e20]` and
    `[0, 0, 1e-25]` had given E = 0)."""
    sc = scenes.wavy_pool(512, n_receivers=2, dtype="float32")
    mesh, P = sc.surface, np.asarray(sc.receivers)
    L = np.asarray(sc.lights.endpoint(sc.receivers))
    E = [sms_biased(mesh, P, L, k=16, seed=3, intensity=1.0, receiver_normal=[0.0, 0.0, s]).irradiance
         for s in (1.0, 1e20, 1e-25)]
    assert np.asarray(E[0]).sum() > 0
    np.testing.assert_array_equal(np.asarray(E[1]), np.asarray(E[0]))
    np.testing.assert_array_equal(np.asarray(E[2]), np.asarray(E[0]))


def test_estimators_pass_features_to_solve():
    """`features` goes to `solve` (the general path with None): same estimate on a wavy pool,
    where compaction skips no lane."""
    with cj.precision("float64"):
        sc = scenes.wavy_pool(512, n_receivers=2, dtype="float64")
        P, L = np.asarray(sc.receivers), np.asarray(sc.lights.endpoint(sc.receivers))
        a = sms_biased(sc.surface, P, L, k=8, seed=1, intensity=1.0, receiver_normal=UP)
        b = sms_biased(sc.surface, P, L, k=8, seed=1, intensity=1.0, receiver_normal=UP, features=None)
    np.testing.assert_array_equal(a.irradiance, b.irradiance)
    np.testing.assert_array_equal(a.paths, b.paths)
