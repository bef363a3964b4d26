"""Directional lights (surface/lights.py, math.md §9): `Directional(direction)` wherever a
point light goes, solved in the limit of `L` at infinity, and far point lights (a sun
1.5e11 m away) in float32 instead of refused."""

import argparse
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import caustics_jax as cj
from caustics_jax.app.compare import load_scene
from caustics_jax.app.scene_file import scene_options
from caustics_jax.surface.lights import light_points, limit_distance, scene_size
from caustics_jax.testing.oracle import flat_interface_irradiance_directional, refraction_angle_error

SUN = np.array([-0.3, -0.2, -1.0]) / np.linalg.norm([-0.3, -0.2, -1.0])  # the way the rays travel
FAR = 1.5e11  # m: the sun's distance


@pytest.fixture(scope="module")
def wavy():
    with cj.precision("float64"):
        return {dt: cj.scenes.wavy_pool(2048, n_receivers=16, dtype=dt) for dt in ("float32", "float64")}


def test_directional_takes_any_finite_non_zero_direction_and_normalises_it():
    d = cj.Directional([0, 0, -1e-200])
    np.testing.assert_array_equal(d.direction, [0, 0, -1])
    np.testing.assert_array_equal(d.toward, [0, 0, 1])
    np.testing.assert_allclose(np.linalg.norm(cj.Directional([3e200, 4e200, 0]).direction), 1, rtol=1e-15)
    for bad, match in (([0, 0, 0], "finite and non-zero"), ([0, np.nan, -1], "finite and non-zero"),
                       ([0, -1], r"shape \(3,\)"), ("down", "real")):
        with pytest.raises(ValueError, match=match):
            cj.Directional(bad)


def test_the_placed_point_is_on_the_ray_toward_the_light_at_the_limit_distance():
    P = np.array([[0.0, 0.0, -1.0], [1.0, 2.0, -1.0]])
    placed = light_points(cj.Directional(SUN), P, 4.0, np.float32)
    R = limit_distance(4.0, np.float32)
    assert R == 4.0 * 2.0**26 and placed.at_infinity.all() and np.all(placed.gain == 1)
    np.testing.assert_allclose(placed.points, P - R * SUN, rtol=1e-15)
    # A far point light: moved onto its ray at R, its 1/d^2 kept as the gain; a near one is untouched.
    L = np.array([[0.0, 0.0, FAR], [0.4, -0.3, 3.0]])
    placed = light_points(L, P, 4.0, np.float32)
    assert placed.at_infinity.tolist() == [True, False]
    np.testing.assert_array_equal(placed.points[1], L[1])
    np.testing.assert_allclose(np.linalg.norm(placed.points[0] - P[0]), R)
    assert not light_points(L, P, 4.0, np.float64).at_infinity.any()  # float64's R is 1.4e17 m here
    np.testing.assert_allclose(placed.gain[0], 1 / (FAR + 1) ** 2, rtol=1e-12)
    assert scene_size(np.array([[0, 0, 0], [4.0, 2, 0]]), np.array([[2.0, 1, -10]])) == 20.0


def test_lights_that_cannot_be_far_are_placed_as_when_one_lane_is():
    """`light_points` skips the normalisation when no lane can be farther than `R` (every
    component of `L - P` below `R / sqrt(3)`): the same lanes, with and without one far lane
    that forces the full computation, come back bit for bit; lanes along the diagonal just
    inside and outside `R` are far exactly where `|L - P| > R`."""
    R = limit_distance(4.0, np.float32)
    rng = np.random.default_rng(3)
    P = rng.uniform(-2, 2, (64, 3))
    u = rng.normal(size=(64, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    near = P + (R / np.sqrt(3)) * rng.uniform(0.5, 0.999, (64, 1)) * u
    diag = np.full(3, 1 / np.sqrt(3))
    edge = np.stack([P[0] + R * (1 - 1e-9) * diag, P[1] + R * (1 + 1e-9) * diag])
    alone = light_points(near, P, 4.0, np.float32)
    mixed = light_points(np.concatenate([near, edge]), np.concatenate([P, P[:2]]), 4.0, np.float32)
    assert not alone.at_infinity.any() and np.all(alone.gain == 1)
    np.testing.assert_array_equal(alone.points, near)
    for a, b in zip(alone, mixed, strict=True):
        np.testing.assert_array_equal(a, b[:64])
    assert mixed.at_infinity[64:].tolist() == [False, True]
    np.testing.assert_array_equal(mixed.points[64], edge[0])
    np.testing.assert_allclose(np.linalg.norm(mixed.points[65] - P[1]), R, rtol=1e-12)


@pytest.mark.parametrize("dtype, tol", [("float64", 1e-10), ("float32", 1e-5)])
def test_found_paths_refract_exactly_toward_the_light_at_infinity(wavy, dtype, tol):
    """Checked against the limit itself: the oracle's `w_L` is `Directional.toward`, not the
    placed point. The angle stays within the solver's `tol` plus the rounding of the
    returned point (float32: the float32 audit's 1e-6 noise floor of `f`)."""
    sc = wavy[dtype]
    P = np.asarray(sc.receivers, np.float64)
    sol = cj.solve(sc.surface, P, cj.Directional(SUN))
    found = np.asarray(sol.found)
    assert found.mean() > 0.85
    err = refraction_angle_error(sc.surface, np.asarray(sol.triangle)[found], np.asarray(sol.barycentric)[found],
                                 P[found], cj.Directional(SUN), 1.333)
    assert err.max() <= (1.0001 * tol if dtype == "float64" else tol + 2e-6), err.max()


def test_a_far_sun_and_the_directional_light_agree_in_float32(wavy):
    """A point light 1.5e11 m away (refused in float32 before) gives the lanes and points of
    `Directional`. Measured: identical points and irradiance on this pool (the far point is
    moved onto each receiver's ray at float32's limit distance, and its direction differs by
    a parallax of 1e-11 rad). Before that move, a point sun 1.5e11 m away gave 2.4e-7 m and
    3.6e-7; the bounds are 4x and 10x those."""
    sc = wavy["float32"]
    P = np.asarray(sc.receivers, np.float64)
    E_perp = 1000.0  # W/m^2
    a = cj.solve(sc.surface, P, cj.Directional(SUN))
    b = cj.solve(sc.surface, P, -FAR * SUN)
    fa, fb = np.asarray(a.found), np.asarray(b.found)
    np.testing.assert_array_equal(fa, fb)
    assert np.abs(np.asarray(a.point) - np.asarray(b.point))[fa].max() <= 1e-6
    n = [0.0, 0.0, 1.0]
    E_dir = np.asarray(cj.irradiance(sc.surface, P, cj.Directional(SUN), intensity=E_perp, receiver_normal=n))
    E_far = np.asarray(cj.irradiance(sc.surface, P, -FAR * SUN, intensity=E_perp * FAR**2, receiver_normal=n))
    assert np.all(np.isfinite(E_dir)) and np.all(E_dir[fa] > 0) and np.all(E_dir[~fa] == 0)
    np.testing.assert_allclose(E_far[fa], E_dir[fa], rtol=4e-6)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_flat_water_under_the_sun_gets_T_E_perp_cos_theta_everywhere(dtype):
    """A parallel beam through a flat interface stays parallel: a horizontal receiver gets
    `E_perp cos(theta_i) T(theta_i)` (oracle), here from `eta^2 T cos_P E_perp / (D / d_L^2)`
    with the D factor's limit. float64: the solver's angle tolerance 1e-10 bounds it
    (measured 6.7e-12); float32: the D factor's rounding, measured 3.3e-6, bound 1e-5."""
    sc = cj.scenes.flat_pool(512, n_receivers=8, dtype=dtype)
    P = np.asarray(sc.receivers, np.float64)
    P = P[np.all(np.abs(P[:, :2]) < 1.0, axis=1)]  # refraction points inside the pool
    sun = cj.Directional([0.3, -0.2, -0.9])
    E = np.asarray(cj.irradiance(sc.surface, P, sun, intensity=2.0, receiver_normal=[0, 0, 1]))
    want = flat_interface_irradiance_directional(sun.toward, 1.333, 2.0)
    np.testing.assert_allclose(E, want, rtol=1e-10 if dtype == "float64" else 1e-5)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_photons_under_the_sun_match_the_flat_interface_formula(dtype):
    """Parallel photons through the emission plane (flux `E_perp A_e |d_z| / n`): the mean
    over the cells equals the formula within 5 standard errors, in both dtypes; a flux without
    the cross-section factor |d_z| fails it."""
    sc = cj.scenes.flat_pool(512, dtype=dtype)
    sun = cj.Directional([0.6, 0.3, -1.0])  # |d_z| = 0.83: a flux without it is 20% off
    grid = cj.ReceiverGrid(z=-1.0, x0=-1.0, x1=1.0, y0=-1.0, y1=1.0, nx=4, ny=4)
    pm = cj.photon_irradiance(sc.surface, sun, intensity=1000.0, receiver=grid, n_photons=1 << 18)
    want = flat_interface_irradiance_directional(sun.toward, 1.333, 1000.0)
    mean, err = pm.irradiance.mean(), np.sqrt(np.sum(pm.stderr**2)) / pm.irradiance.size
    assert abs(mean - want) <= 5 * err, (mean, want, err)
    with pytest.raises(ValueError, match="must travel down"):
        cj.photon_irradiance(sc.surface, cj.Directional([0, 0, 1]), intensity=1.0, receiver=grid, n_photons=16)


def test_a_sun_travelling_up_warns_that_the_light_is_below():
    sc = cj.scenes.flat_pool(512, n_receivers=8, dtype="float32")
    with pytest.warns(UserWarning, match="the light is below the surface.*way its rays travel"):
        sol = cj.solve(sc.surface, np.asarray(sc.receivers), cj.Directional([0, 0, 1]))
    assert np.all(np.asarray(sol.status) == cj.Status.NO_CROSSING)


def test_far_lights_beyond_the_products_float32_resolves_are_refused_with_the_way_out():
    V = np.array([[0, 0, 0], [1e8, 0, 0], [0, 1e8, 0]], np.float64)
    mesh = cj.SurfaceMesh.from_arrays(V, np.array([[0, 1, 2]]), dtype="float32")
    with pytest.raises(ValueError, match="light's coordinates reach .*Directional"):
        cj.solve(mesh, [[1e7, 1e7, -1e7]], [[1e7, 1e7, 1e15]])


def test_the_sms_estimators_take_the_sun(wavy):
    sc = wavy["float32"]
    P = np.asarray(sc.receivers, np.float64)[:16]
    kw = dict(k=8, seed=3, receiver_normal=[0, 0, 1])
    a = cj.sms_biased(sc.surface, P, cj.Directional(SUN), intensity=1000.0, **kw)
    b = cj.sms_biased(sc.surface, P, -FAR * SUN, intensity=1000.0 * FAR**2, **kw)
    np.testing.assert_array_equal(a.paths, b.paths)
    assert a.paths.sum() > 0 and np.all(np.isfinite(a.irradiance))
    np.testing.assert_allclose(a.irradiance, b.irradiance, rtol=4e-6)


def test_scene_options_take_the_sun_from_the_flag_or_the_scene_file(tmp_path):
    args = argparse.Namespace(scene_file=None, scene=None, light=None, sun=[0.1, 0.0, -1.0], floor_depth=None,
                              eta=None, lanes=None)
    got = scene_options(args, {"scene": None, "light": None, "floor_depth": None, "eta": None, "lanes": 256})
    assert isinstance(got["light"], cj.Directional) and got["light"].direction[2] < 0
    with pytest.raises(ValueError, match="exclude each other"):
        scene_options(argparse.Namespace(scene_file=None, light=[0, 0, 3], sun=[0, 0, -1]), {"light": None})
    toml = tmp_path / "s.toml"
    toml.write_text("sun = [0, 0, -1]\n")
    got = scene_options(argparse.Namespace(scene_file=str(toml), light=None, sun=None), {"light": None})
    np.testing.assert_array_equal(got["light"].direction, [0, 0, -1])
    got = scene_options(argparse.Namespace(scene_file=str(toml), light=[0, 0, 3], sun=None), {"light": None})
    assert got["light"] == (0, 0, 3)  # the flag wins over the file
    sc = load_scene("flat", 512, "float64", light=cj.Directional([0, 0, -1]))
    assert sc.lights.directional == (True,)
    np.testing.assert_array_equal(sc.lights.source(0).direction, [0, 0, -1])


def test_lights_source_is_the_light_itself():
    with cj.precision("float64"):
        sc = cj.scenes.flat_pool(512, light="both", dtype="float64")
    assert isinstance(sc.lights.source(1), cj.Directional)
    np.testing.assert_allclose(sc.lights.source(1).toward, np.asarray(sc.lights.direction[1]))
    np.testing.assert_array_equal(sc.lights.source(0), np.asarray(sc.lights.position[0]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert jnp.asarray(sc.lights.source(0)).shape == (3,)


def test_start_points_take_the_sun_as_solve_places_it(wavy):
    sc = wavy["float32"]
    P = np.asarray(sc.receivers, np.float64)
    a = cj.start_points(sc.surface, P, cj.Directional(SUN))
    sol = cj.solve(sc.surface, P, cj.Directional(SUN))
    np.testing.assert_array_equal(np.asarray(a.found), np.asarray(sol.status) != cj.Status.NO_CROSSING)
    hit = np.asarray(a.found)
    np.testing.assert_allclose(np.asarray(sol.start_point)[hit],
                               cj.barycentric_point(*[np.asarray(x) for x in sc.surface.triangle(a.face)][:1],
                                                    a.barycentric)[hit], atol=1e-6)
