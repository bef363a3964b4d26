"""Adaptive cross-bilateral denoiser (seed 004 eq. 21-28, Alg. 4)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax.kernels import (
    C_SCENE_FACTOR,
    C_SCENE_FACTOR_ALG4,
    adaptive_kernel_params,
    bilateral_denoise,
    bilateral_weight,
    denoise_subpass,
    luminance,
)

DTYPES = [jnp.float32, jnp.float64]
EPS = {jnp.float32: np.finfo(np.float32).eps, jnp.float64: np.finfo(np.float64).eps}
seeds = st.integers(0, 2**32 - 1)
denoise_j = jax.jit(bilateral_denoise, static_argnames="passes")
subpass_j = jax.jit(denoise_subpass, static_argnames="axis")


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds, eps=st.sampled_from([1.0, 0.1, 1e-3]))
def test_weight_is_symmetric_bounded_by_centre_and_decreasing(dtype, seed, eps):
    rng = np.random.default_rng(seed)
    zp, zq = rng.uniform(0, 100, (2, 256))
    pp, pq = rng.normal(size=(2, 256, 3))
    delta = rng.choice([1.0, 2.0, 15.0], 256)
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    w = np.asarray(bilateral_weight(c(zp), c(zq), c(pp), c(pq), c(delta), eps))
    assert w.dtype == dtype
    np.testing.assert_array_equal(
        w, np.asarray(bilateral_weight(c(zq), c(zp), c(pq), c(pp), c(delta), eps))
    )
    centre = np.asarray(bilateral_weight(c(zp), c(zp), c(pp), c(pp), c(delta), eps))
    np.testing.assert_allclose(centre, 1 / eps, rtol=2 * EPS[dtype])
    assert np.all((w > 0) & (w <= centre))
    # moving q further in depth or in space never raises the weight
    w_z = np.asarray(bilateral_weight(c(zp), c(zq + np.sign(zq - zp)), c(pp), c(pq), c(delta), eps))
    w_d = np.asarray(bilateral_weight(c(zp), c(zq), c(pp), c(pp + 1.5 * (pq - pp)), c(delta), eps))
    assert np.all(w_z <= w) and np.all(w_d <= w)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds, factor=st.sampled_from([C_SCENE_FACTOR, C_SCENE_FACTOR_ALG4, 0.5]))
def test_adaptive_parameters_follow_the_thresholds_of_eq_26_to_28(dtype, seed, factor):
    rng = np.random.default_rng(seed)
    l_min = rng.uniform(0.1, 10)
    lum = rng.uniform(0, 1, 512) * factor * l_min
    rho, lam, delta = (
        np.asarray(a) for a in adaptive_kernel_params(jnp.asarray(lum, dtype), l_min, factor)
    )
    assert delta.dtype == dtype
    c_scene = factor * l_min
    for sel, want in (
        (lum < 0.1 * c_scene, (15, 5, 15)),
        ((lum >= 0.1 * c_scene) & (lum < 0.5 * c_scene), (10, 1, 2)),
        (lum >= 0.5 * c_scene, (5, 1, 1)),
    ):
        clear = sel & (np.abs(lum / c_scene - 0.1) > 1e-5) & (np.abs(lum / c_scene - 0.5) > 1e-5)
        for got, w in zip((rho, lam, delta), want, strict=True):
            assert np.all(got[clear] == w)
    assert np.all(rho % lam == 0)  # Alg. 4's loop from -rho in steps of lambda hits 0 and rho


@pytest.mark.parametrize("dtype", DTYPES)
def test_c_scene_default_is_eq25_and_alg4_constant_only_changes_the_band_between(dtype):
    """0.114 (eq. 25) is the default; 0.144 (Alg. 4 line 7) moves both thresholds up by
    26 %. Pixels with lum/lum(L_min) in [0.0114, 0.0144) or [0.057, 0.072) change class."""
    l_min = 2.0
    ratio = np.linspace(0, 0.1, 10001)
    lum = jnp.asarray(ratio * l_min, dtype)
    default = np.asarray(adaptive_kernel_params(lum, l_min)[0])
    explicit = np.asarray(adaptive_kernel_params(lum, l_min, 0.114)[0])
    alg4 = np.asarray(adaptive_kernel_params(lum, l_min, 0.144)[0])
    np.testing.assert_array_equal(default, explicit)
    differs = default != alg4
    in_band = ((ratio >= 0.0114) & (ratio < 0.0144)) | ((ratio >= 0.057) & (ratio < 0.072))
    edge = np.minimum.reduce([np.abs(ratio - b) for b in (0.0114, 0.0144, 0.057, 0.072)]) < 1e-6
    np.testing.assert_array_equal(differs[~edge], in_band[~edge])


def _scene(rng, H, W, dtype, depth_step=None):
    """Image, depth and view-space positions from depth (pinhole, 1 mrad pixels)."""
    depth = (
        rng.uniform(5, 6, (H, W))
        if depth_step is None
        else np.where(np.arange(W) < W // 2, 5.0, depth_step)[None].repeat(H, 0)
    )
    y, x = np.meshgrid(np.arange(H) - H / 2, np.arange(W) - W / 2, indexing="ij")
    pos = np.stack([x * 1e-3 * depth, y * 1e-3 * depth, depth], -1)
    return jnp.asarray(depth, dtype), jnp.asarray(pos, dtype)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds, level=st.floats(0, 2))
def test_constant_image_stays_constant(dtype, seed, level):
    rng = np.random.default_rng(seed)
    depth, pos = _scene(rng, 24, 40, dtype)
    C = jnp.full((24, 40, 3), level, dtype) * jnp.asarray([1.0, 0.5, 0.25], dtype)
    out = np.asarray(denoise_j(C, depth, pos, 1.0, passes=2))
    assert out.dtype == dtype
    np.testing.assert_allclose(out, np.asarray(C), rtol=64 * EPS[dtype], atol=0)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_output_is_a_convex_combination_of_the_input(dtype, seed):
    rng = np.random.default_rng(seed)
    depth, pos = _scene(rng, 24, 40, dtype)
    C = rng.exponential(0.01, (24, 40, 3))  # spans all three luminance classes
    out = np.asarray(subpass_j(jnp.asarray(C, dtype), depth, pos, 1.0, axis=1))
    slack = 8 * EPS[dtype] * C.max()
    # each row only mixes with itself (x sub-pass)
    assert np.all(out >= C.min(axis=1, keepdims=True) - slack)
    assert np.all(out <= C.max(axis=1, keepdims=True) + slack)
    assert np.abs(out - C).max() > 0  # it does filter


@pytest.mark.parametrize("dtype", DTYPES)
def test_depth_step_is_not_blurred_across(dtype):
    rng = np.random.default_rng(0)
    H, W = 16, 48
    C = np.where(np.arange(W)[None, :, None] < W // 2, 1.0, 1e-3) * np.ones((H, W, 3))
    depth, pos = _scene(rng, H, W, dtype, depth_step=500.0)
    out = np.asarray(denoise_j(jnp.asarray(C, dtype), depth, pos, 1.0))
    step = 1.0 - 1e-3
    # Leakage across the edge as a fraction of the step: measured 3.5e-7 (float64, depth
    # 5 vs 500: w_z ~ 2e-3 times w_pos ~ 1e-4); bound 1e-6. Within a side nothing changes.
    assert np.abs(out - C).max() / step <= 1e-6
    # same image, flat depth: the edge is smeared (so the check above can fail)
    flat_depth, flat_pos = _scene(rng, H, W, dtype, depth_step=5.0)
    smeared = np.asarray(denoise_j(jnp.asarray(C, dtype), flat_depth, flat_pos, 1.0))
    assert np.abs(smeared - C).max() / step > 0.01


@pytest.mark.parametrize("dtype", DTYPES)
def test_dark_pixels_sample_every_fifth_neighbour_out_to_fifteen(dtype):
    """Alg. 4 loop: rho = 15, lambda = 5 for lum < 0.1 C_scene: offsets +-5, +-10, +-15."""
    W = 40
    depth = jnp.full((1, W), 5.0, dtype)
    pos = jnp.zeros((1, W, 3), dtype)  # w_pos = 1: only the footprint matters
    changed = []
    for off in range(1, 19):
        C = np.zeros((1, W, 3))
        C[0, 20 + off] = 1e-4  # still far below 0.1 C_scene for lum(L_min) = 1
        out = np.asarray(subpass_j(jnp.asarray(C, dtype), depth, pos, 1.0, axis=1))
        changed.append(out[0, 20, 1] > 0)
    assert [o for o, ch in zip(range(1, 19), changed, strict=True) if ch] == [5, 10, 15]


def _alg4_numpy(C, depth, pos, l_min, factor=0.114):
    """Alg. 4 transcribed line by line (x sub-pass), Rec. 709 luminance, except line 7.

    Line 7 prints `0.144 lum(LMin)`; `factor` is passed in instead and defaults to eq. 25's
    0.114 (docs/kernels.md). Neighbours outside the image are skipped (Alg. 4 does not say).
    """
    H, W, _ = C.shape
    out = np.empty_like(C)
    for y in range(H):
        for x in range(W):
            Cp, sum_w = C[y, x].copy(), 1.0
            lum = C[y, x] @ np.array([0.2126, 0.7152, 0.0722])
            c_scene = factor * l_min
            rho, lam, delta = (
                (15, 5, 15)
                if lum < 0.1 * c_scene
                else ((10, 1, 2) if lum < 0.5 * c_scene else (5, 1, 1))
            )
            for i in range(-rho, rho + 1, lam):
                if i == 0 or not 0 <= x + i < W:
                    continue
                d = pos[y, x] - pos[y, x + i]
                w = 1 / (abs(depth[y, x] - depth[y, x + i]) + 1.0) / (1 + 10 * (d @ d) / delta**2)
                Cp += w * C[y, x + i]
                sum_w += w
            out[y, x] = Cp / sum_w
    return out


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_subpass_equals_a_transcription_of_alg4(dtype, seed):
    rng = np.random.default_rng(seed)
    depth, pos = _scene(rng, 4, 36, dtype)
    C = rng.exponential(0.01, (4, 36, 3))
    out = np.asarray(subpass_j(jnp.asarray(C, dtype), depth, pos, 1.0, axis=1))
    want = _alg4_numpy(C, np.asarray(depth, np.float64), np.asarray(pos, np.float64), 1.0)
    # float32: inputs rounded to float32 and ~30-term sums; measured max rel 3e-7
    np.testing.assert_allclose(out, want, rtol=3e-6 if dtype == jnp.float32 else 1e-12)


def test_luminance_and_shapes():
    np.testing.assert_allclose(np.asarray(luminance(jnp.ones((2, 3)))), 1.0, rtol=1e-6)
    with pytest.raises(ValueError):
        denoise_subpass(jnp.ones((4, 4, 3)), jnp.ones((4, 5)), jnp.ones((4, 4, 3)), 1.0)
    with pytest.raises(ValueError, match="delta"):
        bilateral_weight(0.0, 1.0, jnp.zeros(3), jnp.ones(3), 0.0)


# Scales of delta and |p - q| together: the weight of eq. 23 depends on their ratio only.
SCALES = {jnp.float32: [1e-30, 1e-23, 1e-19, 1.0, 1e19, 1e30],
          jnp.float64: [1e-300, 1e-160, 1.0, 1e160, 1e300]}


@pytest.mark.parametrize("dtype", DTYPES)
def test_weight_depends_on_the_ratio_of_distance_to_delta_at_any_scale(dtype):
    """`1 / (1 + 10 k^2)` for `|p - q| = k delta`, whatever delta, with finite gradients.

    As `d.d / delta^2` (before the fix) float32 gave NaN at delta = 1e-30 and 1e-23 with
    p = q (delta^2 underflows: 0/0) and at delta = |p - q| = 1e30 (inf/inf)."""
    scale = np.repeat(SCALES[dtype], 4)
    k = np.tile([0.0, 0.5, 1.0, 3.0], len(SCALES[dtype]))
    pos_q = np.stack([k * scale, 0 * k, 0 * k], -1)
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731

    def w_of(delta, q):
        return bilateral_weight(c(2.0), c(2.0), c(np.zeros(3)), q, delta)

    w = np.asarray(jax.jit(w_of)(c(scale), c(pos_q)))
    # measured max relative error 1.9e-7 (float32), 1.9e-16 (float64): a few roundings
    np.testing.assert_allclose(w, 1 / (1 + 10 * k**2), rtol=4 * EPS[dtype])
    grads = jax.jit(jax.grad(lambda d, q: jnp.sum(w_of(d, q)), argnums=(0, 1)))(c(scale), c(pos_q))
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in grads)


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_delta_or_eps_below_the_smallest_normal_number_is_refused(dtype):
    """Subnormal parameters are flushed to zero by XLA: 1 / eps would be inf."""
    sub = np.finfo(dtype).tiny / 4
    z3 = jnp.zeros(3, dtype)
    with pytest.raises(ValueError, match="delta"):
        bilateral_weight(jnp.asarray(1.0, dtype), 1.0, z3, z3, jnp.asarray(sub, dtype))
    with pytest.raises(ValueError, match="eps"):
        bilateral_weight(jnp.asarray(1.0, dtype), 1.0, z3, z3, jnp.asarray(1.0, dtype), eps=sub)


def test_inside_jit_a_zero_delta_or_eps_gives_finite_weights():
    """Not checked on tracers: delta = 0 is the limit (1 at p = q, else 0), eps is floored."""
    z3 = jnp.zeros(3, jnp.float32)
    w = jax.jit(lambda d, e: bilateral_weight(jnp.float32(1.0), 1.0, z3, jnp.asarray([[0, 0, 0], [1.0, 0, 0]]),
                                              d, e))(jnp.float32(0), jnp.float32(0))
    assert bool(jnp.all(jnp.isfinite(w))) and float(w[1]) == 0


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_tiny_eps_does_not_overflow_the_denoiser_sums(dtype):
    """eps = 2 tiny makes w(p, p) = 1 / (2 tiny); 31 such weights overflowed the sums (NaN)."""
    eps = 2 * float(np.finfo(dtype).tiny)
    H, W = 2, 8
    depth = jnp.full((H, W), 5.0, dtype)
    pos = jnp.zeros((H, W, 3), dtype)
    C = jnp.ones((H, W, 3), dtype)
    out = np.asarray(denoise_subpass(C, depth, pos, 1.0, eps=eps))
    np.testing.assert_allclose(out, 1.0, rtol=8 * EPS[dtype])


@pytest.mark.parametrize("shape", [(0, 4), (4, 0), (0, 0)])
def test_an_empty_image_gives_an_empty_result(shape):
    C, depth = jnp.zeros((*shape, 3)), jnp.zeros(shape)
    assert denoise_subpass(C, depth, C, 1.0, axis=1).shape == (*shape, 3)
    assert bilateral_denoise(C, depth, C, 1.0).shape == (*shape, 3)


def test_static_arguments_given_a_tracer_are_a_value_error_naming_them():
    C, depth = jnp.ones((2, 2, 3)), jnp.ones((2, 2))
    with pytest.raises(ValueError, match="axis.*static"):
        jax.jit(lambda a: denoise_subpass(C, depth, C, 1.0, axis=a))(1)
    with pytest.raises(ValueError, match="passes.*static"):
        jax.jit(lambda n: bilateral_denoise(C, depth, C, 1.0, passes=n))(1)
