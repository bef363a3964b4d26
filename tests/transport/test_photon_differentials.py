"""Photon differentials (seed 004 eq. 10-11, Alg. 2; seed 003 footprints) against closed forms."""

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
# Paraxial closed forms hold to O(delta^2 / h^2) = 2.5e-7 (float64); float32 loses
# eps * t' / delta ~ 1e-4 in the differences of nearby hits.
TOL = {jnp.float32: 2e-3, jnp.float64: 1e-6}
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
