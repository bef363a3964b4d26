"""Photon differentials (seed 004 eq. 10-11, Alg. 2; seed 003 footprints) against closed forms."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax import scenes
from caustics_jax.transport import (
    ReceiverGrid,
    compression_ratio,
    compression_ratio_exact,
    footprint_ellipse,
    splat_footprints,
    texel_jacobian,
)
from caustics_jax.transport.photon_differentials import light_view_texels

DTYPES = [jnp.float32, jnp.float64]
# Paraxial closed forms hold to O(delta^2 / h^2) = 2.5e-7 (float64; measured 4.8e-8). float32
# measured max 2.2e-7 in these closed-form tests (the caustic triangles are formed from
# differences, so nearby hits lose no digits; before, from absolute hits, eps t' / delta was
# feared and 2e-3 allowed).
TOL = {jnp.float32: 2e-6, jnp.float64: 1e-6}
UP = np.array([0.0, 0.0, 1.0])


def _point_light_patch(dtype, h, delta=1e-3, eta=1.333):
    """Flat surface z = 0, light at height h straight above x00; neighbours delta away."""
    x = np.array([[0, 0, 0], [delta, 0, 0], [0, delta, 0]], np.float64)
    L = np.array([0.0, 0.0, h])
    l_dir = (x - L) / np.linalg.norm(x - L, axis=-1, keepdims=True)
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    n = c(UP)
    return [c(x[0]), c(x[1]), c(x[2]), n, n, n], [c(l_dir[0]), c(l_dir[1]), c(l_dir[2])]


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("mode, virtual", [("reflect", lambda h, eta: h), ("refract", lambda h, eta: eta * h)])
def test_point_light_spreads_like_its_virtual_source(dtype, mode, virtual):
    """A point light at height h over a flat interface: reflected rays diverge from the mirror image
    at depth h, refracted ones (paraxially) from height eta h, so at distance t' the beam is
    (h_v + t') / h_v times wider: sigma (same t') and sqrt(exact ratio) both equal that."""
    h, t, eta = 2.0, 1.5, 1.333
    geo, (l00, l10, l01) = _point_light_patch(dtype, h, eta=eta)
    sigma, ok = compression_ratio(*geo, l00, jnp.asarray(t, dtype), eta=eta, mode=mode, l_dir10=l10, l_dir01=l01)
    expected = (virtual(h, eta) + t) / virtual(h, eta)
    assert bool(ok) and sigma.dtype == dtype
    np.testing.assert_allclose(float(sigma), expected, rtol=TOL[dtype])
    plane_z = t if mode == "reflect" else -t
    ratio, ok = compression_ratio_exact(*geo, l00, jnp.asarray([0, 0, plane_z], dtype), jnp.asarray(UP, dtype),
                                        eta=eta, mode=mode, l_dir10=l10, l_dir01=l01)
    assert bool(ok)
    np.testing.assert_allclose(float(ratio), expected**2, rtol=TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_directional_light_on_flat_interface_keeps_the_beam_and_scales_by_cascade(dtype):
    """Parallel light through a flat interface stays parallel: sigma = s^c (seed 004 eq. 11)."""
    geo, _ = _point_light_patch(dtype, 2.0, delta=0.1)
    l_dir = jnp.asarray([0.3, 0.0, -1.0], dtype) / np.sqrt(1.09)
    sigma, ok = compression_ratio(*geo, l_dir, jnp.asarray(2.0, dtype), scale=2.0, level=3)
    np.testing.assert_allclose(float(sigma), 8.0, rtol=TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_texel_jacobian_on_axis_is_paraxial(dtype):
    """Straight below the light: J = (h + d / eta) / h_e I (h_e the light's height over the emission
    plane); with eta = 1 the map is a central projection, J = (L_z - z_r) / h_e I everywhere."""
    scene = scenes.flat_pool(512, dtype=dtype)
    mesh = scene.surface
    L = np.array([0.1, 0.2, 2.5])
    tx = light_view_texels(mesh, L, 8)
    z_e = tx.plane.z
    X = jnp.asarray([[0.1, 0.2, z_e], [0.9, -0.7, z_e]], dtype)
    from caustics_jax.transport import surface_hits

    face, ab, found = surface_hits(mesh, jnp.asarray(L, dtype), X)
    V, N = mesh.triangle(face)
    d = 1.0
    for eta in (1.333, 1.0):
        J, Y, T, cos_e, r_e, t, ok = texel_jacobian(V, N, jnp.asarray(L, dtype), X, eta,
                                                    jnp.asarray([0, 0, -d], dtype), jnp.asarray(UP, dtype))
        assert np.all(np.asarray(ok))
        h, h_e = L[2], L[2] - z_e
        expected = (h + d / eta) / h_e
        np.testing.assert_allclose(np.asarray(J[0]), expected * np.eye(2), atol=TOL[dtype] * expected)
        if eta == 1.0:
            np.testing.assert_allclose(np.asarray(J[1]), (h + d) / h_e * np.eye(2), atol=TOL[dtype] * expected)


@pytest.mark.parametrize("dtype", DTYPES)
def test_footprint_ellipse_matches_svd(dtype):
    rng = np.random.default_rng(0)
    J = rng.normal(size=(256, 2, 2))
    axes, dirs, area = footprint_ellipse(jnp.asarray(J[..., 0], dtype), jnp.asarray(J[..., 1], dtype))
    U, S, _ = np.linalg.svd(J)
    tol = 1e-4 if dtype == jnp.float32 else 1e-10
    np.testing.assert_allclose(np.asarray(axes), S, rtol=tol, atol=tol)
    np.testing.assert_allclose(np.asarray(area), np.pi * np.abs(np.linalg.det(J)), rtol=tol, atol=tol)
    align = np.abs(np.einsum("ni,ni->n", np.asarray(dirs[:, 0]), U[:, :, 0]))
    well_separated = S[:, 0] > 1.01 * S[:, 1]
    np.testing.assert_allclose(align[well_separated], 1, atol=10 * tol)


@pytest.mark.parametrize("dtype", DTYPES)
def test_splats_conserve_flux_and_rebuild_a_uniform_field(dtype):
    """A regular lattice of equal photons (J = I) splats to a flat map flux / (du dv) inside the
    grid, to the kernel sum's ripple; every photon deposits exactly its flux."""
    receiver = ReceiverGrid(-1.0, -1.0, 1.0, -1.0, 1.0, 40, 40)
    # A texel of 1.46 cells, incommensurate with them (as in practice): measured ripple 1.2e-4
    # with kappa = 0.7, 0.32 with kappa = 0.3.
    du = 0.0731
    g = np.arange(-1.5, 1.5, du) + du / 2
    X, Y = np.meshgrid(g, g, indexing="xy")
    xy = np.stack([X.ravel(), Y.ravel()], -1)
    flux = np.full(len(xy), 3.0 * du * du)
    J = np.broadcast_to(np.eye(2), (len(xy), 2, 2))
    E = splat_footprints(jnp.asarray(xy, dtype), jnp.asarray(flux, dtype), J, du, du, receiver)
    np.testing.assert_allclose(E, 3.0, rtol=1e-3)
    inner = np.all(np.abs(xy) < 0.5, -1)
    E_in = splat_footprints(jnp.asarray(xy[inner], dtype), jnp.asarray(flux[inner], dtype), J[inner], du, du,
                            receiver)
    np.testing.assert_allclose(E_in.sum() * receiver.cell_area, flux[inner].sum(), rtol=1e-5)


def test_bad_mode_raises():
    geo, (l00, _, _) = _point_light_patch(jnp.float64, 2.0)
    with pytest.raises(ValueError, match="mode"):
        compression_ratio(*geo, l00, 1.0, mode="refrakt")
    with pytest.raises(ValueError, match="res"):
        light_view_texels(scenes.flat_pool(128, dtype=jnp.float64).surface, [0, 0, 3.0], 1)


_SPLAT = dict(xy=np.zeros((2, 2)), flux=np.ones(2), J=np.tile(np.eye(2), (2, 1, 1)), du=0.1, dv=0.1,
              receiver=ReceiverGrid(-1.0, -1.0, 1.0, -1.0, 1.0, 8, 8))


@pytest.mark.parametrize("change, name", [
    (dict(kappa=-0.7), "kappa"), (dict(kappa=0.0), "kappa"), (dict(kappa=float("nan")), "kappa"),
    (dict(window=-1), "window"), (dict(window=2.5), "window"), (dict(window=10**6), "window"),
    (dict(du=0.0), "du"), (dict(dv=-1.0), "dv"), (dict(xy=np.zeros((2, 3))), "shapes"),
    (dict(flux=np.ones(3)), "shapes"), (dict(J=np.ones((2, 2))), "shapes"),
    (dict(xy=np.array([[0.0, np.nan], [0, 0]])), "xy"), (dict(J=np.full((2, 2, 2), np.inf)), "J"),
    (dict(flux=np.array([1.0, -1.0])), "flux"), (dict(xy=np.zeros((2, 2), bool)), "xy"),
    (dict(receiver=(0.0, 1.0, -1.0, -1.0, 1.0, 8, 8)), "receiver"), (dict(receiver=None), "receiver"),
])
def test_splat_footprints_refuses_bad_input_naming_it(change, name):
    """Before: a negative window gave an empty map, a negative kappa the same map as its
    absolute value, NaN photons a NaN map; each is now a ValueError naming the argument."""
    with pytest.raises(ValueError, match=name):
        splat_footprints(**{**_SPLAT, **change})


@pytest.mark.parametrize("L, name", [([0.0, np.nan, 3.0], "L"), ([0.0, 0.0], "L"), ([[0, 0, 3.0]] * 2, "L"),
                                     ("up", "L")])
def test_light_view_texels_refuses_a_bad_light_or_resolution(L, name):
    mesh = scenes.flat_pool(128, dtype=jnp.float64).surface
    with pytest.raises(ValueError, match=name):
        light_view_texels(mesh, L, 8)
    for res in (1, 2.5, True, 1 << 20):
        with pytest.raises(ValueError, match="res"):
            light_view_texels(mesh, [0, 0, 3.0], res)
    with pytest.raises(ValueError, match="SurfaceMesh"):
        light_view_texels(np.zeros((3, 3)), [0, 0, 3.0], 8)


@pytest.mark.parametrize("dtype", DTYPES)
def test_photon_differential_irradiance_matches_flat_interface_formula(dtype):
    """Forward irradiance at each texel's landing point equals the exact flat-interface value
    (measured max relative error 1.1e-15 in float64, 4.9e-7 in float32; bounds 10x)."""
    from caustics_jax.testing import flat_interface_irradiance
    from caustics_jax.transport import photon_differential_irradiance

    mesh = scenes.flat_pool(2048, dtype=dtype).surface
    L = np.array([0.4, -0.3, 3.0])
    tx = light_view_texels(mesh, L, 32)
    V, N = mesh.triangle(tx.face)
    E, Y, ok = photon_differential_irradiance(V, N, jnp.asarray(L, dtype), tx.X, 1.333, 2.0,
                                              jnp.asarray([0, 0, -1.0], dtype), jnp.asarray(UP, dtype), 0.2)
    assert E.dtype == dtype
    ok = np.asarray(ok & tx.found)
    assert ok.mean() > 0.99
    ref = flat_interface_irradiance(np.asarray(Y, np.float64)[ok], L, 0.0, 1.333, 2.0, 0.2)
    np.testing.assert_allclose(np.asarray(E, np.float64)[ok], ref, rtol=5e-6 if dtype == jnp.float32 else 1e-14)


def test_compression_ratios_beyond_the_scale_band_are_invalid_not_nan():
    """float32 positions scaled by 1e10 and more (beyond `arguments.scale_range`): the areas
    overflow and sigma came out NaN with valid True; now valid False and sigma 0. At 1e3
    the ratio is the unit-scale one (it is scale-free)."""
    import caustics_jax as cj
    z, x, y = np.float32([0, 0, 1]), np.float32([1, 0, 0]), np.float32([0, 1, 0])
    rows = []
    for s in (1.0, 1e3, 1e10, 1e19):
        s = np.float32(s)
        sig, ok = cj.compression_ratio(np.zeros(3, np.float32), x * s, y * s, z, z, z, -z, np.float32(2.0) * s)
        ex, ok_ex = cj.compression_ratio_exact(np.zeros(3, np.float32), x * s, y * s, z, z, z, -z,
                                               np.float32([0, 0, -2]) * s, z)
        rows.append((float(sig), bool(ok), float(ex), bool(ok_ex)))
    assert rows[0][1] and rows[0][3] and rows[1][1] and rows[1][3]
    np.testing.assert_allclose([rows[1][0], rows[1][2]], [rows[0][0], rows[0][2]], rtol=1e-5)
    for sig, ok, ex, ok_ex in rows[2:]:
        assert (sig, ok, ex, ok_ex) == (0.0, False, 0.0, False)


# --------------------------------------------------------------------------- float32 and degenerate lanes

EPS32 = float(np.finfo(np.float32).eps)
OFFSETS, TEXELS = (0.0, 10.0, 100.0, 1000.0), (1e-2, 1e-3, 1e-4)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _np_scatter(l, n, eta, mode):
    """GLSL reflect / refract(l, n, 1/eta), normalised, in numpy float64 (the independent reference)."""
    c = np.sum(l * n, -1, keepdims=True)
    if mode == "reflect":
        return _unit(l - 2 * c * n)
    e = 1 / eta
    return _unit(e * l - (e * c + np.sqrt(1 - e**2 * (1 - c**2))) * n)


def _texel_patches(lanes=48):
    """Texel triangles over every (offset, texel size) of the sweep, lit by a point light 3 m up
    (own light direction per neighbour), normals varying by 20 texels per metre; float32-rounded."""
    rng = np.random.default_rng(7)
    rows = []
    for off in OFFSETS:
        for h in TEXELS:
            x00 = np.array([off, off, 0.0]) + rng.uniform(-1, 1, (lanes, 3)) * [1, 1, 0.01]
            n00 = _unit([0, 0, 1] + 0.2 * rng.normal(size=(lanes, 3)))
            n10, n01 = (_unit(n00 + 20 * h * rng.normal(size=(lanes, 3))) for _ in range(2))
            x10, x01 = x00 + [h, 0, 0], x00 + [0, h, 0]
            L = np.array([off + 0.5, off - 0.3, 3.0])
            t = rng.uniform(1, 5, lanes)
            rows.append([x00, x10, x01, n00, n10, n01, _unit(x00 - L), _unit(x10 - L), _unit(x01 - L), t,
                         np.broadcast_to([off, off, -3.0], (lanes, 3))])
    return [np.concatenate(c).astype(np.float32).astype(np.float64) for c in zip(*rows, strict=True)]


def _np_ratios(a, mode, eta=1.333):
    """(same-t' A'/A, its conditioning, receiver A'/A (NaN where a ray meets the horizontal
    receiver behind the surface), its conditioning), float64 from absolute hits. The
    conditioning: the sine of the angle between the caustic triangle's edges, for the
    receiver times the smallest `|w.n|` of the three ray-plane hits (inverse condition numbers)."""
    x00, x10, x01, n00, n10, n01, l00, l10, l01, t, P = a
    xs = (x00, x10, x01)
    w = [_np_scatter(li, ni, eta, mode) for li, ni in ((l00, n00), (l10, n10), (l01, n01))]
    A = np.linalg.norm(np.cross(x10 - x00, x01 - x00), axis=-1)
    t_rec = [(P[:, 2] - x[:, 2]) / wi[:, 2] for x, wi in zip(xs, w, strict=True)]
    out = []
    for ts in ([t] * 3, t_rec):
        pts = [x + ti[:, None] * wi for x, ti, wi in zip(xs, ts, w, strict=True)]
        e1, e2 = pts[1] - pts[0], pts[2] - pts[0]
        c = np.linalg.norm(np.cross(e1, e2), axis=-1)
        out += [np.where(np.all(np.stack(ts) > 0, 0), c / A, np.nan),
                c / (np.linalg.norm(e1, axis=-1) * np.linalg.norm(e2, axis=-1))]
    out[3] = out[3] * np.min(np.abs(np.stack([wi[:, 2] for wi in w])), 0)  # and 1/|w.n| of each ray-plane hit
    return out


@pytest.mark.parametrize("mode", ["refract", "reflect"])
def test_compression_ratios_float32_error_scales_with_the_texel_not_the_offset(mode):
    """float32 against float64 on the same float32-rounded inputs, surfaces 0..1000 m from the
    origin, texels 1 cm..0.1 mm, error times the inverse condition number (`_np_ratios`):
    measured max 1.3e-6 = 10.5 eps over 2000 lanes per cell (both modes, both ratios;
    docs/irradiance.md); bound 32 eps. The absolute hits x + t' w had given up to 4.0 (same
    t') and 2.1 (receiver) at 1000 m, 0.1 mm. float64 against numpy: measured 1.5e-9, the
    reference's own error (it forms the absolute hits: eps64 * 1000 m / 0.1 mm * t'); bound 2e-8."""
    a64 = _texel_patches()
    if mode == "reflect":  # the receiver 3 m above the surface
        a64[10] = a64[10] * [1, 1, -1]
    sig2_ref, sin_s, ratio_ref, sin_r = _np_ratios(a64, mode)
    res = {}
    for dtype in DTYPES:
        a = [jnp.asarray(v, dtype) for v in a64]
        sig, ok = compression_ratio(*a[:7], a[9], mode=mode, l_dir10=a[7], l_dir01=a[8])
        ratio, ok_x = compression_ratio_exact(*a[:7], a[10], jnp.asarray(UP, dtype), mode=mode, l_dir10=a[7],
                                              l_dir01=a[8])
        assert sig.dtype == dtype and bool(jnp.all(ok))
        # reflected rays that leave downward never meet the receiver above: invalid
        np.testing.assert_array_equal(np.asarray(ok_x), ~np.isnan(ratio_ref))
        res[dtype] = np.asarray(sig, np.float64) ** 2, np.asarray(ratio, np.float64), np.asarray(ok_x)
    for k, (ref, sine) in enumerate(((sig2_ref, sin_s), (ratio_ref, sin_r))):
        ok = res[jnp.float64][2] if k else np.ones(len(ref), bool)
        r64, r32, ref, sine = res[jnp.float64][k][ok], res[jnp.float32][k][ok], ref[ok], sine[ok]
        err64, err32 = np.abs(r64 - ref) / ref * sine, np.abs(r32 - r64) / r64 * sine
        assert ok.mean() > 0.9 and err64.max() < 2e-8, (k, err64.max())
        assert err32.max() < 32 * EPS32, (k, err32.max())


@pytest.mark.parametrize("dtype", DTYPES)
def test_compression_ratio_marks_total_internal_reflection_invalid_like_the_exact_ratio(dtype):
    """eta < 1 (a ray leaving the denser medium) past the critical angle, asin(eta): GLSL refract
    returns 0, the "hits" stay on the surface, and the same-t' ratio had read sigma = 1, valid,
    where the exact ratio rejects the lane. One neighbour alone past it counts too. And t' <= 0
    (the receiver behind the surface) is invalid as the exact ratio's rays behind the plane."""
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    theta = np.radians(np.r_[np.arange(0, 85, 5), 47.0, 47.0])  # critical angle 48.6 deg at eta = 0.75
    n = len(theta)
    l_dir = np.stack([np.sin(theta), np.zeros(n), -np.cos(theta)], -1)
    tilt = np.zeros((n, 3))
    tilt[-1] = [0.1, 0, 0]  # the last lane's neighbour x10 sees the light at 53 deg
    x00, x10, x01 = np.zeros((n, 3)), np.tile([0.01, 0, 0], (n, 1)), np.tile([0, 0.01, 0], (n, 1))
    up = np.tile(UP, (n, 1))
    geo = [c(x00), c(x10), c(x01), c(up), c(_unit(up + tilt)), c(up)]
    for eta in (0.75, 1e-3):  # 1e-3: only normal incidence transmits
        valid = np.r_[np.sin(theta[:-1]) < eta, False]
        sigma, ok = compression_ratio(*geo, c(l_dir), c(np.full(n, 2.0)), eta=eta)
        ratio, ok_x = compression_ratio_exact(*geo, c(l_dir), c([0, 0, -2.0]), c(UP), eta=eta)
        np.testing.assert_array_equal(np.asarray(ok), valid)
        np.testing.assert_array_equal(np.asarray(ok_x), valid)
        assert np.all(np.asarray(sigma)[~valid] == 0) and np.all(np.asarray(ratio)[~valid] == 0)
    sigma, ok = compression_ratio(*geo, c(l_dir), c(np.r_[-1.0, 0.0, np.ones(n - 2)]), eta=1.333)
    np.testing.assert_array_equal(np.asarray(ok), np.arange(n) >= 2)


def _curved_triangles(lanes=24):
    """Triangles (10 cm and 1 cm, random smooth normals) 0..1000 m from the origin under a light
    3 m up, emission points 0.3 m up on the ray to a point near the centre; float32-rounded."""
    rng = np.random.default_rng(8)
    rows = []
    for off in OFFSETS:
        for size in (0.1, 0.01):
            c = np.array([off, off, 0.0]) + rng.uniform(-1, 1, (lanes, 3)) * [1, 1, 0.02]
            V = c[:, None] + size * np.array([[-0.5, -0.4, 0], [0.5, -0.4, 0.05], [0, 0.6, -0.03]])
            N = _unit(UP + 0.3 * rng.normal(size=(lanes, 3, 3)) * [1, 1, 0])
            L = np.broadcast_to([off + 0.3, off - 0.2, 3.0], (lanes, 3))
            M = c + size * 0.1 * rng.uniform(-1, 1, (lanes, 3)) * [1, 1, 0]
            X = L + (M - L) * ((0.3 - L[:, 2]) / (M[:, 2] - L[:, 2]))[:, None]
            rows.append([V, N, L, X, np.broadcast_to([off, off, -1.0], (lanes, 3))])
    return [np.concatenate(c).astype(np.float32).astype(np.float64) for c in zip(*rows, strict=True)]


def test_texel_jacobian_float32_error_does_not_grow_with_the_offset():
    """float32 against float64 on the same float32 inputs, triangles 0..1000 m from the origin:
    relative error of J measured max 2.2e-6 = 19 eps (1000 lanes per cell), bound 48 eps; of E
    times |det J| / |J|^2 (its inverse condition number) 1.2e-6 = 10 eps, bound 32 eps, where
    both are valid (float32 rejects |det J| below sqrt(eps32) |J|^2 by design). Barycentrics
    and landing points formed from absolute points had given 2.3e-3 (J) and 1.5e-3 (E) at
    1000 m (docs/irradiance.md)."""
    from caustics_jax.transport import photon_differential_irradiance

    a64 = _curved_triangles()
    out = {}
    for dtype in DTYPES:
        V, N, L, X, P = (jnp.asarray(v, dtype) for v in a64)
        J, *_, ok = texel_jacobian(V, N, L, X, 1.333, P, jnp.asarray(UP, dtype))
        E, _, ok_e = photon_differential_irradiance(V, N, L, X, 1.333, 1.0, P, jnp.asarray(UP, dtype))
        assert J.dtype == dtype and bool(jnp.all(ok))
        out[dtype] = np.asarray(J, np.float64), np.asarray(E, np.float64), np.asarray(ok_e)
    (J64, E64, ok64), (J32, E32, ok32) = out[jnp.float64], out[jnp.float32]
    err_J = np.linalg.norm(J32 - J64, axis=(-2, -1)) / np.linalg.norm(J64, axis=(-2, -1))
    kappa = np.abs(np.linalg.det(J64)) / np.sum(J64**2, axis=(-2, -1))
    assert np.all(ok64) and np.all(ok32 | (kappa < 2 * np.sqrt(EPS32)))
    err_E = (np.abs(E32 - E64) / E64 * kappa)[ok32]
    assert err_J.max() < 48 * EPS32 and err_E.max() < 32 * EPS32, (err_J.max(), err_E.max())


@pytest.mark.parametrize("dtype", DTYPES)
def test_texel_jacobian_at_the_light_is_invalid_with_finite_values_and_gradients(dtype):
    """X = L (finite input, no photon direction) had given NaN J, Y, cos_e and gradients; now
    the lane is invalid, every output and the gradient of E finite, other lanes unchanged."""
    from caustics_jax.transport import photon_differential_irradiance

    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    V = c([[-1, -1, 0], [1, -1, 0], [0, 1, 0]])
    N = c(_unit(np.array([[0.1, 0, 1], [0, 0.1, 1], [0, 0, 1]])))
    L, P = c([0, 0, 2]), c([0, 0, -1])
    X = c([[0, 0, 2], [0.1, -0.05, 1], [0, 0, 2], [-0.2, 0.1, 1]])

    def total(X):
        E, _, ok = photon_differential_irradiance(V, N, L, X, 1.333, 1.0, P, c(UP))
        return jnp.sum(E), (E, ok)

    @jax.jit  # one compile for both
    def run(X):
        return texel_jacobian(V, N, L, X, 1.333, P, c(UP)), jax.grad(total, has_aux=True)(X)

    outs, (g, (E, ok)) = run(X)
    np.testing.assert_array_equal(np.asarray(outs[-1]), [False, True, False, True])
    assert all(np.all(np.isfinite(np.asarray(o))) for o in outs[:-1])
    np.testing.assert_array_equal(np.asarray(ok), [False, True, False, True])
    assert np.all(np.isfinite(np.asarray(g))) and np.all(np.asarray(g)[[0, 2]] == 0)
    assert np.all(np.asarray(E)[[0, 2]] == 0) and np.all(np.asarray(E)[[1, 3]] > 0)


@pytest.mark.parametrize("dtype", DTYPES)
def test_photon_crossing_the_emission_plane_upward_carries_positive_flux(dtype):
    """The scene mirrored in z (light below the surface, photons crossing the emission plane
    upward, cos_e < 0) has the same irradiance; it had come out negative, valid."""
    from caustics_jax.transport import photon_differential_irradiance

    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    V = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0.0]])
    N = _unit(np.array([[0.1, 0, 1], [0, 0.1, 1], [0, 0, 1]]))
    L, X, P = np.array([0.1, 0, 2]), np.array([[0.2, -0.1, 1], [-0.3, 0.2, 1]]), np.array([0, 0, -1.0])
    flip = np.array([1, 1, -1])
    E, _, ok = photon_differential_irradiance(c(V), c(N), c(L), c(X), 1.333, 1.0, c(P), c(UP))
    E_up, _, ok_up = photon_differential_irradiance(c(V * flip), c(N * flip), c(L * flip), c(X * flip), 1.333,
                                                    1.0, c(P * flip), c(UP))
    assert bool(jnp.all(ok)) and bool(jnp.all(ok_up))
    np.testing.assert_allclose(np.asarray(E_up), np.asarray(E), rtol=TOL[dtype] if dtype == jnp.float32 else 1e-12)


def test_footprint_minor_axis_is_accurate_in_float32_at_any_aspect():
    """Rotated ellipses of aspect 1e1..1e6: float32 semi-axes against the float64 SVD of the same
    float32 J. A singular value moves by up to eps |J| under rounding, so the bound is on
    `|ds| / s1`: measured max 1.9e-7 = 1.6 eps (s1) and 4.5e-8 (s2) over 2000 lanes per
    aspect, bound 4 eps. `sqrt(half_trace - root)` had lost s2 (2.9e-4 s1; s2 = 0 from 1e4);
    the area stays pi s1 s2."""
    rng = np.random.default_rng(9)
    aspect = np.repeat([1e1, 1e2, 1e3, 1e4, 1e6], 64)
    a, b = rng.uniform(0, np.pi, (2, len(aspect)))
    rot = lambda t: np.stack([np.stack([np.cos(t), -np.sin(t)], -1), np.stack([np.sin(t), np.cos(t)], -1)], -2)  # noqa: E731
    S = np.zeros((len(aspect), 2, 2))
    S[:, 0, 0], S[:, 1, 1] = 1, 1 / aspect
    J = (rot(a) @ S @ rot(b) * rng.uniform(0.1, 10, (len(aspect), 1, 1))).astype(np.float32)
    axes, _, area = footprint_ellipse(jnp.asarray(J[..., 0]), jnp.asarray(J[..., 1]))
    s = np.linalg.svd(J.astype(np.float64), compute_uv=False)
    err = np.abs(np.asarray(axes, np.float64) - s) / s[:, :1]
    assert err.max() < 4 * EPS32, err.max(axis=0)
    np.testing.assert_allclose(np.asarray(area), np.pi * np.prod(np.asarray(axes), -1), rtol=4 * EPS32)


@pytest.mark.parametrize("dtype", DTYPES)
def test_footprint_gradients_are_finite_at_a_circle_and_a_singular_J(dtype):
    """At a circle (J = I) the semi-axes are not differentiable: each gets the mean of its
    one-sided derivatives, d sqrt((s1^2 + s2^2)/2) = J/2, and the directions zero (they had
    been NaN); at a singular J and at J = 0 every gradient is finite. Away from them the
    gradient is the SVD's, u_i v_i^T (checked at J = diag(2, 1))."""
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731

    def parts(J):
        axes, dirs, area = footprint_ellipse(J[..., 0], J[..., 1])
        return axes[..., 0], axes[..., 1], jnp.sum(dirs), area

    grads = jax.jit(jax.vmap(jax.jacrev(parts)))
    Js = c([np.eye(2), [[1.0, 2.0], [0.5, 1.0]], np.zeros((2, 2)), np.diag([2.0, 1.0])])
    g1, g2, gd, ga = (np.asarray(g) for g in grads(Js))
    assert all(np.all(np.isfinite(g)) for g in (g1, g2, gd, ga))
    np.testing.assert_allclose(g1[0], np.eye(2) / 2, atol=1e-6)
    np.testing.assert_allclose(g2[0], np.eye(2) / 2, atol=1e-6)
    np.testing.assert_allclose(gd[0], 0, atol=1e-6)
    np.testing.assert_allclose(g1[3], np.diag([1.0, 0.0]), atol=1e-6)
    np.testing.assert_allclose(g2[3], np.diag([0.0, 1.0]), atol=1e-6)


def test_surface_hits_and_surface_starts_refuse_bad_input_naming_it():
    """Exported helpers that validated nothing: a NaN light gave garbage hits, an X above the
    light a ray going up (never a hit, no error), a negative count numpy's own message."""
    from caustics_jax.transport import surface_hits, surface_starts

    mesh = scenes.flat_pool(128, dtype=jnp.float64).surface
    X = np.array([[0.1, 0.2, 1.0], [0.3, 0.1, 1.0]])
    for L, X_, match in (([0.0, np.nan, 3.0], X, "L has NaN"), ([0.0, 0.0, 3.0], X[:, :2], "shape"),
                         ([0.0, 0.0, 0.5], X, "below L"), ([0.0, 0.0, 3.0], X * np.inf, "X has NaN")):
        with pytest.raises(ValueError, match=match):
            surface_hits(mesh, L, X_)
    with pytest.raises(ValueError, match="SurfaceMesh"):
        surface_hits("mesh", [0.0, 0.0, 3.0], X)
    face, ab, found = surface_hits(mesh, [0.0, 0.0, 3.0], np.array([[0.1, 0.2, 1.0]]))  # lists are fine
    assert bool(found[0])
    for n, rng, match in ((-1, np.random.default_rng(0), "n must"), (2.5, np.random.default_rng(0), "n must"),
                          (4, 0, "numpy.random.Generator")):
        with pytest.raises(ValueError, match=match):
            surface_starts(mesh, n, rng)
    with pytest.raises(ValueError, match="SurfaceMesh"):
        surface_starts(None, 4, np.random.default_rng(0))
    # (traced input is left to the caller: inside jit the rays are traced unchecked)
    hits = jax.jit(lambda L, X: surface_hits(mesh, L, X))(jnp.asarray([0.0, 0.0, 3.0]), jnp.asarray(X))
    assert np.asarray(hits[2]).all()
