"""Brute-force photon tracing: inverse-square law, Monte-Carlo error that falls as 1/sqrt(N), input checks."""

import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax import scenes
from caustics_jax.testing import flat_interface_irradiance
from caustics_jax.transport import ReceiverGrid, photon_irradiance

DTYPES = [jnp.float32, jnp.float64]
LIGHT = np.array([0.4, -0.3, 3.0])
RECEIVER = ReceiverGrid(-1.0, -1.0, 1.0, -1.0, 1.0, 8, 8)


def _cell_average(fn, receiver, k=4):
    pts = receiver.subsamples(k)
    return fn(pts.reshape(-1, 3)).reshape(receiver.ny, receiver.nx, k * k).mean(-1)


@pytest.mark.parametrize("dtype", DTYPES)
def test_photons_follow_inverse_square_law_without_refraction(dtype):
    """eta = 1 (no bending, T = 1): E = I_e cos / r^2 = I_e (L_z - z) / r^3 on the receiver plane."""
    scene = scenes.wavy_pool(2048, dtype=dtype)
    pm = photon_irradiance(scene.surface, LIGHT, intensity=2.0, eta=1.0, receiver=RECEIVER, n_photons=1 << 20,
                           seed=1, chunk=1 << 18)

    def exact(P):
        r = np.linalg.norm(P - LIGHT, axis=-1)
        return 2.0 * (LIGHT[2] - P[:, 2]) / r**3

    z = (pm.irradiance - _cell_average(exact, RECEIVER)) / pm.stderr
    assert 0.5 < np.mean(z**2) < 1.7, np.mean(z**2)
    assert pm.n_photons == 1 << 20


def test_receiver_cells_are_half_open_row_major_and_move_with_the_frame():
    """`ReceiverGrid.cells`: cell `j nx + i` holds `[x0 + i dx, x0 + (i+1) dx) x [y0 + j dy, ...)`;
    the far edges, points off the grid and invalid points land nowhere; in a frame moved by
    `origin` the same points (minus `origin`) land in the same cells."""
    grid = ReceiverGrid(0.0, -1.0, 1.0, 2.0, 3.0, 4, 2)  # dx 0.5, dy 0.5
    xy = np.array([[-1.0, 2.0], [-0.51, 2.49], [-0.5, 2.5], [0.99, 2.99], [1.0, 2.5], [0.0, 3.0],
                   [-1.01, 2.2], [0.2, 1.99], [0.2, 2.7]])
    cell, inside = grid.cells(xy)
    np.testing.assert_array_equal(inside, [1, 1, 1, 1, 0, 0, 0, 0, 1])
    np.testing.assert_array_equal(cell, [0, 0, 5, 7, 0, 0, 0, 0, 6])
    centres = grid.centers().reshape(-1, 3)
    np.testing.assert_array_equal(grid.cells(centres)[0], np.arange(8))
    valid = np.arange(9) != 8
    np.testing.assert_array_equal(grid.cells(xy, valid)[1], inside & valid)
    origin = np.array([100.0, -40.0])
    np.testing.assert_array_equal(grid.cells(xy - origin, origin=origin)[0], cell)


@pytest.mark.parametrize("dtype", DTYPES)
def test_photon_error_falls_as_inverse_sqrt_n(dtype):
    """Flat pool against the exact flat-interface irradiance: the RMS relative error at 16x the
    photons is about 1/4 (between 1/7 and 1/2.5 for 64 cells), and matches the reported error."""
    scene = scenes.flat_pool(512, dtype=dtype)
    ref = _cell_average(lambda P: flat_interface_irradiance(P, LIGHT, 0.0, 1.333), RECEIVER)
    rms, claimed = [], []
    for n in (1 << 16, 1 << 20):
        pm = photon_irradiance(scene.surface, LIGHT, intensity=1.0, receiver=RECEIVER, n_photons=n, seed=7,
                               chunk=1 << 16)
        rms.append(np.sqrt(np.mean((pm.irradiance / ref - 1) ** 2)))
        claimed.append(np.sqrt(np.mean((pm.stderr / ref) ** 2)))
    assert 1 / 7 < rms[1] / rms[0] < 1 / 2.5, rms
    np.testing.assert_allclose(claimed[1] / claimed[0], 0.25, rtol=0.05)
    for r, c in zip(rms, claimed, strict=True):
        assert 0.6 < r / c < 1.5


def test_same_seed_same_map_and_attenuation():
    scene = scenes.flat_pool(512, dtype=jnp.float64)
    kw = dict(intensity=1.0, receiver=RECEIVER, n_photons=1 << 16, chunk=1 << 15)
    a = photon_irradiance(scene.surface, LIGHT, seed=5, **kw)
    b = photon_irradiance(scene.surface, LIGHT, seed=5, **kw)
    np.testing.assert_array_equal(a.irradiance, b.irradiance)
    # Beer-Lambert: each photon weighs exp(-sigma_t t); on a flat pool 1 m deep t >= 1 m.
    c = photon_irradiance(scene.surface, LIGHT, seed=5, sigma_t=0.5, **kw)
    ratio = c.irradiance.sum() / a.irradiance.sum()
    assert np.exp(-0.5 * 1.2) < ratio < np.exp(-0.5)


@pytest.mark.parametrize("n, chunk, calls, traced", [(1000, 512, [(512, 1000), (1000, 1000)], [512, 512]),
                                                     (300, 1 << 16, [(300, 300)], [512])])
def test_exactly_n_photons_are_emitted_whatever_the_chunk(n, chunk, calls, traced, monkeypatch):
    """`n_photons` is what is emitted (it had been rounded up to whole chunks: 256 photons
    traced 65,536): with eta = 1 every photon through the emission plane that meets the
    surface lands on a receiver covering everything below, so at most `n` land and nearly
    all do; a count under the chunk size traces one chunk of the power of two above it."""
    from caustics_jax.transport import photons

    sizes, trace_chunk = [], photons._trace_chunk

    def spy(*args, chunk, **static):
        sizes.append(chunk)
        return trace_chunk(*args, chunk=chunk, **static)

    monkeypatch.setattr(photons, "_trace_chunk", spy)
    scene = scenes.flat_pool(512, dtype=jnp.float64)
    seen = []
    pm = photon_irradiance(scene.surface, LIGHT, intensity=1.0, eta=1.0, n_photons=n, chunk=chunk,
                           receiver=ReceiverGrid(-1.0, -9.0, 9.0, -9.0, 9.0, 4, 4),
                           progress=lambda done, total: seen.append((done, total)))
    assert pm.n_photons == n
    assert 0.9 * n <= pm.hits.sum() <= n
    assert seen == calls and sizes == traced


@pytest.mark.parametrize("kwargs, match", [
    (dict(L=[0, 0, -3.0]), "above the surface"),
    (dict(receiver=ReceiverGrid(0.5, -1, 1, -1, 1, 4, 4)), "below the surface"),
    (dict(receiver=ReceiverGrid(-1, 1, -1, -1, 1, 4, 4)), "x1 > x0"),
    (dict(n_photons=-1), "n_photons"),  # (0 photons: an all-zero map, tests/test_contract.py)
    (dict(intensity=float("nan")), "intensity"),
    (dict(L=[0, 0]), "shape"),
    # traced in the mesh's dtype: a float32 receiver plane at -1e39 had been traced at -inf
    (dict(receiver=ReceiverGrid(-1e39, -1, 1, -1, 1, 4, 4), dtype=jnp.float32),
     r"receiver \(z, x0, x1, y0, y1\) overflows"),
])
def test_photon_irradiance_rejects_bad_input(kwargs, match):
    scene = scenes.flat_pool(128, dtype=kwargs.pop("dtype", jnp.float64))
    args = dict(L=LIGHT, intensity=1.0, receiver=RECEIVER, n_photons=1024)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        photon_irradiance(scene.surface, args.pop("L"), **args)


@pytest.mark.parametrize("dtype", DTYPES)
def test_photons_traced_one_by_one_bin_to_the_flat_interface_irradiance(dtype):
    """`trace_photons` on stratified emission points (a jittered 512 x 512 grid over the
    emission plane, each photon standing for its stratum): binned `flux T exp(-sigma_t t)`
    matches the exact flat-interface irradiance times the attenuation within the photons'
    own error; `T` is the exact Fresnel transmittance at `cos_i`, and `t` is the refracted
    ray's length from the plane z = 0 to the floor (Snell: `sin_t = sin_i / eta`)."""
    from caustics_jax import fresnel_transmittance
    from caustics_jax.transport import EmissionPlane, trace_photons

    scene = scenes.flat_pool(512, dtype=dtype)
    plane = EmissionPlane.covering(scene.surface, LIGHT)
    k = 512
    rng = np.random.default_rng(3)
    s = (np.arange(k)[:, None] + rng.uniform(0, 1, (k, k))) / k
    X = np.stack([plane.x0 + s.reshape(-1) * (plane.x1 - plane.x0),
                  plane.y0 + ((np.arange(k)[None, :] + rng.uniform(0, 1, (k, k))) / k).reshape(-1)
                  * (plane.y1 - plane.y0), np.full(k * k, plane.z)], -1)
    hits = trace_photons(scene.surface, LIGHT, X, intensity=1.0, area=plane.area / k**2, receiver_z=RECEIVER.z)
    v = hits.valid
    assert v.mean() > 0.99
    np.testing.assert_allclose(hits.T[v], np.asarray(fresnel_transmittance(hits.cos_i[v], 1 / 1.333)), rtol=1e-5)
    sin_t = np.sqrt(1 - hits.cos_i[v] ** 2) / 1.333
    np.testing.assert_allclose(hits.t[v], -RECEIVER.z / np.sqrt(1 - sin_t**2), rtol=1e-4)
    sigma = 0.4
    w = hits.flux * hits.T * np.exp(-sigma * hits.t)
    cell, inside = RECEIVER.cells(hits.Y, v)
    E = np.bincount(cell[inside], w[inside], 64).reshape(8, 8) / RECEIVER.cell_area

    def exact(P):
        return flat_interface_irradiance(P, LIGHT, 0.0, 1.333, sigma_t=sigma)

    ref = _cell_average(exact, RECEIVER)
    # about 1,000 photons per cell, stratified: cells scatter by <= 1.5% (float64, measured), the
    # mean by far less; a missing Fresnel factor would bias it by 2%, attenuation by 40%
    assert abs(np.mean(E / ref - 1)) < 3e-3 and np.max(np.abs(E / ref - 1)) < 0.03


def test_trace_photons_refuses_points_off_the_emission_plane_and_a_receiver_above_the_water():
    from caustics_jax.transport import EmissionPlane, trace_photons

    scene = scenes.flat_pool(512, dtype=jnp.float32)
    plane = EmissionPlane.covering(scene.surface, LIGHT)
    X = np.array([[0.0, 0.0, plane.z], [0.1, 0.2, plane.z]])
    with pytest.raises(ValueError, match="emission plane"):
        trace_photons(scene.surface, LIGHT, X - [0, 0, 0.1], intensity=1.0, area=1.0, receiver_z=-1.0)
    with pytest.raises(ValueError, match="below the surface"):
        trace_photons(scene.surface, LIGHT, X, intensity=1.0, area=1.0, receiver_z=0.5)
    with pytest.raises(ValueError, match="area"):
        trace_photons(scene.surface, LIGHT, X, intensity=1.0, area=[1.0, -1.0], receiver_z=-1.0)
