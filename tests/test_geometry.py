"""Properties of refract / reflect / Fresnel (math.md §1), float32 and float64."""

import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax import fresnel_reflectance, fresnel_transmittance, reflect, refract, safe_normalize
from caustics_jax.math.geometry import beer_lambert, safe_sqrt
from caustics_jax.testing import oracle

DTYPES = [jnp.float32, jnp.float64]
# Measured float32 errors against float64 (experiments/float32_audit.py, 2026-11-22):
# refract max 7.5e-7 (unit vector, 200k planted paths), Fresnel max 2.1e-7. Bounds keep 4x.
TOL = {jnp.float32: 3e-6, jnp.float64: 1e-13}

refract_j = jax.jit(refract)
fresnel_j = jax.jit(fresnel_reflectance)


def _incident_and_normal(seed, n):
    rng = np.random.default_rng(seed)
    N = rng.normal(size=(n, 3))
    N /= np.linalg.norm(N, axis=-1, keepdims=True)
    I = rng.normal(size=(n, 3))
    I /= np.linalg.norm(I, axis=-1, keepdims=True)
    I = np.where(np.sum(I * N, -1, keepdims=True) > 0, -I, I)  # dot(N, I) <= 0
    return I, N


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1), eta=st.floats(0.4, 2.5))
def test_refract_obeys_snell_coplanarity_and_is_zero_exactly_under_tir(dtype, seed, eta):
    I, N = _incident_and_normal(seed, 512)
    T = np.asarray(refract_j(jnp.asarray(I, dtype), jnp.asarray(N, dtype), jnp.asarray(eta, dtype)))
    assert T.dtype == dtype
    cos_i = np.sum(N * I, -1)
    k = oracle.refraction_discriminant(cos_i, eta)
    tir = k < 0
    margin = np.abs(k) > 1e-5  # lanes at the TIR boundary can round either way in float32
    assert np.all(T[tir & margin] == 0)
    ok = ~tir & margin
    tol = TOL[dtype]
    np.testing.assert_allclose(np.linalg.norm(T[ok], axis=-1), 1, atol=tol)
    sin_i = np.linalg.norm(np.cross(N[ok], I[ok]), axis=-1)
    sin_t = np.linalg.norm(np.cross(N[ok], T[ok]), axis=-1)
    np.testing.assert_allclose(sin_t, eta * sin_i, atol=tol * max(1, eta))
    coplanar = np.einsum("ij,ij->i", np.cross(I[ok], N[ok]), T[ok])
    np.testing.assert_allclose(coplanar, 0, atol=tol)
    # transmitted, not reflected: it keeps going through the interface
    assert np.all(np.sum(T[ok] * N[ok], -1) <= tol)


@pytest.mark.parametrize("dtype", DTYPES)
def test_refract_is_identity_for_eta_one_and_at_normal_incidence(dtype):
    I, N = _incident_and_normal(7, 64)
    T = refract_j(jnp.asarray(I, dtype), jnp.asarray(N, dtype), 1.0)
    np.testing.assert_allclose(np.asarray(T), I, atol=TOL[dtype])
    T0 = refract_j(jnp.asarray(-N, dtype), jnp.asarray(N, dtype), 1.5)
    np.testing.assert_allclose(np.asarray(T0), -N, atol=TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_reflect_preserves_angle_and_is_an_involution(dtype):
    I, N = _incident_and_normal(3, 256)
    I_, N_ = jnp.asarray(I, dtype), jnp.asarray(N, dtype)
    R = reflect(I_, N_)
    np.testing.assert_allclose(np.sum(np.asarray(R) * N, -1), -np.sum(I * N, -1), atol=TOL[dtype])
    np.testing.assert_allclose(np.asarray(reflect(R, N_)), I, atol=2 * TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
@given(eta=st.floats(0.3, 3.0), seed=st.integers(0, 2**32 - 1))
def test_fresnel_is_in_unit_range_with_known_limits_and_reciprocity(dtype, eta, seed):
    rng = np.random.default_rng(seed)
    cos_i = rng.uniform(0, 1, 1024)
    R = np.asarray(fresnel_j(jnp.asarray(cos_i, dtype), jnp.asarray(eta, dtype)))
    assert R.dtype == dtype
    assert np.all((R >= 0) & (R <= 1))
    tol = TOL[dtype]
    ends = np.asarray(fresnel_j(jnp.asarray([1.0, 0.0], dtype), jnp.asarray(eta, dtype)))
    np.testing.assert_allclose(ends[0], ((eta - 1) / (eta + 1)) ** 2, atol=tol)
    assert ends[1] == 1  # grazing incidence reflects everything
    # Against the float64 kernel on the same (rounded) inputs.
    cos_r = cos_i.astype(dtype).astype(np.float64)
    eta_r = np.float64(dtype(eta))
    R64 = np.asarray(fresnel_j(jnp.asarray(cos_r), jnp.asarray(eta_r)))
    # R is ill-conditioned near the critical angle (dR/dcos_t ~ 1/cos_t): measured float32
    # error <= 20 eps / max(cos_t, 1e-3) over 800k lanes; the bound keeps 2x margin.
    cos_t = np.sqrt(np.maximum((1 - eta_r) * (1 + eta_r) + (eta_r * cos_r) ** 2, 0))
    eps = np.finfo(dtype).eps
    assert np.all(np.abs(R - R64) <= 40 * eps / np.maximum(cos_t, 1e-3) + tol / 10)
    # Stokes reciprocity: T(theta_i, eta) = T(theta_t, 1/eta), a float64 identity.
    sin_t2 = eta**2 * (1 - cos_i**2)
    ok = sin_t2 < 1 - 1e-3
    cos_t = np.sqrt(1 - sin_t2[ok])
    R64 = np.asarray(fresnel_j(jnp.asarray(cos_i[ok]), jnp.asarray(eta, jnp.float64)))
    T_back = np.asarray(fresnel_transmittance(jnp.asarray(cos_t), jnp.asarray(1 / eta)))
    np.testing.assert_allclose(1 - R64, T_back, atol=1e-12)
    assert np.all(R[sin_t2 > 1 + 1e-3] == 1)  # total internal reflection


def test_fresnel_matches_textbook_value_for_water():
    # Air -> water (n = 1.333) at 60 deg, by hand: sin_t = 0.8660 / 1.333 = 0.6497,
    # cos_t = 0.7602; r_s = (0.5 - 1.0134) / (0.5 + 1.0134) = -0.3392, r_p =
    # (0.6665 - 0.7602) / (0.6665 + 0.7602) = -0.0657; R = (0.1151 + 0.0043) / 2 = 0.0597.
    cos_i = np.cos(np.radians(60.0))
    n = 1.333
    cos_t = np.sqrt(1 - (np.sin(np.radians(60.0)) / n) ** 2)
    rs = ((cos_i - n * cos_t) / (cos_i + n * cos_t)) ** 2
    rp = ((n * cos_i - cos_t) / (n * cos_i + cos_t)) ** 2
    R = float(fresnel_reflectance(jnp.asarray(cos_i, jnp.float64), 1 / n))
    assert abs(R - (rs + rp) / 2) < 1e-12
    assert abs(R - 0.0597) < 2e-4


@pytest.mark.parametrize("dtype", DTYPES)
def test_beer_lambert_halves_over_the_half_length_and_ignores_what_is_not_a_path(dtype):
    """`A = exp(-sigma_t t)`: sigma_t = ln 2 / 0.5 m halves the energy every 0.5 m (1/2, 1/4,
    1/8 at 0.5, 1, 1.5 m, 1 at t = 0); a negative length attenuates nothing; clear water
    (sigma_t = 0) attenuates nothing even over an infinite length, murky water absorbs all
    of it; the dtype of `t` is kept. One call on one array per water."""
    sigma = np.log(2) / 0.5
    t = jnp.asarray([0.0, 0.5, 1.0, 1.5, -2.0, np.inf], dtype)
    A = np.asarray(beer_lambert(jnp.asarray(sigma, dtype), t))
    assert A.dtype == dtype
    np.testing.assert_allclose(A, [1, 0.5, 0.25, 0.125, 1, 0], rtol=TOL[dtype])
    clear = np.asarray(beer_lambert(jnp.asarray(0.0, dtype), t))
    np.testing.assert_array_equal(clear, np.ones(6))


@pytest.mark.parametrize("dtype", DTYPES)
def test_gradients_stay_finite_at_zero_vector_tir_and_grazing(dtype):
    g = jax.grad(lambda v: jnp.sum(safe_normalize(v)))(jnp.zeros(3, dtype))
    assert np.all(np.isfinite(g))
    I = jnp.asarray([0.9, 0.0, -np.sqrt(1 - 0.81)], dtype)
    N = jnp.asarray([0.0, 0.0, 1.0], dtype)
    g_tir = jax.grad(lambda i: jnp.sum(refract(i, N, 1.333)))(I)
    assert np.all(np.isfinite(g_tir))
    g_f = jax.grad(lambda c: fresnel_reflectance(c, 1.333))(jnp.asarray(0.0, dtype))
    assert np.isfinite(g_f)
    assert np.isfinite(jax.grad(lambda x: safe_sqrt(x))(jnp.asarray(0.0, dtype)))


def test_importing_the_package_does_not_enable_float64():
    code = "import caustics_jax, jax; print(jax.config.jax_enable_x64)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_precision_context_switches_float64_on_and_back_off():
    code = (
        "import caustics_jax as cj, jax.numpy as jnp\n"
        "with cj.precision('float64'):\n"
        "    a = jnp.zeros(2).dtype\n"
        "b = jnp.zeros(2).dtype\n"
        "print(a, b)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["float64", "float32"]
    with pytest.raises(ValueError, match="'float32' or 'float64'"):
        import caustics_jax as cj

        with cj.precision("int32"):
            pass


@pytest.mark.parametrize("dtype", DTYPES)
def test_safe_normalize_is_unit_in_range_and_zero_where_the_square_leaves_it(dtype):
    """As documented: a unit vector wherever `v . v` is a normal number of the dtype, the
    zero vector (never NaN) where it underflows or overflows; `path_vectors` reads such a
    lane as degenerate (`test_objectives`)."""
    info = np.finfo(dtype)
    d = np.array([0.6, -0.48, 0.64])
    inside = jnp.asarray(np.stack([d * s for s in (np.sqrt(float(info.tiny)) * 4, 1e-3, 1.0, 1e3,
                                                   np.sqrt(float(info.max)) / 4)]), dtype)
    np.testing.assert_allclose(np.asarray(safe_normalize(inside)), np.broadcast_to(d, inside.shape),
                               rtol=4 * float(info.eps))
    outside = jnp.asarray(np.stack([d * np.sqrt(float(info.tiny)) / 8, d * np.sqrt(float(info.max)) * 8]), dtype)
    assert np.all(np.asarray(safe_normalize(outside)) == 0)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_refraction_k_beyond_physical_ratios_is_tir_or_one_never_nan(dtype):
    """From |eta| = 16 `refraction_k` is `1 - (eta sin)^2`: the regrouped squares had cancelled
    (float64 eta = 1e30: a lane transmitted) or overflowed float32 (`inf - inf`: NaN eagerly,
    +inf under jit, every oblique ray transmitted). Compared with the oracle's sign in
    float64 (exact there for these values), and 1 exactly at normal incidence."""
    from caustics_jax.math.geometry import refraction_k
    from caustics_jax.testing.oracle import refraction_discriminant
    cos = np.array([-1.0, -0.999, -0.8, -0.3, 0.0, 0.5, 1.0])
    for eta in (16.0, 1e3, 1e19, 1e30, 3e38 if dtype == jnp.float32 else 1e300):
        c, e = jnp.asarray(cos, dtype), jnp.asarray(eta, dtype)
        for fn in (refraction_k, jax.jit(refraction_k)):
            k = np.asarray(fn(c, e))
            assert not np.isnan(k).any(), (eta, k)
            np.testing.assert_array_equal(k[np.abs(cos) == 1], 1.0)
            oblique = np.abs(cos) < 1
            with np.errstate(over="ignore"):
                want = refraction_discriminant(cos[oblique], np.float64(eta))
            np.testing.assert_array_equal(np.sign(k[oblique]), np.sign(want))
    # physical ratios keep the regrouped form: equal to the oracle to rounding
    cos = np.linspace(-1, 1, 41)
    for eta in (1 / 1.333, 1.333, 2.42, 15.9):
        k = np.asarray(refraction_k(jnp.asarray(cos, dtype), jnp.asarray(eta, dtype)))
        tol = 8 * float(jnp.finfo(dtype).eps) * eta**2
        np.testing.assert_allclose(k, refraction_discriminant(cos, eta), atol=tol, rtol=0)


def test_signed_sine_at_an_unphysical_eta_is_total_internal_reflection_not_a_root():
    """float32 signed_sine at eta = 1e30 had returned f = 0 with status OK on every record
    (refract's k was +inf under jit); float64 on one record in 107."""
    from caustics_jax.export import KERNELS
    from caustics_jax.math.objectives import ObjectiveStatus, signed_sine_and_status
    x, _ = KERNELS["signed_sine"].generate(np.random.default_rng(0), 32)
    for dtype in (jnp.float32, jnp.float64):
        args = [jnp.asarray(x[k], dtype) for k in ("V", "N", "P", "L", "ab")]
        ok_at_1 = np.asarray(jax.jit(signed_sine_and_status)(*args, jnp.ones(len(x["eta"]), dtype))[1]) == 0
        _, status = jax.jit(signed_sine_and_status)(*args, jnp.full(len(x["eta"]), 1e30, dtype))
        status = np.asarray(status)
        assert ok_at_1.sum() > 50  # the records are ordinary paths
        assert not np.any(status == ObjectiveStatus.OK)
        assert np.all(status[ok_at_1] == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION)


def test_refraction_k_derivative_beyond_physical_ratios_is_exact_at_normal_incidence():
    """d k / d cos = 2 eta^2 cos: the large-eta form had used a sqrt, whose derivative at
    |cos| = 1 is cut to 0 (0 instead of -800 at eta = 20)."""
    from caustics_jax.math.geometry import refraction_k
    for dtype in (jnp.float32, jnp.float64):
        for eta in (1.333, 20.0, 1e3):
            for cos in (-1.0, -0.6, 1.0):
                g = jax.grad(refraction_k)(jnp.asarray(cos, dtype), jnp.asarray(eta, dtype))
                np.testing.assert_allclose(float(g), 2 * eta**2 * cos, rtol=1e-6)
