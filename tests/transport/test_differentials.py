"""The D factor by ray differentials against an exact autodiff trace (seed 001 eq. 26-33; math.md §6)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax.testing import oracle, planted_paths, random_triangles
from caustics_jax.transport import autodiff_D, ray_differential_D

DTYPES = [jnp.float32, jnp.float64]
BATCH = 1024  # every hypothesis example is one batch of this size: one compile per dtype


def _cast(arrays, dtype):
    return [jnp.asarray(x, dtype) for x in arrays]


def _fields(p):
    return p.V, p.N, p.P, p.L, p.ab


def _dot(u, v):
    return np.sum(u * v, -1, keepdims=True)


def _D_reference(V, N, P, L, ab, eta, *, m_sign=-1, eta_sign=-1, wn_sign=1, mu_d_sign=1, ns_prime=True):
    """Float64 numpy seed 001 eq. 26-33, written independently of the package.

    Returns `(D, L'_perp, L'_par)`. The keywords switch single signs so that the test can
    show which readings of the paper are right: defaults are the true derivative with
    respect to `w_P` (`M'` = minus eq. 28 as printed, `-eta` in eq. 31); `m_sign=+1` is
    eq. 28 as printed, `eta_sign=+1` eq. 31 as extracted, `wn_sign=-1` flips `w_P'.n_s`
    in eq. 30, `mu_d_sign=-1` the whole `mu'` term, `ns_prime=False` drops `n_s'`. The
    frame (w_perp, w_par) is built differently from the package's, on purpose: D must not
    depend on it.
    """
    E1, E2 = V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
    M, n_tilde = oracle.barycentric_point(V, ab), oracle.interpolated_normal(N, ab)
    n_s, n_len = oracle.unit(n_tilde), np.linalg.norm(n_tilde, axis=-1, keepdims=True)
    w_P, w_L = oracle.unit(P - M), oracle.unit(L - M)
    d_P = np.linalg.norm(P - M, axis=-1, keepdims=True)
    d_L = np.linalg.norm(L - M, axis=-1, keepdims=True)
    n_g = oracle.unit(np.cross(E1, E2))
    helper = np.where(np.abs(w_P[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    w_perp = oracle.unit(np.cross(w_P, helper))
    w_par = np.cross(w_P, w_perp)
    G = np.stack([E1, E2], -1)
    Gt = np.swapaxes(G, -1, -2)
    cos_P, cos_L = _dot(w_P, n_s), _dot(w_L, n_s)
    out = []
    for w in (w_perp, w_par):
        M_d = m_sign * d_P * (w - _dot(w, n_g) / _dot(w_P, n_g) * w_P)
        ab_d = np.linalg.solve(Gt @ G, Gt @ M_d[..., None])[..., 0]
        n_tilde_d = ab_d[:, :1] * (N[:, 1] - N[:, 0]) + ab_d[:, 1:] * (N[:, 2] - N[:, 0])
        n_s_d = (n_tilde_d - _dot(n_s, n_tilde_d) * n_s) / n_len if ns_prime else 0 * n_tilde_d
        mu = cos_L + eta * cos_P
        mu_d = mu_d_sign * (eta**2 * cos_P / cos_L + eta) * (wn_sign * _dot(w, n_s) + _dot(w_P, n_s_d))
        w_L_d = eta_sign * eta * w + mu_d * n_s + mu * n_s_d
        out.append(M_d - _dot(M_d, w_L) * w_L + d_L * w_L_d)
    return np.linalg.norm(np.cross(*out), axis=-1), out[0], out[1]


def _rel(x, ref):
    return np.abs(np.asarray(x, np.float64) - ref) / np.abs(ref)


@given(seed=st.integers(0, 2**32 - 1), spread=st.sampled_from([0.0, 0.3, 0.6]),
       eta=st.sampled_from([1.333, 1.5]))
def test_ray_differential_D_equals_autodiff_jacobian_determinant(seed, spread, eta):
    """math.md §6 **verify**: eq. 26-33 (signs as in the module docstring) = |det| of the exact map."""
    p = planted_paths(seed, BATCH, eta=eta, normal_spread=spread)
    args = _cast(_fields(p), jnp.float64)
    D, valid = ray_differential_D(*args, eta)
    D_exact = np.asarray(autodiff_D(*args, eta))
    valid = np.asarray(valid)
    # planted paths are valid except at w_P grazing the geometric plane (0 of 920k in
    # float64 for these settings)
    assert valid.mean() > 0.99
    # Measured max 5.0e-11 over 920k paths (spread 0.6; 1.4e-11 at 0.3, 1.4e-12 flat):
    # the largest values are near caustics, where D is a small difference of large terms.
    # math.md asks for 1e-6; the bound keeps 200x over the measurement.
    assert np.max(_rel(D, D_exact)[valid]) < 1e-8
    D_ref = _D_reference(*_fields(p), eta)[0]
    assert np.max(_rel(D, D_ref)[valid]) < 1e-8  # independent numpy formula, other frame


def test_only_the_consistent_sign_readings_match_autodiff():
    """Which signs of eq. 28-31 are right, measured against the exact trace (float64).

    Right: the true derivative (minus eq. 28 as printed, `-eta` in eq. 31; math.md §6 and
    the package), and its global
    negation (eq. 28 and eq. 31 as printed, `w_P'.n_s` negated in eq. 30), which flips L'
    and keeps D. Wrong, with the median / max relative error they give on these paths
    (seed 41, spread 0.3; on flat triangles in brackets):
    eq. 28 as printed + eq. 31 with -eta (M' flipped alone) 0.70 / 1.6e3 [0.66 / 11];
    eq. 28 and 31 as extracted 0.15 / 82 [0.16 / 2.7]; true M' with +eta 0.74 / 1.4e3
    [0.75 / 9.9]; n_s' dropped 0.15 / 1.3e3 [exact: n_s' = 0 on flat triangles];
    mu' negated 0.15 / 1.4e2 [0.16 / 2.7].
    """
    eta = 1.333
    p = planted_paths(41, BATCH, eta=eta, normal_spread=0.3)
    D_exact = np.asarray(autodiff_D(*_cast(_fields(p), jnp.float64), eta))
    ref = lambda **kw: _D_reference(*_fields(p), eta, **kw)[0]  # noqa: E731
    assert np.max(_rel(ref(), D_exact)) < 1e-10  # measured 4.0e-13
    assert np.max(_rel(ref(m_sign=1, eta_sign=1, wn_sign=-1), D_exact)) < 1e-10  # measured 4.0e-13
    wrong = {
        "eq. 28 printed, eq. 31 -eta": dict(m_sign=1),
        "eq. 28 and eq. 31 as extracted": dict(m_sign=1, eta_sign=1),
        "true M', eq. 31 +eta": dict(eta_sign=1),
        "n_s' dropped": dict(ns_prime=False),
        "mu' negated": dict(mu_d_sign=-1),
    }
    for name, kw in wrong.items():
        err = _rel(ref(**kw), D_exact)
        assert np.median(err) > 0.05, name  # measured medians 0.15 to 0.74
        assert np.mean(err > 1e-3) > 0.95, name  # measured 0.990 to 1.000


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1), spread=st.sampled_from([0.0, 0.3, 0.6]),
       eta=st.sampled_from([1.333, 1.5]))
def test_float32_D_error_is_rounding_times_conditioning(dtype, seed, spread, eta):
    """float32 (and float64) against the float64 reference; the error scale is |L'_perp| |L'_par|.

    D = |L'_perp x L'_par| cancels near caustics (D << |L'_perp| |L'_par|), so the
    relative error of D is not bounded; the error relative to the Hadamard bound is.
    """
    p = planted_paths(seed, BATCH, eta=eta, normal_spread=spread)
    args = _cast(_fields(p), dtype)
    D, valid = ray_differential_D(*args, eta)
    D_ad = autodiff_D(*args, eta)
    assert D.dtype == D_ad.dtype == dtype
    valid = np.asarray(valid)
    # float32 reports w_P within sqrt(eps) = 3.5e-4 of the geometric plane invalid:
    # 6 of 245k planted paths
    assert valid.mean() > 0.99
    D_ref, L_perp, L_par = _D_reference(*_fields(p), eta)
    scale = np.linalg.norm(L_perp, axis=-1) * np.linalg.norm(L_par, axis=-1)
    hadamard_err = np.abs(np.asarray(D, np.float64) - D_ref)[valid] / scale[valid]
    hadamard_err_ad = np.abs(np.asarray(D_ad, np.float64) - D_ref)[valid] / scale[valid]
    if dtype == jnp.float32:
        # Measured over 245k paths (spread 0, 0.3, 0.6): eq. 26-33 max 6.4e-5, autodiff
        # max 1.3e-4; relative error median 1.5e-7 (max 1.1e-2, near caustics).
        assert np.max(hadamard_err) < 5e-4
        assert np.max(hadamard_err_ad) < 1e-3
        assert np.median(_rel(D, D_ref)[valid]) < 1e-6
    else:
        # measured max 6.4e-13 and 1.4e-12 (the numpy reference's normal-equation solve
        # contributes); relative error max 1.6e-11
        assert np.max(hadamard_err) < 1e-10
        assert np.max(hadamard_err_ad) < 1e-10


def _geometric_normals(V):
    n = oracle.unit(np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]))
    return np.repeat(n[:, None], 3, axis=1)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1))
def test_D_is_squared_path_length_when_eta_is_one(dtype, seed):
    """eta = 1 is a straight line: D = (d_P + d_L)^2 (math.md §6 **verify**).

    On a flat triangle (normals = geometric normal) as math.md asks, and also on a curved
    one: at eta = 1 GLSL refract is the identity whatever the normal, mu = mu' = 0 and
    n_s' drops out of eq. 31.
    """
    p = planted_paths(seed, BATCH, eta=1.0, normal_spread=0.0)
    exact = (np.linalg.norm(p.P - p.M, axis=-1) + np.linalg.norm(p.L - p.M, axis=-1)) ** 2
    curved_N = planted_paths(seed + 1, BATCH, normal_spread=0.4).N
    # Measured max relative error over 30k paths each: float64 flat 1.5e-13, curved
    # 5.3e-13, autodiff flat 1.2e-14; float32 flat 8.6e-6, curved 5.2e-4 (lanes whose
    # w_P is within a few degrees of the triangle's plane), autodiff flat 1.9e-6.
    tol = {jnp.float32: (1e-4, 5e-3), jnp.float64: (1e-11, 1e-11)}[dtype]
    for N, bound in ((_geometric_normals(p.V), tol[0]), (curved_N, tol[1])):
        args = _cast((p.V, N, p.P, p.L, p.ab), dtype)
        D, valid = ray_differential_D(*args, 1.0)
        valid = np.asarray(valid)
        # invalid: P on the outer side of the (replaced) shading normal, where GLSL
        # refract reflects; measured mean 0.6% (max 1.3%) flat, 0.08% (max 0.3%) curved
        assert valid.mean() > 0.95
        assert np.max(_rel(D, exact)[valid]) < bound
        if N is not curved_N:
            assert np.max(_rel(autodiff_D(*args, 1.0), exact)[valid]) < bound


def test_flipping_M_prime_alone_gives_d_P_minus_d_L_squared_at_eta_one():
    """math.md §6: `M'` flipped without `w_P'` (eq. 28 as printed, `-eta` in eq. 31) gives
    `(d_P - d_L)^2` at `eta = 1` on a flat surface, not `(d_P + d_L)^2`.

    At `eta = 1`, `mu = mu' = 0` and `w_L' = -w_P'`, so `L' = (+-d_P - d_L) w_P'`: the
    sign of `M'` decides between the sum and the difference of the path lengths.
    """
    p = planted_paths(43, BATCH, eta=1.0, normal_spread=0.0)
    args = (p.V, _geometric_normals(p.V), p.P, p.L, p.ab)
    d_P = np.linalg.norm(p.P - p.M, axis=-1)
    d_L = np.linalg.norm(p.L - p.M, axis=-1)
    scale = (d_P + d_L) ** 2  # (d_P - d_L)^2 can vanish; relative to the sum
    flipped = _D_reference(*args, 1.0, m_sign=1)[0]
    true = _D_reference(*args, 1.0)[0]
    assert np.max(np.abs(flipped - (d_P - d_L) ** 2) / scale) < 1e-12  # measured 7.1e-16
    assert np.max(np.abs(true - (d_P + d_L) ** 2) / scale) < 1e-12  # measured 1.7e-15
    # the two differ by 4 d_P d_L: at least 0.155 of the scale on these paths
    assert np.min(np.abs(flipped - true) / scale) > 0.1


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1), eta=st.sampled_from([1.333, 1.5]))
def test_D_at_normal_incidence_on_a_flat_surface_is_d_P_plus_eta_d_L_squared(dtype, seed, eta):
    """math.md §6's flat-interface result `D = (d + eta h)^2`, exact along the normal."""
    rng = np.random.default_rng(seed)
    V, _ = random_triangles(rng, BATCH)  # tilted, no slivers
    N = _geometric_normals(V)
    n = N[:, 0]
    ab = rng.dirichlet([2.0, 2.0, 2.0], BATCH)[:, 1:]
    M = oracle.barycentric_point(V, ab)
    d_P, d_L = rng.uniform(0.2, 2.0, BATCH), rng.uniform(0.5, 5.0, BATCH)
    args = _cast((V, N, M - d_P[:, None] * n, M + d_L[:, None] * n, ab), dtype)
    exact = (d_P + eta * d_L) ** 2
    D, valid = ray_differential_D(*args, eta)
    assert np.all(np.asarray(valid))
    # measured max over 123k paths: float64 1.2e-15 (autodiff 1.8e-15), float32 4.9e-7 (8.8e-7)
    tol = {jnp.float32: 5e-6, jnp.float64: 1e-13}[dtype]
    assert np.max(_rel(D, exact)) < tol
    assert np.max(_rel(autodiff_D(*args, eta), exact)) < tol


def _degenerate_cases(n=64):
    """Five batches of `n` inputs, each degenerate in one way only."""
    p = planted_paths(31, n)
    # w_P in the (flat, z = 0) triangle's plane, while the tilted shading normal still
    # refracts it (w_P.n_s = -0.71, not TIR): only eq. 28's w_P.n_g vanishes
    V = p.V.copy()
    V[..., 2] = 0
    N = np.broadcast_to(oracle.unit(np.array([-1.0, 0.0, 1.0])), V.shape).copy()
    M = oracle.barycentric_point(V, p.ab)
    grazing = (V, N, M + [1.0, 0, 0], M + [0, 0, 1.0], p.ab)
    # P far sideways: -w_P beyond the critical angle at M
    tir = (p.V, p.N, p.M + np.array([8.0, 0.0, -0.5]), p.L, p.ab)
    # collinear vertices
    V = p.V.copy()
    V[:, 2] = V[:, 0] + 2 * (V[:, 1] - V[:, 0])
    M = oracle.barycentric_point(V, p.ab)
    sliver = (V, p.N, M + [0.1, 0.2, -1.0], M + [0.1, 0, 1.0], p.ab)
    # P exactly at M = V0
    at_P = (p.V, p.N, p.V[:, 0], p.L, np.zeros_like(p.ab))
    # n~ = 0 halfway along edge V0V1
    N = p.N.copy()
    N[:, 1] = -N[:, 0]
    ab = np.tile([0.5, 0.0], (n, 1))
    M = oracle.barycentric_point(p.V, ab)
    zero_normal = (p.V, N, M - [0, 0, 1.0], M + [0, 0, 1.0], ab)
    cases = [grazing, tir, sliver, at_P, zero_normal]
    return [np.concatenate([c[i] for c in cases]) for i in range(5)], len(cases)


@pytest.mark.parametrize("dtype", DTYPES)
def test_degenerate_inputs_are_invalid_with_finite_values_and_gradients(dtype):
    (V, N, P, L, ab), n_cases = _degenerate_cases()
    args = _cast((V, N, P, L, ab), dtype)
    D, valid = ray_differential_D(*args, 1.333)
    assert not np.any(np.asarray(valid))
    assert np.all(np.asarray(D) == 0)
    assert np.all(np.isfinite(np.asarray(autodiff_D(*args, 1.333))))
    if dtype == jnp.float64:  # the gradient's compile is the slowest part of this file
        grads = jax.grad(lambda P, ab: jnp.sum(ray_differential_D(args[0], args[1], P, args[3], ab, 1.333)[0]),
                         argnums=(0, 1))(args[2], args[4])
        assert all(np.all(np.isfinite(np.asarray(g))) for g in grads)


def test_batch_dimensions_and_per_lane_eta_broadcast():
    sets = [planted_paths(7, 16, eta=1.333, normal_spread=0.3), planted_paths(8, 16, eta=1.5, normal_spread=0.3)]
    fields = [np.stack([f1, f2]) for f1, f2 in zip(_fields(sets[0]), _fields(sets[1]), strict=True)]
    eta = np.array([[1.333], [1.5]])  # (2, 1) against batch (2, 16)
    D, valid = ray_differential_D(*_cast(fields, jnp.float64), jnp.asarray(eta))
    D_ad = autodiff_D(*_cast(fields, jnp.float64), jnp.asarray(eta))
    assert D.shape == valid.shape == D_ad.shape == (2, 16)
    ref = np.stack([_D_reference(*_fields(s), s.eta)[0] for s in sets])
    assert np.all(np.asarray(valid))
    assert np.max(_rel(D, ref)) < 1e-10
    assert np.max(_rel(D_ad, ref)) < 1e-10


def test_an_overflowing_D_is_marked_invalid_and_zero():
    """float32, a unit triangle scaled by `s`: `D` follows `s^2 D(1)` to rounding up to
    s = 3e8 (the edge of `arguments.scale_range`); at 1e9 and 1e19 an intermediate
    overflows (D came out inf, or 0, with valid True before): now valid is False and D 0."""
    V = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    N = np.tile(np.float32([0, 0, 1]), (3, 1))
    P, L, ab = np.float32([0.2, 0.3, -1]), np.float32([0.4, 0.2, 3]), np.float32([0.3, 0.3])
    D1 = float(ray_differential_D(V, N, P, L, ab, 1.333)[0])
    s = np.float32([1e3, 3e8, 1e9, 1e19])[:, None]
    D, ok = (np.asarray(x) for x in ray_differential_D(V * s[:, None], N, P * s, L * s, ab, 1.333))
    np.testing.assert_allclose(D[:2] / (D1 * s[:2, 0].astype(float) ** 2), 1, rtol=5e-7)
    assert ok[:2].all() and not ok[2:].any() and np.all(D[2:] == 0)
