"""Fast subset of the stress suite (experiments/stability.py): adversarial planted paths
from `caustics_jax.testing.stress`, every kernel and the walk and Newton solvers, float32 and
float64: no NaN/Inf for finite input, and no silent failure (a lane reported FOUND whose
residual or refraction-angle error is above what the tolerance allows).

Each category is one batch (64 lanes) on a 2048-triangle pool: one compile per solver and
dtype serves every category.
"""

import functools
import inspect

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import caustics_jax as cj
from caustics_jax import scenes
from caustics_jax.solvers import Status, default_tol
from caustics_jax.testing import oracle, stress

DTYPES = ["float32", "float64"]
CATEGORIES = [c for c in stress.CATEGORIES if c != "large"]
N = 64
# A FOUND lane's angle error (float64 re-evaluation on the data the solver saw) may exceed
# tol only by rounding: |f| <= tol bounds the sine of that angle, up to refract's own
# rounding near the critical angle, `oracle.refraction_rounding_bound`. The stress suite
# measured angle <= tol + 1.3 bound (near_tir, float32 walk, 256 lanes; every other
# category within 1.0x tol); 10x either flags a wrong point.
SILENT_FACTOR = 10.0


# The general solver path, not a scene-feature specialisation (issue 7 part 2, where present).
GENERAL = {"features": None} if "features" in inspect.signature(cj.solve).parameters else {}


@functools.cache
def _case(category):
    return stress.stress_case(category, N, seed=0)


def _silent_and_nonfinite(case, mesh, P, L, sol, tol):
    found = np.asarray(sol.found)
    for name in ("point", "barycentric", "residual", "start_point"):
        assert np.all(np.isfinite(np.asarray(getattr(sol, name)))), name
    np.testing.assert_array_equal(found, np.asarray(sol.status) == Status.FOUND)
    seen = oracle.NumpyMesh.from_mesh(mesh)  # the mesh as the solver saw it, exactly in float64
    angle = oracle.refraction_angle_error(seen, np.asarray(sol.triangle)[found],
                                          np.asarray(sol.barycentric, np.float64)[found],
                                          np.asarray(P, np.float64)[found], np.asarray(L, np.float64)[found],
                                          case.eta)
    residual = np.abs(np.asarray(sol.residual, np.float64))[found]
    bound = oracle.refraction_rounding_bound(seen, np.asarray(sol.triangle)[found],
                                             np.asarray(sol.barycentric, np.float64)[found],
                                             np.asarray(P, np.float64)[found], case.eta, P.dtype)
    return np.nonzero(found)[0][(residual > tol) | (angle > SILENT_FACTOR * (tol + bound))]


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("method", ["walk", "newton"])
def test_solvers_on_adversarial_paths_report_no_nan_and_no_silent_failure(method, dtype):
    with cj.precision(dtype):
        for category in CATEGORIES:
            case = _case(category)
            mesh = case.mesh(dtype)
            P, L = np.asarray(case.P, dtype), np.asarray(case.L, dtype)
            sol = cj.solve(mesh, P, L, method=method, **GENERAL)
            silent = _silent_and_nonfinite(case, mesh, P, L, sol, default_tol(dtype))
            assert silent.size == 0, (category, silent, sol.summary())


@jax.jit
def _kernels(V, N, P, L, ab, I, Ns, cos_i, eta):
    coef = cj.conic_coefficients(V, N, P, L)
    return (cj.refract(I, Ns, eta), cj.fresnel_transmittance(cos_i, 1 / eta), coef,
            cj.conic_tangent(coef, ab), cj.edge_intersections(coef)[0],
            cj.signed_sine(V, N, P, L, ab, eta), cj.signed_sine(V, N, P, L, ab, eta, "plane"),
            cj.ray_differential_D(V, N, P, L, ab, eta)[0])


@pytest.mark.parametrize("dtype", DTYPES)
def test_kernels_on_adversarial_paths_return_no_nan(dtype):
    cases = [_case(c) for c in stress.CATEGORIES if c != "large"]
    V, Nv = (np.concatenate(x) for x in zip(*(c.triangles() for c in cases), strict=True))
    P, L, ab = (np.concatenate([getattr(c, k) for c in cases]) for k in ("P", "L", "ab"))
    M = np.concatenate([c.M for c in cases])
    n_s = oracle.shading_normal(Nv, ab)
    w_P = oracle.unit(P - M)
    with cj.precision(dtype):
        args = [jnp.asarray(x, dtype) for x in (V, Nv, P, L, ab, -w_P, -n_s, np.sum(w_P * n_s, -1))]
        out = _kernels(*args, jnp.asarray(stress.ETA, dtype))
    for name, x in zip(("refract", "fresnel", "conic", "tangent", "edges", "f", "f_plane", "D"), out, strict=True):
        x = np.asarray(x)
        assert x.dtype == np.dtype(dtype), name
        bad = ~np.isfinite(x.reshape(len(x), -1)).all(-1)
        assert not bad.any(), (name, np.nonzero(bad)[0][:10])


@pytest.mark.parametrize("dtype", DTYPES)
def test_walk_accepts_m0_where_the_conic_is_singular_at_the_solution(dtype):
    # A light straight above each receiver of a flat pool: M0 is the solution, and with P,
    # L and the constant normal aligned every point of the plane satisfies eq. 9 (the
    # conic is identically zero). The walk used to call these lanes DEGENERATE.
    with cj.precision(dtype):
        sc = scenes.flat_pool(2048, n_receivers=8, dtype=dtype)
        P = np.asarray(sc.receivers)
        L = P + np.asarray([0.0, 0.0, 3.0], dtype)
        sol = cj.solve(sc.surface, P, L, method="walk", **GENERAL)
    assert np.all(np.asarray(sol.found)), sol.summary()
    np.testing.assert_allclose(np.asarray(sol.point)[:, :2], P[:, :2], atol=1e-6)


@pytest.mark.parametrize("dtype", DTYPES)
def test_walk_finds_roots_next_to_the_onset_of_total_internal_reflection(dtype):
    # Light 0.5-5 degrees above the surface: the solution lies within about 1e-5 m of
    # where light from P starts to be totally reflected, so the arc holding it ends in
    # TIR and shows no sign change of f. Before the walk searched such arcs it found 0
    # of these 52 lanes (every lane with a start point; Newton finds 45).
    case = _case("grazing")
    with cj.precision(dtype):
        mesh = case.mesh(dtype)
        P, L = np.asarray(case.P, dtype), np.asarray(case.L, dtype)
        sol = cj.solve(mesh, P, L, method="walk", **GENERAL)
    crossing = np.asarray(sol.status) != Status.NO_CROSSING
    assert crossing.sum() >= 48
    assert np.asarray(sol.found)[crossing].mean() >= 0.95, sol.summary()


def test_walk_searches_the_first_arc_when_it_runs_into_total_internal_reflection():
    # P 1e-9-1e-6 m below the surface: the root lies within 1e-8 m of M0 and the rest of
    # the first triangle is totally reflecting (w_P nearly horizontal there). The walk used
    # to walk off through TIR and leave the mesh on all 64 lanes; searching the first arc
    # towards the onset brackets the root: 8 lanes FOUND, 27 NOT_CONVERGED (f's rounding,
    # eps |M| / |P - M| ~ 1e-6, is above tol = 1e-10 there), 29 LEFT_MESH (float64).
    case = _case("p_near_surface")
    with cj.precision("float64"):
        sol = cj.solve(case.mesh("float64"), case.P, case.L, method="walk", **GENERAL)
    status = np.asarray(sol.status)
    assert (status == Status.FOUND).sum() >= 4, sol.summary()
    assert (status != Status.LEFT_MESH).sum() >= 24, sol.summary()


@pytest.mark.parametrize("dtype", DTYPES)
def test_walk_refines_a_bracket_on_a_straight_conic_to_the_root(dtype):
    # Solutions on edges and at vertices of the flat pool with the path's plane along grid
    # lines: the conic is a straight line along the tangent, every cut of the bracket has
    # pencil angle 0, and the walk used to stop after one cut as if the bracket had
    # stalled: NOT_CONVERGED on 2 (float32) and 3 (float64) of these 64 lanes. The 4
    # LOST_CURVE lanes are curves running exactly along a mesh edge (docs/stability.md).
    case = _case("vertex_edge_flat")
    with cj.precision(dtype):
        mesh = case.mesh(dtype)
        sol = cj.solve(mesh, np.asarray(case.P, dtype), np.asarray(case.L, dtype), method="walk", **GENERAL)
    status = np.asarray(sol.status)
    assert not np.any(status == Status.NOT_CONVERGED), sol.summary()
    assert np.sum(status == Status.FOUND) >= 60, sol.summary()


@functools.cache
def _exhaustive_vertex_edge():
    case = stress.stress_case("vertex_edge", 32, seed=0)
    with cj.precision("float64"):
        sol = cj.solve(case.mesh("float64"), case.P, case.L, method="exhaustive")
    return np.asarray(sol.found), np.asarray(sol.status)


def test_exhaustive_finds_solutions_on_edges_and_at_vertices():
    # Planted on edges (odd lanes) and at vertices (even lanes) of the wavy pool. f at an
    # arc's end point is rounding noise, so the scan sampled up to that point missed a
    # root exactly there: 12 of these 24 lanes (not at normal incidence) were found.
    found, _ = _exhaustive_vertex_edge()
    oblique = np.arange(32) % 4 != 1
    assert np.all(found[oblique]), np.nonzero(~found & oblique)[0]


def test_exhaustive_finds_m0_when_it_is_a_solution_at_a_singular_point_of_the_conic():
    # Normal incidence at a vertex: P, L and the vertex normal aligned, so M0 is the
    # solution and a singular point of the conic, with no arc through it to scan. The
    # scan alone found none of these 8 lanes.
    found, _ = _exhaustive_vertex_edge()
    normal = np.arange(32) % 4 == 1
    assert np.all(found[normal]), np.nonzero(~found & normal)[0]
