"""Properties of the coplanarity conic (seed 001 eq. 9-15, 22-24; math.md §2-3)."""

from decimal import Decimal, getcontext

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax import conic_coefficients, conic_tangent, edge_intersections
from caustics_jax.math.conic import (
    conic_centre,
    conic_matrix,
    conic_second_intersection,
    conic_value,
    edge_intersection_points,
    edge_quadratics,
    solve_quadratic,
    symmetric_matrix,
)
from caustics_jax.testing import oracle, random_triangles

DTYPES = [jnp.float32, jnp.float64]
# Relative triple-product residual |n~ . (PL x PM)| / (|n~| |PL| |PM|) at points that are
# exactly on the curve in float64. Measured float32 maxima (experiments/float32_audit.py,
# 200k paths): 6.3e-7 at M0, 5.4e-6 at edge roots (tests use 4x RESID_TOL there).
# float64 measured below 1e-14.
RESID_TOL = {jnp.float32: 3e-5, jnp.float64: 1e-13}

coef_j = jax.jit(conic_coefficients)
edges_j = jax.jit(edge_intersections)


def _config(seed, n, dtype=np.float64):
    """Random triangles with a line P -> L through a known point X of the triangle's plane."""
    rng = np.random.default_rng(seed)
    V, N = random_triangles(rng, n, normal_spread=0.5)
    w = rng.dirichlet([1.0, 1.0, 1.0], n)
    ab_x = w[:, 1:] * rng.uniform(-0.5, 1.5, (n, 1))  # inside and outside the triangle
    X = oracle.barycentric_point(V, ab_x)
    u = rng.normal(size=(n, 3)) * [0.4, 0.4, 0.0] + [0.0, 0.0, 1.0]
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    P = X - rng.uniform(0.2, 3.0, (n, 1)) * u
    L = X + rng.uniform(0.5, 6.0, (n, 1)) * u
    return V, N, P, L, ab_x


def triple_product_residual(V, N, P, L, ab):
    """Float64 |n~ . (PL x PM)| / (|n~| |PL| |PM|) by the oracle, independent of the code under test."""
    return oracle.triple_product(*(np.asarray(x, np.float64) for x in (V, N, P, L, ab)), relative=True)


def conic_residual(coef, V, N, P, L, ab):
    """|conic(ab)| normalised like `triple_product_residual` (the conic *is* that product)."""
    ab64 = np.asarray(ab, np.float64)
    val = np.abs(np.asarray(conic_value(jnp.asarray(coef), jnp.asarray(ab, coef.dtype)), np.float64))
    V, N, P, L = (np.asarray(x, np.float64) for x in (V, N, P, L))
    M, n = oracle.barycentric_point(V, ab64), oracle.interpolated_normal(N, ab64)
    den = np.linalg.norm(n, axis=-1) * np.linalg.norm(L - P, axis=-1) * np.linalg.norm(M - P, axis=-1)
    return val / den


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1))
def test_start_point_lies_on_conic_for_arbitrary_normals(dtype, seed):
    V, N, P, L, ab0 = _config(seed, 512)
    args = [jnp.asarray(x, dtype) for x in (V, N, P, L)]
    coef = coef_j(*args)
    assert coef.shape == (512, 6) and coef.dtype == dtype
    assert np.all(conic_residual(coef, V, N, P, L, ab0) < RESID_TOL[dtype])


def test_conic_is_the_triple_product_everywhere():
    """x^T K x equals n~ . (PL x PM) at arbitrary (a, b), not only on the curve (eq. 9-10)."""
    V, N, P, L, _ = _config(11, 256)
    ab = np.random.default_rng(1).uniform(-1, 2, (256, 2))
    coef = coef_j(*(jnp.asarray(x) for x in (V, N, P, L)))
    expected = oracle.triple_product(V, N, P, L, ab)
    np.testing.assert_allclose(np.asarray(conic_value(coef, jnp.asarray(ab))), expected,
                               rtol=1e-11, atol=1e-12)
    K = np.asarray(conic_matrix(*(jnp.asarray(x) for x in (V, N, P, L))))
    assert np.max(np.abs(K - np.swapaxes(K, -1, -2))) > 1e-3  # K is genuinely not symmetric


def test_symmetric_matrix_is_the_symmetric_part_of_K():
    """`symmetric_matrix(A..F)` rebuilds `S = (K + K^T) / 2` of math.md §2 from the six coefficients."""
    V, N, P, L, _ = _config(19, 64)
    args = [jnp.asarray(x) for x in (V, N, P, L)]
    K = np.asarray(conic_matrix(*args))
    S = np.asarray(symmetric_matrix(coef_j(*args)))
    np.testing.assert_allclose(S, (K + np.swapaxes(K, -1, -2)) / 2, rtol=1e-12, atol=1e-14)


def test_second_intersection_is_the_other_root_of_the_conic_on_the_line():
    """`conic_second_intersection` from `M0` (on the conic) against `oracle.conic_on_line`.

    On the line `ab0 + s d` the conic is `q2 s^2 + q1 s + q0` with `q0 = 0` at a curve
    point, so the other point is at `s = -q1 / q2` (float64, numpy).
    """
    V, N, P, L, ab0 = _config(17, 256)
    d = np.random.default_rng(17).normal(size=(256, 2))
    coef = coef_j(*(jnp.asarray(x) for x in (V, N, P, L)))
    ab, ok = (np.asarray(x) for x in conic_second_intersection(coef, jnp.asarray(ab0), jnp.asarray(d)))
    q2, q1, _ = oracle.conic_on_line(np.asarray(coef), ab0, d)
    s = -q1 / q2
    near = np.abs(s) < 10  # farther: the line is nearly parallel to an asymptote
    assert near.mean() > 0.8 and np.all(ok[near])  # measured 0.95
    want = ab0 + s[:, None] * d
    err = np.linalg.norm(ab - want, axis=-1) / (np.linalg.norm(ab0, axis=-1) + np.linalg.norm(want, axis=-1))
    assert np.max(err[near]) < 1e-10  # measured 3.1e-14
    assert np.all(conic_residual(coef, V, N, P, L, ab)[near] < RESID_TOL[jnp.float64])  # measured 1.7e-15


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1))
def test_points_solved_onto_conic_satisfy_triple_product(dtype, seed):
    V, N, P, L, _ = _config(seed, 512)
    coef = coef_j(*(jnp.asarray(x, dtype) for x in (V, N, P, L)))
    a = np.random.default_rng(seed).uniform(0, 1, 512).astype(dtype)
    # For fixed a the conic is a quadratic in b: B b^2 + (C a + E) b + (A a^2 + D a + F),
    # evaluated in `dtype` (the oracle's conic on the line (a, 0) + t (0, 1)).
    q = oracle.conic_on_line(np.asarray(coef), np.stack([a, np.zeros_like(a)], -1), np.array([0, 1], dtype))
    b, valid = solve_quadratic(*(jnp.asarray(x) for x in q))
    b, valid = np.asarray(b), np.asarray(valid)
    for k in range(2):
        ok = valid[:, k] & (np.abs(b[:, k]) < 10)
        ab = np.stack([a[ok], b[ok, k]], -1)
        assert np.all(triple_product_residual(V[ok], N[ok], P[ok], L[ok], ab) < 4 * RESID_TOL[dtype])
    assert valid[:, 0].mean() > 0.5  # the property is exercised on most lanes


@pytest.mark.parametrize("dtype", DTYPES)
def test_constant_normals_give_the_line_through_the_projections_of_P_and_L(dtype):
    """n0 = n1 = n2 = n: the conic is the line through P and L projected along n (eq. 1-2)."""
    V, _, P, L, _ = _config(5, 512)
    rng = np.random.default_rng(5)
    n = rng.normal(size=(512, 3)) * [0.3, 0.3, 0] + [0, 0, 1]
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    N = np.repeat(n[:, None], 3, axis=1)
    coef = np.asarray(coef_j(*(jnp.asarray(x, dtype) for x in (V, N, P, L))))
    assert np.all(coef[:, :3] == 0)  # A = B = C = 0: no quadratic part
    g = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    for X in (P, L):
        s = np.sum((V[:, 0] - X) * g, -1) / np.sum(n * g, -1)
        Xp = X + s[:, None] * n
        E = np.stack([V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]], -1)
        ab = np.linalg.lstsq(E[0], (Xp - V[:, 0])[0], rcond=None)[0]  # warm-up shape check
        ab = np.stack([np.linalg.lstsq(E[i], Xp[i] - V[i, 0], rcond=None)[0] for i in range(512)])
        assert ab.shape == (512, 2)
        assert np.all(conic_residual(jnp.asarray(coef), V, N, P, L, ab) < RESID_TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_conic_centre_is_the_planted_centre_where_the_gradient_vanishes(dtype):
    """Conics `A a^2 + B b^2 + C ab + D a + E b + F` built around a planted centre `(a0, b0)`
    (`D = -(2A a0 + C b0)`, `E = -(C a0 + 2B b0)`, seed 001 eq. 11): `conic_centre` returns
    it for ellipses, the autodiff gradient vanishes there, and only `4AB - C^2 > 0` is called
    an ellipse (elsewhere the centre is finite and unused).
    A swapped `D`/`E` or a sign error moves the centre off the planted one."""
    rng = np.random.default_rng(11)
    n = 512
    A, B = rng.uniform(0.2, 2, n), rng.uniform(0.2, 2, n)
    C = rng.uniform(-3, 3, n)
    a0, b0 = rng.uniform(-1, 2, n), rng.uniform(-1, 2, n)
    coef64 = np.stack([A, B, C, -(2 * A * a0 + C * b0), -(C * a0 + 2 * B * b0), rng.uniform(-1, 1, n)], -1)
    coef = jnp.asarray(coef64, dtype)
    a_c, b_c, ellipse = conic_centre(coef)
    assert np.array_equal(np.asarray(ellipse), 4 * A * B - C * C > 0)
    det = 4 * A * B - C * C
    keep = det > 0.05  # ellipses away from parabolas, where the centre recedes to infinity
    assert keep.sum() > 100 and (det < 0).sum() > 100
    assert np.all(np.isfinite(np.asarray(a_c))) and np.all(np.isfinite(np.asarray(b_c)))  # elsewhere: finite
    err = np.abs(np.stack([np.asarray(a_c) - a0, np.asarray(b_c) - b0]))[:, keep] * det[keep] / 8
    # measured max 3.2e-7 (float32) and 5.7e-16 (float64), in units of |coef| / |4AB - C^2|
    assert np.max(err) < {jnp.float32: 2e-6, jnp.float64: 4e-15}[dtype]
    grad = jax.vmap(jax.grad(conic_value, argnums=1))(coef, jnp.stack([a_c, b_c], -1))
    # measured max 7.2e-6 (float32) and 9.3e-15 (float64)
    assert np.max(np.abs(np.asarray(grad))[keep]) < {jnp.float32: 1e-4, jnp.float64: 1e-13}[dtype]


@pytest.mark.parametrize("dtype", DTYPES)
def test_tangent_matches_autodiff_of_the_conic(dtype):
    V, N, P, L, ab0 = _config(9, 256)
    coef = coef_j(*(jnp.asarray(x, dtype) for x in (V, N, P, L)))
    ab = jnp.asarray(ab0, dtype)
    grad = jax.vmap(jax.grad(lambda c, x: conic_value(c, x), argnums=1))(coef, ab)
    t = conic_tangent(coef, ab)
    expected = 0.5 * jnp.stack([-grad[:, 1], grad[:, 0]], -1)
    scale = np.max(np.abs(np.asarray(coef)), -1, keepdims=True)
    err = np.abs(np.asarray(t - expected)) / scale
    assert np.max(err) < {jnp.float32: 1e-6, jnp.float64: 1e-15}[dtype]
    assert np.all(np.abs(np.sum(np.asarray(t) * np.asarray(grad), -1)) / scale[:, 0] ** 2 < 1e-5)


def test_paper_tangent_with_K_transpose_is_wrong_away_from_M0():
    """Seed 001 eq. 14 multiplies by K^T: not perpendicular to the gradient unless K = K^T.

    At `M0` itself `Q x = PL x PM0 = 0`, so `K^T x = 2 S x` and the paper's form happens to
    be right there; at other points of the curve it is not.
    """
    V, N, P, L, ab0 = _config(13, 512)
    args = [jnp.asarray(x) for x in (V, N, P, L)]
    K = np.asarray(conic_matrix(*args))
    coef = coef_j(*args)
    a = np.random.default_rng(13).uniform(0, 1, 512)
    q = oracle.conic_on_line(np.asarray(coef), np.stack([a, np.zeros_like(a)], -1), np.array([0.0, 1.0]))
    b, valid = (np.asarray(x) for x in solve_quadratic(*(jnp.asarray(x) for x in q)))
    ok = valid[:, 0] & (np.abs(b[:, 0]) < 10)
    ab = np.stack([a, b[:, 0]], -1)[ok]
    grad = np.asarray(jax.vmap(jax.grad(conic_value, argnums=1))(coef[ok], jnp.asarray(ab)))

    def cos_to_gradient(t):
        return np.abs(np.sum(t * grad, -1)) / (np.linalg.norm(t, axis=-1) * np.linalg.norm(grad, axis=-1))

    for x, on_M0 in ((np.concatenate([ab0[ok], np.ones((ok.sum(), 1))], -1), True),
                     (np.concatenate([ab, np.ones((ok.sum(), 1))], -1), False)):
        uvw = np.einsum("nji,nj->ni", K[ok], x)  # the paper's K^T x
        t_paper = np.stack([-uvw[:, 1], uvw[:, 0]], -1)
        if on_M0:
            t_ok = np.asarray(conic_tangent(coef[ok], jnp.asarray(x[:, :2])))
            np.testing.assert_allclose(t_paper, 2 * t_ok, rtol=1e-9, atol=1e-12)
        else:
            assert np.median(cos_to_gradient(t_paper)) > 1e-2
    t = np.asarray(conic_tangent(coef[ok], jnp.asarray(ab)))
    assert np.max(cos_to_gradient(t)) < 1e-12


def _reference_roots(q):
    """Roots of each quadratic by companion-matrix eigenvalues (float64, a different algorithm)."""
    out = []
    for q2, q1, q0 in q.reshape(-1, 3):
        r = np.roots([q2, q1, q0]) if np.any([q2, q1, q0]) else np.array([])
        out.append(np.sort(r[np.abs(r.imag) < 1e-12].real) if r.size else r)
    return out


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1))
def test_edge_roots_lie_on_the_conic_and_match_float64_reference(dtype, seed):
    V, N, P, L, _ = _config(seed, 256)
    coef = coef_j(*(jnp.asarray(x, dtype) for x in (V, N, P, L)))
    t, valid = (np.asarray(x) for x in edges_j(coef))
    assert t.shape == valid.shape == (256, 3, 2)
    ab = np.asarray(edge_intersection_points(jnp.asarray(t)))
    lanes = np.nonzero(valid)
    Vx, Nx, Px, Lx = V[lanes[0]], N[lanes[0]], P[lanes[0]], L[lanes[0]]
    assert valid.sum() > 50
    res = triple_product_residual(Vx, Nx, Px, Lx, ab[lanes])
    assert np.max(res) < 4 * RESID_TOL[dtype]
    # Against float64 eigenvalue roots of the same (float64) edge quadratics: every
    # well-conditioned root inside (0, 1) is found, to a tolerance set by its conditioning.
    q64 = np.asarray(edge_quadratics(coef_j(*(jnp.asarray(x) for x in (V, N, P, L)))))
    ref = _reference_roots(q64)
    eps = np.finfo(dtype).eps
    for i, r in enumerate(ref):
        lane, edge = divmod(i, 3)
        q2, q1, _ = q64[lane, edge]
        scale = np.max(np.abs(q64[lane, edge]))
        for root in r:
            slope = abs(2 * q2 * root + q1) / scale
            if 1e-3 < root < 1 - 1e-3 and slope > 1e-2:
                found = t[lane, edge][valid[lane, edge]]
                assert found.size and np.min(np.abs(found - root)) < 2e3 * eps / slope


@pytest.mark.parametrize("dtype", DTYPES)
def test_paper_edge_quadratics_22_23_give_points_off_the_conic(dtype):
    """Eq. 22 (B b^2 + D b + F) and eq. 23 (A a^2 + C a + F) are misprints; eq. 24 is right."""
    V, N, P, L, _ = _config(17, 512)
    coef = np.asarray(coef_j(*(jnp.asarray(x, dtype) for x in (V, N, P, L))))
    A, B, C, D, E, F = np.moveaxis(coef, -1, 0)
    for (q2, q1, q0), make_ab in (
        ((B, D, F), lambda t: np.stack([np.zeros_like(t), t], -1)),  # eq. 22 on a = 0
        ((A, C, F), lambda t: np.stack([t, np.zeros_like(t)], -1)),  # eq. 23 on b = 0
    ):
        t, valid = (np.asarray(x) for x in solve_quadratic(*(jnp.asarray(x) for x in (q2, q1, q0))))
        ok = valid[:, 0] & (t[:, 0] > 0) & (t[:, 0] < 1)
        res = conic_residual(jnp.asarray(coef[ok]), V[ok], N[ok], P[ok], L[ok], make_ab(t[ok, 0]))
        assert ok.sum() > 20 and np.median(res) > 100 * RESID_TOL[dtype]


getcontext().prec = 60


def _decimal_roots(q2, q1, q0):
    q2, q1, q0 = Decimal(float(q2)), Decimal(float(q1)), Decimal(float(q0))
    if q2 == 0:
        return [] if q1 == 0 else [-q0 / q1]
    disc = q1 * q1 - 4 * q2 * q0
    if disc < 0:
        return []
    s = disc.sqrt()
    return sorted([(-q1 - s) / (2 * q2), (-q1 + s) / (2 * q2)])


@pytest.mark.parametrize("dtype", DTYPES)
def test_quadratic_solver_near_linear_is_accurate_where_the_textbook_formula_cancels(dtype):
    k = np.arange(1, 31)
    q2 = (10.0 ** -k).astype(dtype)  # a -> 0: the naive (-b + sqrt(disc)) / 2a cancels
    q1 = np.full_like(q2, 1.7)
    q0 = np.full_like(q2, -0.9)
    roots, valid = (np.asarray(x) for x in solve_quadratic(*(jnp.asarray(x) for x in (q2, q1, q0))))
    eps = np.finfo(dtype).eps
    for i in range(len(k)):
        small = float(_decimal_roots(q2[i], q1[i], q0[i])[1])  # the root near -q0/q1
        assert valid[i, 0]
        found = roots[i][valid[i]]
        assert np.min(np.abs(found - small)) <= 4 * eps * abs(small)
    naive = (-q1 + np.sqrt(q1 * q1 - 4 * q2 * q0)) / (2 * q2)
    assert np.max(np.abs(naive - 0.9 / 1.7)) > 1e-3  # what the solver avoids
    lin, lin_valid = solve_quadratic(jnp.asarray(0.0, dtype), jnp.asarray(2.0, dtype), jnp.asarray(-1.0, dtype))
    assert bool(lin_valid[0]) and not bool(lin_valid[1]) and float(lin[0]) == 0.5


@pytest.mark.parametrize("dtype", DTYPES)
def test_quadratic_solver_near_tangent_counts_and_places_roots(dtype):
    r = dtype(0.37)
    eps = np.finfo(dtype).eps
    deltas = np.concatenate([-(10.0 ** -np.arange(1, 16)), 10.0 ** -np.arange(1, 16), [0.0]])
    for delta in deltas.astype(dtype):
        # (t - r)^2 + delta = t^2 - 2 r t + (r^2 + delta)
        q = [dtype(1), dtype(-2 * r), dtype(r * r + delta)]
        roots, valid = (np.asarray(x) for x in solve_quadratic(*(jnp.asarray(x) for x in q)))
        exact = _decimal_roots(*q)
        rounding = 8 * eps * (float(q[1]) ** 2 + 4 * abs(float(q[2])))
        disc = float(q[1]) ** 2 - 4 * float(q[2])
        if abs(disc) > 4 * rounding:  # clearly separated or clearly absent
            assert valid.sum() == len(exact)
            for got, want in zip(roots[valid], exact, strict=True):
                assert abs(got - float(want)) <= 8 * eps / np.sqrt(abs(disc)) + 4 * eps
        elif abs(disc) < rounding / 4:  # tangency within rounding: the double root, once
            assert valid.sum() >= 1
        if abs(disc) <= 4 * rounding:  # either count is right; any root is at the double root
            assert np.all(np.abs(roots[valid] - r) < 8 * np.sqrt(eps))


@pytest.mark.parametrize("dtype", DTYPES)
def test_quadratic_solver_never_returns_nan_or_inf(dtype):
    vals = np.array([0.0, 1e-38, -1e-30, 1.0, -2.5, 1e30, -1e38], dtype)
    g = np.stack(np.meshgrid(vals, vals, vals, indexing="ij"), -1).reshape(-1, 3)
    roots, valid = solve_quadratic(*(jnp.asarray(g[:, i]) for i in range(3)))
    assert np.all(np.isfinite(np.asarray(roots)))
    assert not np.any(np.asarray(valid)[np.all(g == 0, -1)])  # 0 = 0 has no isolated root


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_root_at_a_vertex_belongs_to_both_edges_and_the_window_is_64_eps(dtype):
    """math.md §3 tolerance policy: roots within `64 eps` outside [0, 1] are kept and clamped
    (so a curve through a vertex is reported on both edges that meet there); roots further
    out are dropped."""
    rng = np.random.default_rng(5)
    n = 512
    eps = float(np.finfo(dtype).eps)
    coef = rng.normal(size=(n, 6))
    A, B, C, D, E = coef[:, :5].T
    # F so that the conic passes exactly through vertex V1 = (a, b) = (1, 0) (float64 exact
    # enough: A + D + F = 0). V1 is edge 0 at t = 1 and edge 1 at t = 0.
    coef[:, 5] = -(A + D)
    # keep well-conditioned crossings: |dQ/dt| along both edges at V1 not small
    slope0, slope1 = np.abs(2 * A + D), np.abs(-2 * A - D + C + E)
    keep = (slope0 > 0.3) & (slope1 > 0.3)
    t, valid = (np.asarray(x) for x in edges_j(jnp.asarray(coef[keep], dtype)))
    near = lambda k, target: np.any(valid[:, k] & (np.abs(t[:, k] - target) <= 100 * eps), -1)  # noqa: E731
    assert keep.sum() > 100
    assert np.all(near(0, 1.0)), "root at V1 missing on edge 0 (t = 1)"
    assert np.all(near(1, 0.0)), "root at V1 missing on edge 1 (t = 0)"
    # Edge 0 (b = 0): A a^2 + D a + F with roots 1 + delta and -3, other coefficients random.
    for delta, kept in ((8 * eps, True), (-8 * eps, True), (1e3 * eps, False), (1e-2, False)):
        r1, r2 = 1.0 + delta, -3.0
        c = rng.normal(size=(64, 6))
        c[:, 0], c[:, 3], c[:, 5] = 1.0, -(r1 + r2), r1 * r2
        t, valid = (np.asarray(x) for x in edges_j(jnp.asarray(c, dtype)))
        hit = np.any(valid[:, 0] & (np.abs(t[:, 0] - 1.0) <= 16 * eps), -1)
        assert np.all(hit == kept), (delta, hit.mean())
        assert np.all((t >= 0) & (t <= 1))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_power_of_two_floor_is_exact_over_the_whole_normal_range(dtype):
    """solve_quadratic's exact scale (bit mask, not frexp/ldexp): `p <= x < 2 p` with `p` a
    power of two, for x from the smallest normal number to the largest; 0 below."""
    from caustics_jax.math.conic import power_of_two_floor

    info = np.finfo(dtype)
    rng = np.random.default_rng(3)
    x = np.exp(rng.uniform(np.log(info.tiny), np.log(info.max), 10_000)).astype(dtype)
    x = np.concatenate([x, [info.tiny, info.max, 1, 2, np.nextafter(dtype(2), dtype(0))]]).astype(dtype)
    p = np.asarray(power_of_two_floor(jnp.asarray(x)))
    assert p.dtype == dtype
    assert np.all(p <= x) and np.all(x / p < 2)  # (x / p is exact: p a power of two)
    mantissa, _ = np.frexp(p)
    assert np.all(mantissa == 0.5)  # a power of two
    assert np.asarray(power_of_two_floor(jnp.asarray(info.smallest_subnormal, dtype))) == 0


def test_a_quadratic_with_a_coefficient_not_finite_has_no_root():
    """An infinite coefficient had given a NaN root marked valid (the GLSL port: no roots)."""
    import caustics_jax as cj
    for dtype in (jnp.float32, jnp.float64):
        for q in ((1.0, np.inf, 1.0), (0.0, np.inf, 1.0), (np.inf, 1.0, 0.0), (1.0, -np.inf, 2.0),
                  (np.nan, 1.0, 1.0), (1.0, 1.0, np.nan)):
            for fn in (cj.solve_quadratic, jax.jit(cj.solve_quadratic)):
                roots, valid = fn(*(jnp.asarray(x, dtype) for x in q))
                assert not np.asarray(valid).any(), (q, roots, valid)
                assert np.all(np.asarray(roots) == 0)
        roots, valid = cj.solve_quadratic(*(jnp.asarray(x, dtype) for x in (1.0, -3.0, 2.0)))
        np.testing.assert_allclose(np.asarray(roots), [1.0, 2.0])  # finite ones as before
        assert np.asarray(valid).all()
