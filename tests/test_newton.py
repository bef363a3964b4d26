"""Newton baselines (math.md §5: MNEE/SMS on optimistix) on planted paths and steep waves.

Every run uses the same mesh size (2048 faces, as `test_walk.py`) and the same number of
paths (256), so jit compiles once per (dtype, options).
"""

import functools

import jax
import numpy as np
import pytest

from caustics_jax import scenes, solve
from caustics_jax.solvers import Solution, default_tol
from caustics_jax.testing import assert_solution_sane as _sane
from caustics_jax.testing import planted_mesh_paths, refraction_angle_error

DTYPES = ["float32", "float64"]
N_PATHS = 256
ETA = 1.333
# Angle error (rad, float64 reference) of a found point. float64: measured max 2.0e-15
# (Newton, both constraints) and 9.5e-11 (Levenberg-Marquardt, which stops as soon as
# |f| <= tol = 1e-10); the bound is 2 tol. float32: measured max 1.0e-6 (angle difference on
# the lagoon), bound 1e-5 = the float32 tol.
ANGLE_TOL = {"float32": 1e-5, "float64": 2e-10}
# Distance from the planted M. Every planted path here has exactly one solution (the
# exhaustive reference returns count == 1 for all 256 on wavy, jittered and lagoon), so a
# found point must be M itself. Measured max: float64 5.0e-16 (Newton, both constraints),
# 4.7e-11 (LM, which stops at |f| <= 1e-10); float32 2.4e-7 (coordinates of size 2 rounded).
POINT_TOL = {"float32": 2e-6, "float64": 5e-10}
# stepping="one_step" stops at the first point with |f| <= tol instead of converging past it
# (as the walk does): measured max angle error 9.8e-6 (float32) and 9.8e-11 (float64), max
# distance from the planted point 4.9e-6 and 5.2e-11 m over the four scenes; the bounds
# are 2 tol for the angle and 4 tol (m) for the distance.
ONE_STEP_ANGLE_TOL = {"float32": 2e-5, "float64": 2e-10}
ONE_STEP_POINT_TOL = {"float32": 4e-5, "float64": 4e-10}

SCENES = {
    "flat": lambda dt: scenes.flat_pool(2048, dtype=dt),
    "wavy": lambda dt: scenes.wavy_pool(2048, amplitude=0.05, dtype=dt),
    "wavy_jittered": lambda dt: scenes.wavy_pool(2048, amplitude=0.05, choppiness=0.5, dtype=dt),
    "lagoon": lambda dt: scenes.lagoon(2048, dtype=dt),
}


@functools.cache
def _mesh(scene, dtype):
    return SCENES[scene](dtype).surface


@functools.cache
def _planted(scene):
    return planted_mesh_paths(_mesh(scene, "float64"), N_PATHS, seed=7)


@functools.cache
def _steep(dtype):
    """One steep short wave (slope 1.05): the floor sees caustics, so some receivers have
    several refraction points and some paths end in total internal reflection. 256
    receivers under a point light."""
    make = functools.partial(scenes.wavy_pool, 2048, amplitude=0.1, n_waves=1,
                             wavelength=(0.6, 0.6), n_receivers=16)
    ref = make(dtype="float64")
    return make(dtype=dtype).surface, np.asarray(ref.receivers), np.asarray(
        ref.lights.endpoint(ref.receivers))


def assert_solution_sane(sol: Solution, dtype):
    # Newton accepts points within 64 eps of the triangle; measured slack: 0 in both dtypes.
    _sane(sol, default_tol(dtype), 1e-5 if dtype == "float32" else 1e-12)


def _angle_error(sol, P, L, ref):
    found = np.asarray(sol.found)
    return refraction_angle_error(ref, np.asarray(sol.triangle)[found],
                                  np.asarray(sol.barycentric)[found], P[found], L[found], ETA)


def _check_planted(scene, dtype, **options):
    p = _planted(scene)
    sol = solve(_mesh(scene, dtype), p.P, p.L, method="newton", **options)
    assert_solution_sane(sol, dtype)
    found = np.asarray(sol.found)
    one_step = options.get("stepping") == "one_step"
    angle_tol, point_tol = (ONE_STEP_ANGLE_TOL, ONE_STEP_POINT_TOL) if one_step else (ANGLE_TOL, POINT_TOL)
    assert np.all(_angle_error(sol, p.P, p.L, _mesh(scene, "float64")) < angle_tol[dtype])
    d = np.linalg.norm(np.asarray(sol.point, np.float64) - p.M, axis=-1)[found]
    assert np.all(d < point_tol[dtype]), d.max()
    return sol


@pytest.mark.parametrize("stepping", ["converge", "one_step"])
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("scene", list(SCENES))
def test_newton_finds_the_planted_point(scene, dtype, stepping):
    sol = _check_planted(scene, dtype, stepping=stepping)
    # Measured: 256/256 on every scene in both dtypes, both steppings.
    assert np.mean(np.asarray(sol.found)) >= 0.99, sol.summary()


def test_one_step_takes_fewer_steps_than_converging_in_every_triangle():
    """MNEE/SMS stepping (one Newton step, then project onto the surface) against optimistix
    converging inside every extended triangle before crossing. Measured on the wavy pool's
    256 planted paths (float64): median 4 steps (max 5) against 10; the one-step points
    stop at |f| <= tol (max distance 3.9e-11 m from the planted point) where the converged
    ones land within 5e-16 m."""
    p = _planted("wavy")
    one = solve(_mesh("wavy", "float64"), p.P, p.L, method="newton", stepping="one_step")
    full = solve(_mesh("wavy", "float64"), p.P, p.L, method="newton")
    assert np.asarray(one.found).all() and np.asarray(full.found).all()
    it1, it8 = np.asarray(one.iterations), np.asarray(full.iterations)
    assert np.median(it1) <= 5 < np.median(it8), (np.median(it1), np.median(it8))
    np.testing.assert_array_equal(np.asarray(one.triangle), np.asarray(full.triangle))


@pytest.mark.parametrize(
    "solver, constraint, dtype",
    [
        ("newton", "angle_difference", "float64"),
        ("newton", "angle_difference", "float32"),
        ("levenberg_marquardt", "half_vector", "float64"),
    ],
)
def test_both_constraints_and_levenberg_marquardt_find_the_planted_point(solver, constraint, dtype):
    """On the irregular lagoon; (newton, half_vector) is the default, tested above."""
    sol = _check_planted("lagoon", dtype, solver=solver, constraint=constraint)
    # Measured: 255/256 with angle_difference (one NOT_CONVERGED) in both dtypes, 256 with LM.
    assert np.mean(np.asarray(sol.found)) >= 0.99, sol.summary()


def test_newton_agrees_with_the_walk_on_the_same_triangle():
    p = _planted("lagoon")
    mesh = _mesh("lagoon", "float64")
    newton = solve(mesh, p.P, p.L, method="newton")
    walk = solve(mesh, p.P, p.L)
    both = np.asarray(newton.found) & np.asarray(walk.found)
    same = both & (np.asarray(newton.triangle) == np.asarray(walk.triangle))
    assert same.mean() > 0.99  # measured: all 256
    d = np.linalg.norm(np.asarray(newton.point) - np.asarray(walk.point), axis=-1)[same]
    # Measured max 4.6e-11 (the walk stops at |f| <= 1e-10; Newton lands within 5e-16).
    assert np.all(d < 5e-10), d.max()


# Found on the steep wave's 256 lanes, measured (float32, float64), and the bound checked:
# converge: 221, 228 (also 20/21 MAX_STEPS, 5/6 TIR, 10/1 NOT_CONVERGED); one_step with
# full steps: 200, 202 (29 MAX_STEPS: it cycles between neighbouring triangles, 7 TIR, 5
# LEFT_MESH, 15/13 NOT_CONVERGED); one_step from Cycles' gentle beta = 0.1: 231 float64
# (19 MAX_STEPS, 3 LEFT_MESH, 3 NOT_CONVERGED).
STEEP = {"converge": ({}, 0.8), "one_step": ({"stepping": "one_step"}, 0.75),
         "one_step_gentle": ({"stepping": "one_step", "initial_step": 0.1}, 0.85)}


@pytest.mark.parametrize("stepping", list(STEEP))
@pytest.mark.parametrize("dtype", DTYPES)
def test_newton_on_steep_waves_never_reports_a_bad_point(dtype, stepping):
    mesh, P, L = _steep(dtype)
    options, bound = STEEP[stepping]
    sol = solve(mesh, P, L, method="newton", **options)
    assert_solution_sane(sol, dtype)
    angle_tol = ONE_STEP_ANGLE_TOL if stepping != "converge" else ANGLE_TOL
    assert np.all(_angle_error(sol, P, L, _steep("float64")[0]) < angle_tol[dtype])
    # The lanes that fail are part of the check (STEEP).
    found = np.asarray(sol.found)
    assert bound <= found.mean() < 1, sol.summary()


def test_several_starts_return_the_found_solution_nearest_m0():
    """Extra starts can only add solutions, and never return one farther from M0."""
    mesh, P, L = _steep("float64")
    one = solve(mesh, P, L, method="newton")
    many = solve(mesh, P, L, method="newton", n_starts=4)
    assert_solution_sane(many, "float64")
    assert np.all(_angle_error(many, P, L, mesh) < ANGLE_TOL["float64"])
    np.testing.assert_array_equal(np.asarray(many.start_point), np.asarray(one.start_point))
    f1, f4 = np.asarray(one.found), np.asarray(many.found)
    assert np.all(f4[f1])  # the first start is M0 itself
    M0 = np.asarray(one.start_point)
    d1 = np.linalg.norm(np.asarray(one.point) - M0, axis=-1)
    d4 = np.linalg.norm(np.asarray(many.point) - M0, axis=-1)
    # Measured max(d4 - d1) = 1.7e-16: the same computation for the first start.
    assert np.all(d4[f1] <= d1[f1] + 1e-12)
    # Measured: the extra starts find 7 more lanes (228 -> 235 of 256) and a solution
    # nearer M0 than the first start's on 6 lanes. Both are 0 if the extra starts are lost.
    assert np.sum(f4 & ~f1) >= 1
    assert np.sum(d4[f1] < d1[f1] - 1e-6) >= 1
    assert f4.mean() >= 0.85, many.summary()


@pytest.mark.parametrize("solver", ["dogleg", "levenberg_marquardt"])
def test_trust_region_solvers_in_float32_with_x64_raise_a_clear_value_error(solver):
    """optimistix 0.1.0 mixes float64 state into a float32 solve when x64 is on."""
    assert jax.config.jax_enable_x64  # tests/conftest.py
    mesh = scenes.flat_pool(64, dtype="float32").surface
    with pytest.raises(ValueError, match=f"{solver}.*float64"):
        solve(mesh, np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, 1.0]]), method="newton",
              solver=solver)


@pytest.mark.parametrize(
    "options, match",
    [
        (dict(bogus=1), "option"),
        (dict(solver="gauss_newton"), "solver"),
        (dict(constraint="specular"), "constraint"),
        (dict(n_starts=0), "n_starts"),
        (dict(inner_steps=0), "inner_steps"),
        (dict(max_patches=0), "max_patches"),
        (dict(stepping="two_steps"), "stepping"),
        (dict(scheduler="fifo"), "scheduler"),
        (dict(stepping="one_step", solver="chord"), "one_step"),
        (dict(stepping="one_step", initial_step=0.0), "initial_step"),
        (dict(stepping="one_step", initial_step=1.5), "initial_step"),
    ],
)
def test_bad_newton_options_raise_value_error_naming_the_problem(options, match):
    mesh = scenes.flat_pool(64, dtype="float64").surface
    with pytest.raises(ValueError, match=match):
        solve(mesh, np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, 1.0]]), method="newton",
              **options)
