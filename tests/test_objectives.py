"""Objectives at planted refracted paths (seed 001 eq. 16-21; MATH.md §4)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax import (
    ObjectiveStatus,
    angle_difference_residual,
    conic_coefficients,
    half_vector_residual,
    signed_sine_and_status,
    solve_quadratic,
)
from caustics_jax.testing import oracle, planted_paths

DTYPES = [jnp.float32, jnp.float64]
# Objective values at planted solutions (float64 M rounded to the dtype). Measured maxima
# (experiments/float32_audit.py, 200k paths): float32 |f| 9.8e-7, half-vector 2.4e-6,
# angle 9.5e-7; float64 at most 4.6e-15. Bounds keep >= 6x margin.
ZERO_TOL = {jnp.float32: 1.5e-5, jnp.float64: 1e-12}

objectives_j = jax.jit(
    lambda V, N, P, L, ab, eta: (
        signed_sine_and_status(V, N, P, L, ab, eta),
        half_vector_residual(V, N, P, L, ab, eta),
        angle_difference_residual(V, N, P, L, ab, eta),
    )
)


def _cast(p, dtype):
    return [jnp.asarray(x, dtype) for x in (p.V, p.N, p.P, p.L, p.ab)]


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1), eta=st.sampled_from([1.333, 1.5, 1.1]))
def test_every_objective_vanishes_at_planted_solutions(dtype, seed, eta):
    p = planted_paths(seed, 512, eta=eta)
    (f, status), h, ang = objectives_j(*_cast(p, dtype), eta)
    assert f.dtype == h.dtype == ang.dtype == dtype
    assert np.all(np.asarray(status) == ObjectiveStatus.OK)
    tol = ZERO_TOL[dtype]
    assert np.max(np.abs(np.asarray(f))) < tol
    assert np.max(np.abs(np.asarray(h))) < tol
    assert np.max(np.abs(np.asarray(ang))) < tol


def _signed_sine_reference(V, N, P, L, ab, eta):
    """Float64 numpy seed 001 eq. 19-21 on the oracle, independent of the package's kernels."""
    M = oracle.barycentric_point(V, ab)
    n_s = oracle.shading_normal(N, ab)
    w_P, w_L = oracle.unit(P - M), oracle.unit(L - M)
    c = np.cross(oracle.refract(-w_P, -n_s, eta), w_L)
    # tangent from the gradient of n~ . (PL x PM) w.r.t. (a, b), by central differences
    def g(ab_):
        M_ = oracle.barycentric_point(V, ab_)
        return np.sum(oracle.interpolated_normal(N, ab_) * np.cross(L - P, M_ - P), -1)
    h = 1e-6
    ga = (g(ab + [h, 0]) - g(ab - [h, 0])) / (2 * h)
    gb = (g(ab + [0, h]) - g(ab - [0, h])) / (2 * h)
    t_world = -gb[:, None] * (V[:, 1] - V[:, 0]) + ga[:, None] * (V[:, 2] - V[:, 0])
    return np.sign(np.sum(t_world * c, -1)) * np.linalg.norm(c, axis=-1)


def _points_on_curve_near(p, coef, da):
    """Points of the conic at `a + da`, on the branch through the planted `ab`."""
    a = p.ab[:, 0] + da
    q = oracle.conic_on_line(coef, np.stack([a, np.zeros_like(a)], -1), np.array([0.0, 1.0]))  # the line a = const
    b, valid = (np.asarray(x) for x in solve_quadratic(*(jnp.asarray(x) for x in q)))
    pick = np.argmin(np.where(valid, np.abs(b - p.ab[:, 1:]), np.inf), -1)
    b_near = np.take_along_axis(b, pick[:, None], -1)[:, 0]
    ok = valid.any(-1) & (np.abs(b_near - p.ab[:, 1]) < 20 * abs(da))
    return np.stack([a, b_near], -1), ok


def test_signed_sine_matches_independent_reference_including_sign():
    p = planted_paths(21, 512)
    coef = conic_coefficients(*(jnp.asarray(x) for x in (p.V, p.N, p.P, p.L)))
    ab, ok = _points_on_curve_near(p, coef, 0.03)
    f, status = signed_sine_and_status(*(jnp.asarray(x) for x in (p.V, p.N, p.P, p.L, ab)), p.eta)
    ref = _signed_sine_reference(p.V, p.N, p.P, p.L, ab, p.eta)
    ok &= np.asarray(status) == 0
    assert ok.mean() > 0.9
    np.testing.assert_allclose(np.asarray(f)[ok], ref[ok], rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("dtype", DTYPES)
def test_signed_sine_changes_sign_across_planted_solution_along_the_curve(dtype):
    """The orientation s of eq. 21 makes f continuous through its zero: f(-h) f(+h) < 0.

    Without the sign (f = |sin|) every bracket test of the walk would fail.
    """
    p = planted_paths(23, 1024)
    coef = conic_coefficients(*(jnp.asarray(x) for x in (p.V, p.N, p.P, p.L)))
    h = 2e-3
    sides = []
    ok = np.ones(len(p.ab), bool)
    for da in (-h, h):
        ab, ok_side = _points_on_curve_near(p, coef, da)
        f, status = objectives_j(*_cast(p._replace(ab=ab), dtype), p.eta)[0]
        sides.append(np.asarray(f))
        ok &= ok_side & (np.asarray(status) == 0)
    assert ok.mean() > 0.9
    f_minus, f_plus = sides
    assert np.all(f_minus[ok] * f_plus[ok] < 0)
    # and away from the solution the objectives are clearly non-zero
    assert np.min(np.abs(f_plus[ok])) > 1e-6
    ab_far, ok_far = _points_on_curve_near(p, coef, 0.05)
    _, h_far, ang_far = objectives_j(*_cast(p._replace(ab=ab_far), dtype), p.eta)
    assert np.median(np.linalg.norm(np.asarray(h_far)[ok_far], axis=-1)) > 1e-3
    assert np.median(np.linalg.norm(np.asarray(ang_far)[ok_far], axis=-1)) > 1e-3


@pytest.mark.parametrize("dtype", DTYPES)
def test_total_internal_reflection_is_reported_not_mistaken_for_a_root(dtype):
    p = planted_paths(29, 256)
    # Move P far sideways so that -w_P is beyond the critical angle at M.
    P_tir = p.M + np.array([8.0, 0.0, -0.5])
    f, status = objectives_j(*_cast(p._replace(P=P_tir), dtype), p.eta)[0]
    f, status = np.asarray(f), np.asarray(status)
    cos_i = np.sum(oracle.shading_normal(p.N, p.ab) * oracle.unit(P_tir - p.M), -1)
    k = oracle.refraction_discriminant(cos_i, p.eta)
    clear = np.abs(k) > 1e-3
    assert (k < -1e-3).mean() > 0.8
    np.testing.assert_array_equal(status[clear] == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION, k[clear] < 0)
    assert np.all(f[status == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION] == 0)  # status tells


@pytest.mark.parametrize("dtype", DTYPES)
def test_degenerate_inputs_give_status_and_finite_values(dtype):
    p = planted_paths(31, 64)
    # P exactly at M = V0 (ab = 0): w_P is undefined
    at_v0 = p._replace(P=p.V[:, 0], ab=np.zeros_like(p.ab))
    (f, status), h, ang = objectives_j(*_cast(at_v0, dtype), p.eta)
    assert np.all(np.asarray(status) == ObjectiveStatus.DEGENERATE)
    for x in (f, h, ang):
        assert np.all(np.isfinite(np.asarray(x)))
    grads = jax.grad(lambda ab: jnp.sum(objectives_j(*_cast(p, dtype)[:4], ab, p.eta)[1]))(
        jnp.asarray(p.ab, dtype))
    assert np.all(np.isfinite(np.asarray(grads)))


def test_tangent_orientation_degenerates_with_constant_normals_while_plane_does_not():
    """Why the solvers orient f by "plane", not by the paper's tangent (eq. 20-21).

    With constant normals the curve is a line in the plane through P, L and n, and r, w_L
    and the tangent all lie in that plane: `t . (r x w_L)` vanishes up to rounding, so the
    paper's sign is noise. `(r x w_L) . (PL x n_s)` compares two normals of that plane and
    stays of order one, and the "plane" f changes sign across the solution.
    """
    from caustics_jax import conic_tangent, refract, tangent_to_world
    from caustics_jax.objectives import path_vectors

    p = planted_paths(31, 512, normal_spread=0.0)
    assert np.allclose(p.N, p.N[:, :1])  # constant normals: a line, not a conic
    coef = conic_coefficients(*(jnp.asarray(x) for x in (p.V, p.N, p.P, p.L)))
    ok = np.ones(len(p.ab), bool)
    f_sides = []
    for da in (-0.02, 0.02):
        ab, ok_side = _points_on_curve_near(p, coef, da)
        V, N, P, L, abj = (jnp.asarray(x) for x in (p.V, p.N, p.P, p.L, ab))
        _, n_s, w_P, w_L, _ = path_vectors(V, N, P, L, abj)
        c = np.asarray(jnp.cross(refract(-w_P, -n_s, p.eta), w_L))
        t = np.asarray(tangent_to_world(V, conic_tangent(coef, abj)))
        q = np.cross(p.L - p.P, np.asarray(n_s))
        unit = lambda x: x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-300)  # noqa: E731
        tangent_cos = np.abs(np.sum(unit(t) * unit(c), -1))
        plane_cos = np.abs(np.sum(unit(q) * unit(c), -1))
        f, status = signed_sine_and_status(V, N, P, L, abj, p.eta, orientation="plane")
        good = ok_side & (np.asarray(status) == ObjectiveStatus.OK)
        ok &= good
        assert np.max(tangent_cos[good]) < 1e-10  # measured max 4.8e-13 (rounding)
        # measured min 1 - 3e-16: r x w_L and PL x n_s are the same plane normal
        assert np.min(plane_cos[good]) > 0.999
        f_sides.append(np.asarray(f))
    assert ok.mean() > 0.9
    assert np.all(f_sides[0][ok] * f_sides[1][ok] < 0)
