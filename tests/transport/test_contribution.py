"""Caustic irradiance from a solved path (seed 001 eq. 25 with math.md §6's factors), three ways:
an independent flat-interface formula, brute-force photons, and the forward photon differential."""

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from caustics_jax import scenes
from caustics_jax.solvers import solve
from caustics_jax.testing import flat_interface_irradiance
from caustics_jax.transport import (
    ReceiverGrid,
    irradiance,
    path_irradiance,
    photon_differential_irradiance,
    photon_irradiance,
    surface_hits,
)
from caustics_jax.transport.photon_differentials import light_view_texels, texel_jacobian
from caustics_jax.transport.photons import EmissionPlane

DTYPES = [jnp.float32, jnp.float64]
LIGHT = np.array([0.4, -0.3, 3.0])
UP = np.array([0.0, 0.0, 1.0])
# float32 / float64 relative error against the float64 formula, measured on 1024 flat-pool
# receivers with lights drawn as in the property test: max 3.4e-6 (float32), 2.6e-11
# (float64, the bisection of the reference); bounds with margin.
REL_TOL = {jnp.float32: 2e-5, jnp.float64: 1e-9}


@pytest.mark.parametrize("method, features", [("walk", None), ("newton", None), ("walk", "auto")])
@pytest.mark.parametrize("dtype", DTYPES)
@settings(max_examples=5)  # each example is 1024 receivers under its own light and eta
@given(seed=st.integers(0, 2**31 - 1))
def test_irradiance_matches_flat_interface_formula(dtype, method, features, seed):
    """`eta^2 T cos D^-1 I_e` equals the exact flat-interface irradiance (a wrong eta^2, cos or T fails)
    wherever the solver finds the path; lanes it does not find carry a failure status and E = 0."""
    rng = np.random.default_rng(seed)
    scene = scenes.flat_pool(512, n_receivers=32, dtype=dtype)
    L = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0.5, 5)])
    eta = rng.uniform(1.05, 1.6)
    sigma_t = rng.uniform(0, 0.5)
    E, sol = irradiance(scene.surface, scene.receivers, jnp.asarray(L, dtype), intensity=3.0, eta=eta,
                        receiver_normal=UP, sigma_t=sigma_t, method=method, return_solution=True,
                        features=features)
    E, found = np.asarray(E), np.asarray(sol.found)
    ref, M = flat_interface_irradiance(np.asarray(scene.receivers), L, 0.0, eta, 3.0, sigma_t, return_point=True)
    assert E.dtype == dtype
    # The surface ends at |x|, |y| = 2.1: beyond it there is no path and no light.
    edge = float(np.max(np.asarray(scene.surface.vertices)[:, 0]))
    inside = np.all(np.abs(M[:, :2]) < edge - 1e-3, -1)
    outside = np.any(np.abs(M[:, :2]) > edge + 1e-3, -1)
    np.testing.assert_array_less(np.abs(E / ref - 1)[inside & found], REL_TOL[dtype])
    assert np.all(E[outside | ~found] == 0)
    assert inside.mean() > 0.5
    if method == "newton" or features == "auto":  # "auto": the flat pool's closed form
        assert np.all(found[inside])
    else:
        # The general walk misses a few paths whose M0 lies in total internal reflection
        # (low lights, large eta; at most 5 of 1024 measured): LEFT_MESH with E = 0.
        assert found[inside].mean() > 0.99


def test_paraxial_limit_on_axis():
    """Straight below the light: `E = I_e T / (h + d/eta)^2` (math.md §6's paraxial analysis)."""
    scene = scenes.flat_pool(512, dtype=jnp.float64)
    h, d, eta = 2.5, 1.0, 1.333
    E = irradiance(scene.surface, jnp.asarray([[0.1, 0.2, -d]]), jnp.asarray([0.1, 0.2, h]), intensity=1.0,
                   eta=eta, receiver_normal=UP)
    T = 1 - ((eta - 1) / (eta + 1)) ** 2
    np.testing.assert_allclose(np.asarray(E), T / (h + d / eta) ** 2, rtol=1e-12)


def test_receiver_normal_and_attenuation_factors():
    """A tilted receiver catches `cos(theta_P)` of the light, a back-facing one none; Beer-Lambert
    multiplies by `exp(-sigma_t |P - M|)` with `M` the returned refraction point."""
    scene = scenes.wavy_pool(2048, n_receivers=8, dtype=jnp.float64)
    P, mesh = scene.receivers, scene.surface
    L = jnp.asarray(LIGHT)
    E_up = np.asarray(irradiance(mesh, P, L, intensity=1.0, receiver_normal=UP))
    sol = solve(mesh, P, jnp.broadcast_to(L, P.shape))
    w = np.asarray(P - sol.point)
    w = w / np.linalg.norm(w, axis=-1, keepdims=True)
    tilt = np.array([0.6, 0.0, 0.8])
    E_tilt = np.asarray(irradiance(mesh, P, L, intensity=1.0, receiver_normal=tilt))
    np.testing.assert_allclose(E_tilt, E_up * np.maximum(-w @ tilt, 0) / (-w[:, 2]), rtol=1e-12)
    assert np.all(np.asarray(irradiance(mesh, P, L, intensity=1.0, receiver_normal=-UP)) == 0)
    E_att = np.asarray(irradiance(mesh, P, L, intensity=1.0, receiver_normal=UP, sigma_t=0.7))
    d_P = np.linalg.norm(np.asarray(P - sol.point), axis=-1)
    np.testing.assert_allclose(E_att, E_up * np.exp(-0.7 * d_P), rtol=1e-12)


@pytest.mark.parametrize("dtype", DTYPES)
def test_irradiance_agrees_with_brute_force_photons(dtype):
    """Walk + D against photons binned on 12 x 12 cells of a pre-focal wavy pool: the differences
    are Monte-Carlo noise (z-scores against the photon standard error)."""
    scene = scenes.wavy_pool(4096, amplitude=0.04, dtype=dtype)
    receiver = ReceiverGrid(-1.0, -1.2, 1.2, -1.2, 1.2, 12, 12)
    pm = photon_irradiance(scene.surface, LIGHT, intensity=1.0, receiver=receiver, n_photons=1 << 20, seed=3,
                           chunk=1 << 18)
    k = 3  # cell average by the 3 x 3 midpoint rule
    P = jnp.asarray(receiver.subsamples(k).reshape(-1, 3), dtype)
    E = np.asarray(irradiance(scene.surface, P, jnp.asarray(LIGHT, dtype), intensity=1.0, receiver_normal=UP))
    E_cell = E.reshape(receiver.ny, receiver.nx, k * k).mean(-1)
    z = (pm.irradiance - E_cell) / pm.stderr
    # 144 cells of standard-normal noise: mean z^2 within [0.6, 1.5] (chi-square, p > 0.999),
    # no cell beyond 4.5 sigma. Dropping eta^2 shifts every cell by ~40 sigma.
    assert 0.6 < np.mean(z**2) < 1.5, np.mean(z**2)
    assert np.max(np.abs(z)) < 4.5
    assert np.all(pm.hits > 500)


def test_photon_differential_equals_walk_on_flat_and_converges_on_curved():
    """Forward (photon differential) and backward (walk + D) irradiance at the same landing point:
    equal to rounding with constant normals; with interpolated normals they differ by O(h),
    because a Phong normal field is not the gradient of the surface (no reciprocity)."""
    medians = []
    for scene in (scenes.flat_pool(2048, dtype=jnp.float64),
                  scenes.wavy_pool(2048, amplitude=0.06, dtype=jnp.float64),
                  scenes.wavy_pool(8192, amplitude=0.06, dtype=jnp.float64),
                  scenes.wavy_pool(32768, amplitude=0.06, dtype=jnp.float64)):
        mesh = scene.surface
        plane = EmissionPlane.covering(mesh, LIGHT)
        rng = np.random.default_rng(0)
        X = jnp.asarray(np.stack([rng.uniform(-1.5, 1.5, 1024), rng.uniform(-1.5, 1.5, 1024),
                                  np.full(1024, plane.z)], -1))
        L = jnp.asarray(LIGHT)
        face, ab, found = surface_hits(mesh, L, X)
        V, N = mesh.triangle(face)
        E_fwd, Y, ok = photon_differential_irradiance(V, N, L, X, 1.333, 1.0, jnp.asarray([0, 0, -1.0]),
                                                      jnp.asarray(UP))
        E_bwd, ok_b = path_irradiance(V, N, Y, jnp.broadcast_to(L, Y.shape), ab, 1.333, 1.0, jnp.asarray(UP))
        good = np.asarray(found & ok & ok_b)
        assert good.mean() > 0.99
        rel = np.abs(np.asarray(E_fwd) / np.asarray(E_bwd) - 1)[good]
        medians.append(np.median(rel))
    assert medians[0] < 1e-13
    # Measured: 8.3e-4, 4.0e-4, 2.0e-4 for 2k/8k/32k triangles (h halves each step).
    assert medians[1] < 2e-3
    for coarse, fine in zip(medians[1:], medians[2:], strict=False):
        assert 0.35 < fine / coarse < 0.65


def test_all_paths_sums_every_exhaustive_solution():
    """Past the focal distance several paths reach one receiver: `all_paths` is their sum, at least
    the single path's irradiance, equal to it where there is one path. Receivers on a folded
    sheet of the light-view map (texels with det J < 0) have at least two paths."""
    scene = scenes.wavy_pool(1024, amplitude=0.2, depth=3.0, n_receivers=3, dtype=jnp.float64)
    mesh, L = scene.surface, jnp.asarray(LIGHT)
    tx = light_view_texels(mesh, LIGHT, 64)
    V, N = mesh.triangle(tx.face)
    J, Y, *_, ok = texel_jacobian(V, N, L, tx.X, 1.333, jnp.asarray([0, 0, -3.0]), jnp.asarray(UP))
    folded = (np.linalg.det(np.asarray(J)) < 0) & np.asarray(ok & tx.found)
    P = jnp.concatenate([jnp.asarray(np.asarray(Y)[folded][:8]), scene.receivers])
    res = solve(mesh, P, jnp.broadcast_to(L, P.shape), method="exhaustive", return_all=True)
    count = np.asarray(res.count)
    assert (count > 1).sum() >= 6 and (count == 1).any()
    total = np.asarray(irradiance(mesh, P, L, intensity=1.0, receiver_normal=UP, method="exhaustive",
                                  all_paths=True))
    single = np.asarray(irradiance(mesh, P, L, intensity=1.0, receiver_normal=UP, method="exhaustive"))
    np.testing.assert_allclose(total[count == 1], single[count == 1], rtol=1e-12)
    assert np.all(total[count > 1] > single[count > 1])


@pytest.mark.parametrize("kwargs, match", [
    (dict(intensity=-1.0, receiver_normal=UP), "intensity"),
    (dict(intensity=1.0, receiver_normal=[0, 0, 0]), "receiver_normal"),
    (dict(intensity=1.0, receiver_normal=[[0, 0, 1.0]] * 3), "broadcast"),
    (dict(intensity=1.0, receiver_normal=UP, sigma_t=-1.0), "sigma_t"),
    (dict(intensity=1.0, receiver_normal=UP, all_paths=True, method="newton"), "exhaustive"),
    (dict(intensity=1.0, receiver_normal=UP, visibility="yes"), "visibility"),
    (dict(intensity=1.0, receiver_normal=UP, method="magic"), "method"),
])
def test_irradiance_rejects_bad_input(kwargs, match):
    scene = scenes.flat_pool(128, n_receivers=2, dtype=jnp.float64)
    with pytest.raises(ValueError, match=match):
        irradiance(scene.surface, scene.receivers, jnp.asarray(LIGHT), **kwargs)


def test_no_path_gives_zero_and_no_nan():
    """Receivers above the water (segment never crosses) and at total internal reflection: E = 0."""
    scene = scenes.flat_pool(512, dtype=jnp.float32)
    P = jnp.asarray([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [5.0, 0.0, -1.0]], jnp.float32)
    E = np.asarray(irradiance(scene.surface, P, jnp.asarray([0.0, 0.0, 3.0], jnp.float32), intensity=1.0,
                              receiver_normal=UP))
    assert np.all(np.isfinite(E))
    assert E[0] == 0 and E[1] > 0


def _segments_cross_surface(mesh, A, B):
    """Brute force, numpy float64: does segment `A[i] -> B[i]` cross any face (Moller-Trumbore
    against every triangle, closed edges)? Independent of the acceleration structures."""
    V = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)]
    e1, e2 = V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
    d = B - A
    out = np.zeros(len(A), bool)
    for i in range(len(A)):
        p = np.cross(d[i], e2)
        det = np.sum(e1 * p, -1)
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1 / np.where(ok, det, 1), 0)
        t = A[i] - V[:, 0]
        a = np.sum(t * p, -1) * inv
        q = np.cross(t, e1)
        b = np.sum(d[i] * q, -1) * inv
        s = np.sum(e2 * q, -1) * inv
        out[i] = np.any(ok & (a >= 0) & (b >= 0) & (a + b <= 1) & (s >= 0) & (s <= 1))
    return out


def test_visibility_drops_exactly_the_paths_the_surface_blocks():
    """Steep waves (amplitude 0.1 m, wavelength 0.6 m) under light 15 degrees above the horizon:
    some refracted paths leave the water and cross a crest before the light. The paths
    `path_visible` drops are those whose segments (the end at M pulled back by its eps)
    cross the surface by a brute-force test of every triangle, and the all-path
    irradiance with visibility is the sum over the others."""
    from caustics_jax.transport import path_visible
    from caustics_jax.transport.visibility import visibility_eps

    e = np.radians(15.0)
    scene = scenes.wavy_pool(512, amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6), n_receivers=4,
                             light_position=(6 * np.cos(e), 0.0, 6 * np.sin(e)), dtype=jnp.float64)
    mesh, P = scene.surface, np.asarray(scene.receivers)
    L = np.asarray(scene.lights.endpoint(P))
    res = solve(mesh, P, L, method="exhaustive", return_all=True)
    valid = np.arange(res.all_points.shape[1])[None] < res.count[:, None]
    lane, k = np.nonzero(valid)
    M = res.all_points[lane, k]
    vis = path_visible(mesh, P[lane], M, L[lane])
    eps = visibility_eps(jnp.float64)
    blocked = (_segments_cross_surface(mesh, P[lane], M + eps * (P[lane] - M))
               | _segments_cross_surface(mesh, M + eps * (L[lane] - M), L[lane]))
    np.testing.assert_array_equal(vis, ~blocked)
    assert blocked.any() and (~blocked).any(), blocked.sum()  # measured: BLOCKED_COUNT of PATH_COUNT
    kw = dict(intensity=1.0, receiver_normal=UP, method="exhaustive", all_paths=True)
    E = np.asarray(irradiance(mesh, P, L, **kw))
    E_vis = np.asarray(irradiance(mesh, P, L, visibility=True, **kw))
    V, N = mesh.triangle(jnp.asarray(res.all_triangles[lane, k]))
    E_path, _ = path_irradiance(V, N, jnp.asarray(P[lane]), jnp.asarray(L[lane]),
                                jnp.asarray(res.all_barycentric[lane, k]), 1.333, 1.0, jnp.asarray(UP), 0.0)
    expected = np.zeros(len(P))
    np.add.at(expected, lane[vis], np.asarray(E_path)[vis])
    np.testing.assert_allclose(E_vis, expected, rtol=1e-12, atol=1e-300)
    assert np.all(E_vis <= E) and np.any(E_vis < E)
    # The single-path irradiance drops the walk's path exactly where it is blocked.
    E1, sol = irradiance(mesh, P, L, intensity=1.0, receiver_normal=UP, return_solution=True)
    E1_vis = np.asarray(irradiance(mesh, P, L, intensity=1.0, receiver_normal=UP, visibility=True))
    found = np.asarray(sol.found)
    walk_vis = path_visible(mesh, P[found], np.asarray(sol.point)[found], L[found])
    np.testing.assert_array_equal(E1_vis[found] == 0, ~walk_vis | (np.asarray(E1)[found] == 0))


def test_visibility_changes_nothing_where_no_path_is_blocked():
    """The gentle pool under a high light: no crest lies between a refraction point and the light."""
    scene = scenes.wavy_pool(512, n_receivers=4, dtype=jnp.float64)
    P = scene.receivers
    L = scene.lights.endpoint(P)
    kw = dict(intensity=1.0, receiver_normal=UP)
    np.testing.assert_array_equal(np.asarray(irradiance(scene.surface, P, L, visibility=True, **kw)),
                                  np.asarray(irradiance(scene.surface, P, L, **kw)))


def test_all_paths_irradiance_is_in_the_mesh_dtype():
    """`all_paths=True` on a float32 mesh (walk's every-solution trace) returns float32, as
    the single path does; a float64 `receiver_normal` under x64 had made the sum float64."""
    sc = scenes.wavy_pool(128, amplitude=0.05, dtype="float32")
    P = np.float32([[0.1, 0.2, -1.0], [-0.3, 0.4, -1.2]])
    L = np.float32([0.4, -0.3, 3.0])
    for all_paths in (False, True):
        E = irradiance(sc.surface, P, L, intensity=1.0, receiver_normal=np.asarray([0.0, 0.0, 1.0]),
                       all_paths=all_paths)
        assert E.dtype == np.float32, (all_paths, E.dtype)
        assert np.all(np.isfinite(np.asarray(E))) and np.all(np.asarray(E) > 0)
