"""Objectives at planted refracted paths (seed 001 eq. 16-21; math.md §4)."""

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


@pytest.mark.parametrize("dtype", DTYPES)
def test_refracted_direction_is_w_L_at_planted_solutions(dtype):
    """`refracted_direction` = `refract(-w_P, -n_s, eta)` (seed 001 eq. 19) equals `w_L` on a path."""
    from caustics_jax.math.objectives import refracted_direction

    p = planted_paths(19, 256)
    r = np.asarray(refracted_direction(*_cast(p, dtype), p.eta))
    assert r.dtype == dtype
    # measured max abs component error 4.3e-7 (float32), 6.7e-16 (float64)
    np.testing.assert_allclose(r, oracle.unit(p.L - p.M), atol={jnp.float32: 2e-6, jnp.float64: 1e-13}[dtype])


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
    """The orientation s of eq. 20 makes f continuous through its zero: f(-h) f(+h) < 0.

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
    from caustics_jax.math.objectives import path_vectors

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


def _m0_barycentric(V, P, L):
    """`(a, b)` of `M0`, where the line PL meets the triangle's plane (seed 001 §3.4.2)."""
    E1, E2 = V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
    n_g = np.cross(E1, E2)
    s = np.sum(n_g * (V[:, 0] - P), -1) / np.sum(n_g * (L - P), -1)
    X = P + s[:, None] * (L - P)
    G = np.stack([E1, E2], -1)
    Gt = np.swapaxes(G, -1, -2)
    return np.linalg.solve(Gt @ G, Gt @ (X - V[:, 0])[..., None])[..., 0]


def test_tangent_orientation_flips_at_M0_while_plane_does_not():
    """The paper's sign (eq. 20) flips where M crosses the line PL; "plane"'s does not.

    Near `M0` the plane through P, L, M turns around PL, and `t . (r x w_L)` is proportional
    to the distance of M from PL times that turning rate, so it changes sign at `M0` even
    though `|r x w_L|` stays of order one there (no root). `PL x n_s` is continuous through
    `M0`, so the "plane" f keeps its sign. Curved triangles (normal_spread 0.3), float64.
    """
    p = planted_paths(37, 64, normal_spread=0.3)
    coef = conic_coefficients(*(jnp.asarray(x) for x in (p.V, p.N, p.P, p.L)))
    p0 = p._replace(ab=_m0_barycentric(p.V, p.P, p.L))
    (ab_minus, ok_minus), (ab_plus, ok_plus) = (_points_on_curve_near(p0, coef, da) for da in (-1e-3, 1e-3))
    # the three points per lane (before, at, after M0) in one batch: one compile
    args = [jnp.asarray(np.concatenate([x] * 3)) for x in (p.V, p.N, p.P, p.L)]
    ab = jnp.asarray(np.concatenate([ab_minus, p0.ab, ab_plus]))
    both = jax.jit(lambda *a: [signed_sine_and_status(*a, p.eta, o) for o in ("tangent", "plane")])
    (f_tan, status), (f_plane, _) = both(*args, ab)
    f_tan, f_plane, status = (np.asarray(x).reshape(3, -1) for x in (f_tan, f_plane, status))
    ok = ok_minus & ok_plus & np.all(status == ObjectiveStatus.OK, 0)
    assert ok.mean() > 0.5  # measured 0.69 (the rest: curve nearly parallel to a = const)
    assert np.min(np.abs(f_plane[1])[ok]) > 1e-2  # |r x w_L| at M0: measured min 0.037
    assert np.min(np.abs(f_tan[[0, 2]])[:, ok]) > 1e-2  # measured min 0.036: no rounding noise
    assert np.all(f_tan[0][ok] * f_tan[2][ok] < 0)
    assert np.all(f_plane[0][ok] * f_plane[2][ok] > 0)


def test_a_path_whose_lengths_overflow_the_dtype_is_degenerate_not_a_root():
    """float32, a unit triangle scaled by 1e19: `P - M` squares past the range, normalises to
    0, and the sine came out 0 with status OK (a false root). Now DEGENERATE; at 1e8 (inside
    `arguments.scale_range`) the sine is the unit-scale one."""
    V = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    N = np.tile(np.float32([0, 0, 1]), (3, 1))
    P, L, ab = np.float32([0.2, 0.3, -1]), np.float32([0.4, 0.2, 3]), np.float32([0.3, 0.3])
    s = np.float32([1.0, 1e8, 1e19])[:, None]
    f, status = (np.asarray(x) for x in signed_sine_and_status(V * s[:, None], N, P * s, L * s, ab, 1.333))
    assert list(status) == [ObjectiveStatus.OK, ObjectiveStatus.OK, ObjectiveStatus.DEGENERATE]
    np.testing.assert_allclose(f[1], f[0], rtol=1e-5)
    assert f[0] != 0


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_receiver_mirrored_beyond_the_shading_plane_is_backward_not_a_root(dtype):
    """`refract(-w_P, -n_s, eta)` keeps the tangential part of `w_P` and rebuilds the
    normal one, so `P` mirrored across the shading plane at `M` gives the same refracted
    ray and `f = 0` again: a spurious root with `P` outside the medium. `bracket_objective`
    (what every solver brackets and accepts) reports BACKWARD there; the plain signed sine
    still vanishes (it only describes the formula)."""
    from caustics_jax.math.objectives import bracket_objective

    p = planted_paths(37, 256)
    n_s = oracle.shading_normal(p.N, p.ab)
    up = p.P - 2 * np.sum((p.P - p.M) * n_s, -1, keepdims=True) * n_s
    run = jax.jit(jax.vmap(lambda V, N, P, L, ab: bracket_objective(V, N, P, L, ab[None], p.eta)))
    for P, want in ((p.P, ObjectiveStatus.OK), (up, ObjectiveStatus.BACKWARD)):
        V, N, P_, L, ab = _cast(p._replace(P=P), dtype)
        f, status, _ = (np.asarray(x)[:, 0] for x in run(V, N, P_, L, ab))
        assert np.all(status == want)
        assert np.max(np.abs(f)) < ZERO_TOL[dtype]  # a root of f in both cases
    f_up, st_up = objectives_j(*_cast(p._replace(P=up), dtype), p.eta)[0]
    assert np.all(np.asarray(st_up) == ObjectiveStatus.OK) and np.max(np.abs(np.asarray(f_up))) < ZERO_TOL[dtype]


@pytest.mark.parametrize("dtype, rtol", [(jnp.float64, 1e-13), (jnp.float32, 2e-6)])
def test_the_closed_form_half_vector_jacobian_is_jacfwds(dtype, rtol):
    """`half_vector_residual_and_jacobian` (the one-step Newton's Jacobian) against
    `jax.jacfwd` of `half_vector_residual` on 4,096 random triangles, normals tilted both
    ways across the frame's `n_z = 0` switch, `eta` on both sides of 1: the residual bit
    for bit and the Jacobian relative to its largest entry (measured 4.0e-16 in float64
    and 1.4e-7 in float32); dropping the frame's derivative fails it."""
    from caustics_jax.math.objectives import half_vector_residual_and_jacobian

    rng = np.random.default_rng(5)
    n = 4096
    V = rng.normal(0, 1, (n, 3, 3)) * [1, 1, 0.1]
    N = rng.normal(0, 0.2, (n, 3, 3)) + [0, 0, 1]
    N = N / np.linalg.norm(N, axis=-1, keepdims=True) * np.where(np.arange(n) % 4 == 0, -1, 1)[:, None, None]
    ab = rng.uniform(0, 0.5, (n, 2))
    P = np.column_stack([rng.normal(0, 1, (n, 2)), np.full(n, -1.0)])
    L = np.column_stack([rng.normal(0, 1, (n, 2)), np.full(n, 3.0)])
    eta = np.where(np.arange(n) % 2 == 0, 1.333, 0.75)
    args = [jnp.asarray(x, dtype) for x in (V, N, P, L, ab, eta)]

    def reference(v, n_, p, l, x, e):
        C = lambda y: half_vector_residual(v, n_, p, l, y, e)  # noqa: E731
        return C(x), jax.jacfwd(C)(x)

    r, J = jax.jit(jax.vmap(half_vector_residual_and_jacobian))(*args)
    r0, J0 = jax.jit(jax.vmap(reference))(*args)
    np.testing.assert_allclose(np.asarray(r), np.asarray(r0), rtol=0, atol=4 * float(jnp.finfo(dtype).eps))
    scale = float(jnp.max(jnp.abs(J0)))
    assert float(jnp.max(jnp.abs(J - J0))) <= rtol * scale
