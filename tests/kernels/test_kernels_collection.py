"""Collection points (seed 000 eq. 1-4, §3): radius, cylinder AABB, reuse, resolve, EMA."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax.kernels import (
    RADIUS_CAP,
    cylinder_aabb,
    gather_previous,
    in_cylinder,
    pixel_footprint_radius,
    pixel_spread_angle,
    ray_cone_propagate,
    ray_cone_radius,
    resolve,
    reuse_accepted,
    reuse_weight,
    temporal_ema,
)

DTYPES = [jnp.float32, jnp.float64]
EPS = {jnp.float32: np.finfo(np.float32).eps, jnp.float64: np.finfo(np.float64).eps}
aabb_j = jax.jit(cylinder_aabb)
gather_j = jax.jit(gather_previous)
seeds = st.integers(0, 2**32 - 1)


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _frame(n):
    """Two unit vectors orthogonal to each unit `n` and to each other."""
    a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    u = np.cross(n, a)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    return u, np.cross(n, u)


def _cylinder(seed, n_cyl):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-10, 10, (n_cyl, 3))
    n = _unit(rng, n_cyl)
    # a few exactly axis-aligned normals, where sqrt(1 - n_i^2) hits zero
    n[: n_cyl // 8] = np.eye(3)[rng.integers(0, 3, n_cyl // 8)] * rng.choice(
        [-1, 1], (n_cyl // 8, 1)
    )
    r = np.exp(rng.uniform(np.log(1e-4), np.log(1.0), n_cyl))
    return rng, c, n, r


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_cylinder_aabb_contains_every_point_of_the_cylinder(dtype, seed):
    rng, c, n, r = _cylinder(seed, 256)
    lo, hi = (
        np.asarray(a)
        for a in aabb_j(jnp.asarray(c, dtype), jnp.asarray(n, dtype), jnp.asarray(r, dtype))
    )
    assert lo.dtype == dtype
    u, v = _frame(n)
    k = 64  # points per cylinder, half of them on the rim of the top or bottom disk
    phi = rng.uniform(0, 2 * np.pi, (256, k, 1))
    rho = np.sqrt(rng.uniform(0, 1, (256, k, 1)))
    rho[:, ::2] = 1
    z = rng.uniform(-0.5, 0.5, (256, k, 1))
    z[:, ::2] = rng.choice([-0.5, 0.5], (256, k // 2, 1))
    pts = c[:, None] + r[:, None, None] * (
        rho * (np.cos(phi) * u[:, None] + np.sin(phi) * v[:, None]) + z * 0.1 * n[:, None]
    )
    # float32: rounding of c (|c| <= 10) and of the half-extent, a few ulps of 10
    tol = 8 * EPS[dtype] * (np.abs(c).max(-1) + r)[:, None, None]
    assert np.all(pts >= lo[:, None] - tol) and np.all(pts <= hi[:, None] + tol)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_cylinder_aabb_is_tight_each_face_touches_the_cylinder(dtype, seed):
    _, c, n, r = _cylinder(seed, 256)
    lo, hi = (
        np.asarray(a, np.float64)
        for a in aabb_j(jnp.asarray(c, dtype), jnp.asarray(n, dtype), jnp.asarray(r, dtype))
    )
    for i in range(3):
        e = np.eye(3)[i]
        tangential = e - n[:, i : i + 1] * n
        length = np.linalg.norm(tangential, axis=-1, keepdims=True)
        u = np.where(length > 0, tangential / np.where(length > 0, length, 1), 0)
        # The support point of the cylinder in direction e: rim of the disk on the far end.
        support = c + r[:, None] * u + 0.05 * r[:, None] * np.sign(n[:, i : i + 1]) * n
        tol = 8 * EPS[dtype] * (np.abs(c).max(-1) + r)
        np.testing.assert_array_less(np.abs(support[:, i] - hi[:, i]), tol)
        np.testing.assert_array_less(np.abs((2 * c - support)[:, i] - lo[:, i]), tol)
        inside = np.asarray(in_cylinder(c + (1 - 1e-3) * (support - c), c, n, r))
        assert inside.all()


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_in_cylinder_accepts_inside_and_rejects_outside_by_a_margin(dtype, seed):
    rng, c, n, r = _cylinder(seed, 256)
    u, _ = _frame(n)
    radial = rng.uniform(0, 2, (256, 1))
    axial = rng.uniform(-0.1, 0.1, (256, 1))
    p = c + r[:, None] * (radial * u + axial * n)
    got = np.asarray(
        in_cylinder(
            jnp.asarray(p, dtype),
            jnp.asarray(c, dtype),
            jnp.asarray(n, dtype),
            jnp.asarray(r, dtype),
        )
    )
    want = (radial[:, 0] <= 1) & (np.abs(axial[:, 0]) <= 0.05)
    # p - c carries the rounding of |c| <= 10: only lanes clear of the boundary by more
    # than a few ulps of |c| (absolute) have a defined answer in float32
    slack = 16 * EPS[dtype] * (np.abs(c).max(-1) + r) / r
    clear = (np.abs(radial[:, 0] - 1) > slack) & (np.abs(np.abs(axial[:, 0]) - 0.05) > slack)
    assert clear.mean() > 0.5
    np.testing.assert_array_equal(got[clear], want[clear])


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_reuse_weight_is_a_normalised_symmetric_decreasing_gaussian(dtype, seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, (256, 3))
    d = _unit(rng, 256)
    r = rng.uniform(1e-3, 1, 256)
    s = np.sort(rng.uniform(0, 2, (256, 2)), axis=1)  # two distances along the same line
    near, far = p + s[:, :1] * r[:, None] * d, p + s[:, 1:] * r[:, None] * d
    args = lambda a, b: (jnp.asarray(a, dtype), jnp.asarray(b, dtype), jnp.asarray(r, dtype))  # noqa: E731
    w_near, w_far = (
        np.asarray(reuse_weight(*args(near, p))),
        np.asarray(reuse_weight(*args(far, p))),
    )
    assert w_near.dtype == dtype
    assert np.all((w_far > 0) & (w_far <= w_near) & (w_near <= 1))
    np.testing.assert_array_equal(np.asarray(reuse_weight(*args(p, near))), w_near)
    np.testing.assert_array_equal(np.asarray(reuse_weight(*args(p, p))), 1)
    # sigma = 0.75 r: at distance exactly r the weight is exp(-1 / (2 * 0.75^2)) = exp(-8/9)
    edge = p + r[:, None] * d
    # The error comes from rounding edge - p: measured max 0.91 eps (|p| + r) / r over 200
    # float32 batches; bound 2x that.
    tol = 2 * EPS[dtype] * (np.abs(p).max(-1) + r) / r
    err = np.abs(np.asarray(reuse_weight(*args(edge, p))) - np.exp(-8 / 9))
    assert np.all(err <= tol)
    # degenerate radius: a delta kernel, no NaN
    z = np.asarray(
        reuse_weight(jnp.asarray(near, dtype), jnp.asarray(p, dtype), jnp.zeros(256, dtype))
    )
    assert np.all(np.isfinite(z)) and set(np.unique(z)) <= {0, 1}


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_reuse_acceptance_is_eq4_distance_normal_and_material(dtype, seed):
    rng = np.random.default_rng(seed)
    p, n = rng.uniform(-1, 1, (512, 3)), _unit(rng, 512)
    r = rng.uniform(1e-3, 1e-2, 512)
    dist = rng.uniform(0, 2, 512)
    p_prev = p + dist[:, None] * r[:, None] * _unit(rng, 512)
    u, _ = _frame(n)
    cos = rng.uniform(0.6, 1, 512)
    n_prev = cos[:, None] * n + np.sqrt(1 - cos**2)[:, None] * u
    m, m_prev = rng.integers(0, 3, 512), rng.integers(0, 3, 512)
    got = np.asarray(
        reuse_accepted(
            *(jnp.asarray(a, dtype) for a in (p_prev, n_prev)),
            m_prev,
            jnp.asarray(p, dtype),
            jnp.asarray(n, dtype),
            m,
            jnp.asarray(r, dtype),
        )
    )
    want = (dist <= 1) & (cos >= 0.9) & (m == m_prev)
    clear = (np.abs(dist - 1) > 1e-3) & (np.abs(cos - 0.9) > 1e-4)
    np.testing.assert_array_equal(got[clear], want[clear])


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_resolved_radiance_over_the_disk_returns_the_intensity(dtype, seed):
    rng = np.random.default_rng(seed)
    tau, I = rng.uniform(0, 1, (256, 3)), rng.uniform(0, 10, (256, 3))
    r = rng.uniform(1e-4, 5e-3, 256)
    r[:8] = 0
    L = np.asarray(
        resolve(jnp.asarray(tau, dtype), jnp.asarray(I, dtype), jnp.asarray(r, dtype)[:, None])
    )
    assert L.dtype == dtype and np.all(np.isfinite(L))
    assert np.all(L[:8] == 0)
    rtol = 4 * EPS[dtype]  # three roundings in the kernel and one here
    np.testing.assert_allclose(L[8:] * np.pi * r[8:, None] ** 2, tau[8:] * I[8:], rtol=rtol)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds, alpha=st.floats(0, 1))
def test_temporal_ema_is_a_convex_blend_that_converges_to_a_steady_input(dtype, seed, alpha):
    rng = np.random.default_rng(seed)
    a, b = rng.uniform(0, 10, (2, 256)).astype(dtype)
    out = np.asarray(temporal_ema(jnp.asarray(a), jnp.asarray(b), alpha))
    assert out.dtype == dtype
    slack = 4 * EPS[dtype] * 10
    assert np.all(out >= np.minimum(a, b) - slack) and np.all(out <= np.maximum(a, b) + slack)
    np.testing.assert_allclose(
        np.asarray(temporal_ema(jnp.asarray(b), jnp.asarray(b), alpha)), b, rtol=4 * EPS[dtype]
    )
    # history fed back each frame: distance to a steady input shrinks by alpha per frame
    hist = jnp.asarray(a)
    for _ in range(5):
        hist = temporal_ema(hist, jnp.asarray(b))
    np.testing.assert_allclose(
        np.asarray(hist) - b, 0.8**5 * (a - b), atol=1e-5 if dtype == jnp.float32 else 1e-12
    )


def _gather_numpy(p, n, m, r, pp, npv, mp, rp, Lp):
    """Independent double loop over eq. 3-4 and the cylinder containment."""
    out, wsum = np.zeros((len(p),) + Lp.shape[1:]), np.zeros(len(p))
    for i in range(len(p)):
        for j in range(len(pp)):
            d = p[i] - pp[j]
            axial = d @ npv[j]
            contained = abs(axial) <= rp[j] / 20 and d @ d - axial**2 <= rp[j] ** 2
            if contained and d @ d <= r[i] ** 2 and npv[j] @ n[i] >= 0.9 and mp[j] == m[i]:
                w = np.exp(-(d @ d) / (2 * (0.75 * r[i]) ** 2))
                out[i] += w * Lp[j]
                wsum[i] += w
    return np.where(wsum[:, None] > 0, out / np.where(wsum > 0, wsum, 1)[:, None], 0), wsum


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_gather_matches_a_brute_force_loop_and_keeps_a_constant_field(dtype, seed):
    rng = np.random.default_rng(seed)
    k, n_cur = 48, 32
    # points on a plane z = 0 with jittered normals, so containment and eq. 4 both vary
    pp = np.c_[rng.uniform(0, 1, (k, 2)), np.zeros(k)]
    npv = np.c_[rng.normal(0, 0.3, (k, 2)), np.ones(k)]
    npv /= np.linalg.norm(npv, axis=-1, keepdims=True)
    p = np.c_[rng.uniform(0, 1, (n_cur, 2)), rng.normal(0, 1e-3, n_cur)]
    n = np.tile([0.0, 0, 1], (n_cur, 1))
    r, rp = rng.uniform(0.1, 0.4, n_cur), rng.uniform(0.1, 0.4, k)
    m, mp = rng.integers(0, 2, n_cur), rng.integers(0, 2, k)
    Lp = rng.uniform(0, 1, (k, 3))
    cast = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    L_hat, wsum = gather_j(
        cast(p), cast(n), m, cast(r), cast(pp), cast(npv), mp, cast(rp), cast(Lp)
    )
    assert L_hat.dtype == dtype
    want, want_w = _gather_numpy(p, n, m, r, pp, npv, mp, rp, Lp)
    tol = 1e-5 if dtype == jnp.float32 else 1e-12
    # lanes whose acceptance flips under float32 rounding would differ: compare the rest
    np.testing.assert_allclose(np.asarray(wsum), want_w, atol=tol)
    np.testing.assert_allclose(np.asarray(L_hat), want, atol=tol)
    const, _ = gather_j(
        cast(p), cast(n), m, cast(r), cast(pp), cast(npv), mp, cast(rp), cast(np.full((k, 3), 0.25))
    )
    np.testing.assert_allclose(np.asarray(const)[want_w > 0], 0.25, rtol=8 * EPS[dtype])
    assert np.all(np.asarray(const)[want_w == 0] == 0)


@pytest.mark.parametrize("dtype", DTYPES)
@given(fov=st.floats(0.1, 2.5), height=st.integers(100, 4000))
def test_pixel_spread_angle_tiles_the_image_plane(dtype, fov, height):
    alpha = pixel_spread_angle(jnp.asarray(fov, dtype), height)
    assert alpha.dtype == dtype
    # H pixels of angular size alpha at the centre: tan(alpha) H = 2 tan(fov/2)
    np.testing.assert_allclose(
        np.tan(float(alpha)) * height, 2 * np.tan(fov / 2), rtol=8 * EPS[dtype]
    )


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_ray_cone_width_grows_linearly_and_the_radius_is_capped_at_5mm(dtype, seed):
    rng = np.random.default_rng(seed)
    w0, gamma = rng.uniform(0, 1e-2, 256), rng.uniform(1e-4, 1e-2, 256)
    t = rng.uniform(0, 10, 256)
    rough = rng.uniform(0, 0.1, 256)
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    w1, g1 = ray_cone_propagate(c(w0), c(gamma), c(t), 0.0, c(rough))
    w2, _ = ray_cone_propagate(c(w0), c(gamma), c(2 * t))
    assert w1.dtype == dtype
    np.testing.assert_allclose(np.asarray(w2) - w0, 2 * (np.asarray(w1) - w0), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(np.asarray(g1), gamma + rough, rtol=4 * EPS[dtype])
    # small-angle form of the ray-cones papers: w0 + gamma t, to O(gamma^3)
    np.testing.assert_allclose(np.asarray(w1), w0 + gamma * t, rtol=1e-4 + 4 * EPS[dtype])
    rad = np.asarray(ray_cone_radius(w1))
    assert np.all(rad <= RADIUS_CAP) and np.all(
        rad == np.minimum(np.asarray(w1) / 2, np.asarray(RADIUS_CAP, dtype))
    )


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_pixel_footprint_disk_encloses_the_traced_pixel_corners_tightly(dtype, seed):
    """Trace the 4 corner rays of a pixel onto a tilted plane and compare with the radius."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.1, 10, 256)
    alpha = rng.uniform(1e-4, 1e-3, 256)
    theta = rng.uniform(0, np.radians(75), 256)
    normal = np.stack([np.zeros(256), np.sin(theta), -np.cos(theta)], -1)  # tilted about x
    hit = np.stack([np.zeros(256), np.zeros(256), t], -1)
    h = np.tan(alpha / 2)
    dist = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            d = np.stack([sx * h, sy * h, np.ones(256)], -1)
            s = np.sum(hit * normal, -1) / np.sum(d * normal, -1)
            dist.append(np.linalg.norm(s[:, None] * d - hit, axis=-1))
    far = np.max(dist, axis=0)
    r = np.asarray(
        pixel_footprint_radius(
            jnp.asarray(t, dtype),
            jnp.asarray(alpha, dtype),
            jnp.asarray(np.cos(theta), dtype),
            cap=1e3,
        )
    )
    assert r.dtype == dtype
    # parallel-ray model vs perspective: the traced footprint deviates by O(alpha tan(theta))
    rel = alpha * (1 + np.tan(theta) ** 2) + 16 * EPS[dtype]
    assert np.all(far <= r * (1 + rel)) and np.all(far >= r * (1 - rel))
    capped = np.asarray(
        pixel_footprint_radius(
            jnp.asarray(t, dtype), jnp.asarray(alpha, dtype), jnp.zeros(256, dtype)
        )
    )
    assert np.all(capped == np.asarray(RADIUS_CAP, dtype))


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="radius"):
        cylinder_aabb(jnp.zeros(3), jnp.asarray([0.0, 0, 1]), -1.0)
    with pytest.raises(ValueError, match="center"):
        cylinder_aabb(jnp.zeros(2), jnp.asarray([0.0, 0, 1]), 1.0)
    with pytest.raises(ValueError, match="alpha"):
        temporal_ema(1.0, 2.0, alpha=1.5)
    with pytest.raises(ValueError, match="r"):
        resolve(1.0, 1.0, -1e-3)


# A radius and the distances compared with it, scaled together: the Gaussian of eq. 3, the
# test of eq. 4 and the cylinder depend on their ratios only.
SCALES = {jnp.float32: [1e-30, 1e-19, 1.0, 1e19, 1e30], jnp.float64: [1e-300, 1e-160, 1.0, 1e160, 1e300]}


@pytest.mark.parametrize("dtype", DTYPES)
def test_reuse_weight_acceptance_and_cylinder_depend_on_ratios_at_any_scale(dtype):
    """Before: float32 `reuse_weight` was NaN at r = |d| = 1e20 (inf/inf) and 1 instead of
    exp(-8/9) at r = |d| = 1e-19 (d.d underflows); `reuse_accepted` took |d| = 10 r at
    1e20 (both squares inf); `in_cylinder` failed the same way."""
    scales = np.repeat(SCALES[dtype], 4)
    k = np.tile([0.0, 0.5, 1.0, 2.0], len(SCALES[dtype]))  # |d| / r
    r = 1.0 * scales
    d = np.stack([k * scales * 0.6, k * scales * 0.8, 0 * k], -1)  # in the cylinder's plane
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    z3, up = c(np.zeros(3)), c([0.0, 0, 1])

    def run(d, r):
        return (reuse_weight(d, z3, r), reuse_accepted(d, up, 0, z3, up, 0, r * 0.999),
                in_cylinder(d, z3, up, r * 0.999))

    w, acc, inside = jax.jit(run)(c(d), c(r))
    x = k**2 / (2 * 0.75**2)
    # exp amplifies the exponent's rounding x-fold: measured max relative error
    # 0.79 eps (1 + x) in float32, 0.96 eps (1 + x) in float64 (4.3e-7 and 9.7e-16)
    rel = np.abs(np.asarray(w) - np.exp(-x)) / np.exp(-x)
    assert np.all(rel <= 2 * EPS[dtype] * (1 + x))
    np.testing.assert_array_equal(np.asarray(acc), k <= 0.999)
    np.testing.assert_array_equal(np.asarray(inside), k <= 0.999)
    g = jax.jit(jax.grad(lambda d, r: jnp.sum(reuse_weight(d, z3, r)), argnums=(0, 1)))(c(d), c(r))
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in g)


def test_gather_refuses_arrays_of_mismatched_lengths_naming_them():
    z, up = np.zeros((2, 3)), np.tile([0.0, 0, 1], (2, 1))
    ok = dict(p=z, n=up, m=np.zeros(2, int), r=np.ones(2), p_prev=z, n_prev=up, m_prev=np.zeros(2, int),
              r_prev=np.ones(2), L_prev=np.ones((2, 3)))
    for name, bad in (("r_prev", np.ones(3)), ("m_prev", np.zeros(1, int)), ("n_prev", up[:1]),
                      ("r", np.ones(3)), ("m", np.zeros(1, int)), ("n", up[:1])):
        with pytest.raises(ValueError, match=f"gather_previous: {name} "):
            gather_previous(**{**ok, name: bad})


@pytest.mark.parametrize("dtype", DTYPES)
def test_angles_of_pi_or_more_are_refused_and_inside_jit_give_no_negative_width(dtype):
    """A cone of full angle >= pi has no width: tan(angle / 2) had turned negative
    (float32 fov = pi gave alpha = -1.57, spread = 4 a width of -3.4)."""
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    for angle in (np.pi, 4.0):
        with pytest.raises(ValueError, match="fov_y"):
            pixel_spread_angle(c(angle), 100)
        with pytest.raises(ValueError, match="spread"):
            ray_cone_propagate(c(1.0), c(angle), c(1.0))
        with pytest.raises(ValueError, match="spread"):
            pixel_footprint_radius(c(1.0), c(angle), c(1.0))
    angles = c([np.pi, 4.0, 2 * np.pi, 7.0])

    def run(a):
        return (pixel_spread_angle(a, 100), ray_cone_propagate(c(1.0), a, c(1.0))[0],
                pixel_footprint_radius(c(1.0), a, c(1.0), cap=1e30))

    alpha, width, radius = (np.asarray(x) for x in jax.jit(run)(angles))
    assert np.all((alpha >= 1.5) & (alpha <= np.pi / 2))  # the limit of a widening fov
    assert np.all(np.isfinite(width) & (width > 1e6)) and np.all(np.isfinite(radius) & (radius > 1e6))
