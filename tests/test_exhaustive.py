"""The certified all-solutions reference (math.md §5, docs/solvers.md "The certified
reference") on planted paths, steep waves, issue 16's jittered wave, against Newton started
from every face, and with and without its conservative culling.

Its cost is per (lane, face) pair that survives the cone culling, scanned in chunks padded
to 1024 or 4096 pairs (two compiled sizes per kernel).
"""

import functools

import numpy as np
import pytest

from caustics_jax import scenes, solve
from caustics_jax.accel.start_points import start_points
from caustics_jax.solvers import Solution
from caustics_jax.solvers.exhaustive import ExhaustiveSolution
from caustics_jax.testing import assert_solution_sane as _sane
from caustics_jax.testing import jittered_heightfield, oracle, planted_mesh_paths, refraction_angle_error

ETA = 1.333
TOL = 1e-9  # exhaustive's default acceptance |f| <= tol
DEDUPE = 1e-7  # exhaustive's default: solutions closer than this are one
# 32 paths: 2190-2644 (lane, face) pairs per scene at seed 7, one 4096-pair chunk.
N_PATHS = 32
# The bound. Measured max distance of the nearest returned point to the planted M:
# 4.0e-14 (flat excluded: no points), 8.5e-14 on the rim paths.
PLANTED_TOL = 1e-6
# Angle error (rad) at every returned point, from its face and the barycentrics recovered
# from the point (float64 reference). Measured max 3.3e-13 at the real solutions (the
# accepted |f| <= 1e-9 is the bound); pi at the antiparallel points of the steep waves.
ANGLE_TOL = 1e-9
# Distance of a returned point from its face's plane, and barycentric slack: measured max
# 1.1e-16 and 0.
PLANE_TOL = 1e-12

SCENES = {
    "flat": lambda: scenes.flat_pool(2048, dtype="float64"),
    "wavy": lambda: scenes.wavy_pool(2048, amplitude=0.05, dtype="float64"),
    "wavy_jittered": lambda: scenes.wavy_pool(2048, amplitude=0.05, choppiness=0.5,
                                              dtype="float64"),
    "lagoon": lambda: scenes.lagoon(2048, dtype="float64"),
}


@functools.cache
def _mesh(scene):
    if scene == "steep":
        # One steep short wave (slope 1.05): caustics on the floor, several refraction points
        # per path.
        return scenes.wavy_pool(2048, amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6),
                                dtype="float64").surface
    return SCENES[scene]().surface


def assert_solution_sane(sol: Solution, tol=TOL):
    _sane(sol, tol, PLANE_TOL)


def _barycentric(mesh, tri, M):
    """`(a, b)` of points `M` in faces `tri` (least squares, numpy) and the distance off the plane."""
    V = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[tri]]
    E = np.stack([V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]], -1)  # (k, 3, 2)
    r = M - V[:, 0]
    rhs = np.einsum("kij,ki->kj", E, r)[..., None]
    ab = np.linalg.solve(np.einsum("kij,kil->kjl", E, E), rhs)[..., 0]
    off = np.linalg.norm(np.einsum("kij,kj->ki", E, ab) - r, axis=-1)
    return ab, off


def assert_all_points_are_distinct_solutions(mesh, ex: ExhaustiveSolution, P, L):
    n, width = ex.count.shape[0], ex.all_points.shape[1]
    assert ex.all_points.shape == (n, width, 3) and ex.all_triangles.shape == (n, width)
    valid = np.arange(width)[None] < ex.count[:, None]
    assert np.all(ex.all_triangles[~valid] == -1) and np.all(ex.all_points[~valid] == 0)
    tri = ex.all_triangles[valid]
    assert np.all((tri >= 0) & (tri < mesh.faces.shape[0]))
    lane = np.nonzero(valid)[0]
    ab, off = _barycentric(mesh, tri, ex.all_points[valid])
    assert np.all(off < PLANE_TOL), off.max()
    assert np.all(oracle.inside_triangle(ab, PLANE_TOL))
    err = refraction_angle_error(mesh, tri, ab, P[lane], L[lane], ETA)
    assert np.all(err < ANGLE_TOL), err.max()
    for i in np.nonzero(ex.count > 1)[0]:
        pts = ex.all_points[i, : ex.count[i]]
        d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
        assert np.all(d[~np.eye(len(pts), dtype=bool)] > DEDUPE), (i, d)


def assert_contains(ex: ExhaustiveSolution, M):
    """Each lane's `M` is within PLANTED_TOL of one of its `count` returned points."""
    valid = np.arange(ex.all_points.shape[1])[None] < ex.count[:, None]
    d = np.where(valid, np.linalg.norm(ex.all_points - M[:, None], axis=-1), np.inf).min(1)
    assert np.all(d < PLANTED_TOL), (np.sum(d >= PLANTED_TOL), d.max())


def assert_solution_is_the_one_nearest_m0(ex: ExhaustiveSolution):
    sol = ex.solution
    assert_solution_sane(sol)
    found = np.asarray(sol.found)
    np.testing.assert_array_equal(found, ex.count > 0)
    valid = np.arange(ex.all_points.shape[1])[None] < ex.count[:, None]
    M0 = np.asarray(sol.start_point)
    d = np.where(valid, np.linalg.norm(ex.all_points - M0[:, None], axis=-1), np.inf)
    best = np.argmin(d, axis=1)[found]
    idx = np.nonzero(found)[0]
    np.testing.assert_array_equal(np.asarray(sol.point)[found], ex.all_points[idx, best])
    np.testing.assert_array_equal(np.asarray(sol.triangle)[found], ex.all_triangles[idx, best])
    np.testing.assert_array_equal(np.asarray(sol.triangle)[~found], -1)


@pytest.mark.parametrize("scene", list(SCENES))
def test_exhaustive_contains_the_planted_point_and_only_solutions(scene):
    mesh = _mesh(scene)
    p = planted_mesh_paths(mesh, N_PATHS, seed=7)
    ex = solve(mesh, p.P, p.L, method="exhaustive", return_all=True)
    assert isinstance(ex, ExhaustiveSolution)
    assert_contains(ex, p.M)
    assert_all_points_are_distinct_solutions(mesh, ex, p.P, p.L)
    assert_solution_is_the_one_nearest_m0(ex)


@functools.cache
def _steep_paths():
    """7 of planted_mesh_paths(steep, 40, seed=7) with several solutions, and their
    exhaustive result: 2400 (lane, face) pairs, one 4096-pair chunk."""
    mesh = _mesh("steep")
    p = planted_mesh_paths(mesh, 40, seed=7)
    lanes = [3, 4, 9, 12, 13, 15, 17]
    P, L, M = p.P[lanes], p.L[lanes], p.M[lanes]
    return P, L, M, solve(mesh, P, L, method="exhaustive", return_all=True)


def test_exhaustive_finds_several_distinct_solutions_on_steep_waves():
    """The planted point is among several solutions; all are real and distinct."""
    mesh = _mesh("steep")
    P, L, M, ex = _steep_paths()
    # Measured numbers of real solutions (Newton started in every face): 3, 1, 3, 3, 3, 3, 3.
    assert np.sum(ex.count > 1) >= 4, ex.count
    assert_contains(ex, M)
    assert_all_points_are_distinct_solutions(mesh, ex, P, L)
    assert_solution_is_the_one_nearest_m0(ex)
    sol = solve(mesh, P, L, method="exhaustive")  # return_all=False: the same nearest solution
    assert isinstance(sol, Solution)
    for name in ("point", "triangle", "barycentric", "found", "status", "residual"):
        np.testing.assert_array_equal(np.asarray(getattr(sol, name)),
                                      np.asarray(getattr(ex.solution, name)), err_msg=name)


def test_exhaustive_contains_every_solution_newton_finds_from_any_face():
    """Completeness against an independent search: Newton started at the centroid of every
    face (2048 starts per path) on three of the steep-wave paths."""
    mesh = _mesh("steep")
    P, L, _, ex = _steep_paths()
    lanes = [2, 3, 4]
    F, n = mesh.faces.shape[0], len(lanes)
    start = (np.tile(np.arange(F, dtype=np.int32), n), np.full((n * F, 2), 1 / 3),
             np.ones(n * F, bool))
    newton = solve(mesh, np.repeat(P[lanes], F, 0), np.repeat(L[lanes], F, 0), method="newton",
                   start=start)
    found = np.asarray(newton.found).reshape(n, F)
    points = np.asarray(newton.point).reshape(n, F, 3)
    for i, lane in enumerate(lanes):
        distinct = []
        for q in points[i, found[i]]:
            if all(np.linalg.norm(q - r) > DEDUPE for r in distinct):
                distinct.append(q)
        assert len(distinct) == 3  # measured
        mine = ex.all_points[lane, : ex.count[lane]]
        d = np.linalg.norm(np.asarray(distinct)[:, None] - mine[None], axis=-1).min(1)
        # Measured: Newton's solutions are exhaustive ones to 7.0e-16. One on lane 2 lies
        # between the last sample of its arc and the onset of total internal reflection
        # (refracting at 48.55 deg): the scan missed it until it bracketed at the onset.
        assert np.all(d < PLANTED_TOL), (lane, np.asarray(distinct)[d >= PLANTED_TOL])


def test_exhaustive_reports_lanes_without_a_start_point_consistently():
    """Paths planted at the rim whose segment P -> L leaves the mesh without crossing it
    (no M0: the walk and Newton report NO_CROSSING) still have their planted solution; the
    result must keep `found == (status == FOUND)` whichever way it reports them."""
    mesh = _mesh("wavy")
    rim = planted_mesh_paths(mesh, 1000, seed=2, margin=0.0, height=(2.0, 4.0))
    _, _, crossing = start_points(mesh, rim.P, rim.L)
    out = ~np.asarray(crossing)
    assert out.sum() >= 20  # measured 31 of 1000
    inner = planted_mesh_paths(mesh, N_PATHS, seed=7)
    # 31 rim lanes (2002 pairs) and 16 inner lanes (1342 pairs): one 4096-pair chunk.
    P = np.concatenate([rim.P[out], inner.P[:16]])
    L = np.concatenate([rim.L[out], inner.L[:16]])
    M = np.concatenate([rim.M[out], inner.M[:16]])
    ex = solve(mesh, P, L, method="exhaustive", return_all=True)
    assert_contains(ex, M)
    assert_all_points_are_distinct_solutions(mesh, ex, P, L)
    assert_solution_sane(ex.solution)


@pytest.mark.parametrize(
    "options, match",
    [
        (dict(bogus=1), "option"),
        (dict(samples=32), "samples"),  # the sampled scan's option: gone with the sampling
        (dict(iters=0), "iters"),
        (dict(max_depth=4), "max_depth"),
        (dict(cull="yes"), "cull"),
    ],
)
def test_bad_exhaustive_options_raise_value_error_naming_the_problem(options, match):
    mesh = scenes.flat_pool(64, dtype="float64").surface
    with pytest.raises(ValueError, match=match):
        solve(mesh, np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, 1.0]]),
              method="exhaustive", **options)


def test_exhaustive_on_a_float32_mesh_raises_value_error():
    mesh = scenes.flat_pool(64, dtype="float32").surface
    with pytest.raises(ValueError, match="float64"):
        solve(mesh, np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, 1.0]]),
              method="exhaustive")


@pytest.mark.parametrize("seed, normals", [(1, "computed"), (2, "computed"), (2, "analytic")])
def test_certified_reference_finds_every_planted_path_on_the_jittered_wave(seed, normals):
    """Issue 16's surface: 12 x 12 cells, vertices jittered by 30% of a cell, waves of 5 cm,
    300 planted paths. The sampled scan (32 samples per arc) lost one path in each of these
    three cases, all well inside their triangle: the start point M0 lay in the same sample
    interval as the root, so the "line" orientation of f flipped twice there (at M0 and at
    the root) and the interval was not bracketed. The certified reference finds all."""
    mesh = jittered_heightfield(12, seed=seed, normals=normals)
    p = planted_mesh_paths(mesh, 300, seed=seed)
    ex = solve(mesh, p.P, p.L, method="exhaustive", return_all=True)
    assert_contains(ex, p.M)
    assert_all_points_are_distinct_solutions(mesh, ex, p.P, p.L)


SMALL = {
    "flat": lambda: scenes.flat_pool(512, dtype="float64").surface,
    "wavy": lambda: scenes.wavy_pool(512, amplitude=0.05, dtype="float64").surface,
    "steep": lambda: scenes.wavy_pool(512, amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6),
                                      dtype="float64").surface,
    "jittered": lambda: jittered_heightfield(12, seed=1),
    "lagoon": lambda: scenes.lagoon(512, dtype="float64").surface,
}


@pytest.mark.parametrize("scene", list(SMALL))
def test_certified_reference_equals_newton_started_from_every_face(scene):
    """Completeness against an independent search, on every scene type: Newton (half-vector)
    started at the centroid of every face, for 4 planted paths (receivers down to 1.5 m:
    several paths on the steep wave). Every forward solution Newton finds is a reference
    solution, and the planted one is too; culling off changes nothing."""
    mesh = SMALL[scene]()
    p = planted_mesh_paths(mesh, 4, seed=3, depth=(0.5, 1.5))
    ex = solve(mesh, p.P, p.L, method="exhaustive", return_all=True)
    assert_contains(ex, p.M)
    assert_all_points_are_distinct_solutions(mesh, ex, p.P, p.L)
    F, n = mesh.faces.shape[0], len(p.P)
    start = (np.tile(np.arange(F, dtype=np.int32), n), np.full((n * F, 2), 1 / 3), np.ones(n * F, bool))
    newton = solve(mesh, np.repeat(p.P, F, 0), np.repeat(p.L, F, 0), method="newton", start=start)
    found = np.asarray(newton.found)
    lane = np.repeat(np.arange(n), F)[found]
    err = refraction_angle_error(mesh, np.asarray(newton.triangle)[found], np.asarray(newton.barycentric)[found],
                                 p.P[lane], p.L[lane], ETA)
    forward = err < 1e-6  # Newton's constraint also vanishes on backward rays (angle pi)
    pts = np.asarray(newton.point)[found][forward]
    lane = lane[forward]
    valid = np.arange(ex.all_points.shape[1])[None] < ex.count[:, None]
    d = np.where(valid[lane], np.linalg.norm(ex.all_points[lane] - pts[:, None], axis=-1), np.inf).min(1)
    assert np.all(d < PLANTED_TOL), (scene, d.max(), pts[d >= PLANTED_TOL])
    nocull = solve(mesh, p.P, p.L, method="exhaustive", return_all=True, cull=False)
    np.testing.assert_array_equal(nocull.count, ex.count)
    for i in range(n):
        a, b = ex.all_points[i, : ex.count[i]], nocull.all_points[i, : nocull.count[i]]
        if len(a):
            assert np.linalg.norm(a[:, None] - b[None], axis=-1).min(1).max() < 1e-12


def test_certified_reference_finds_every_path_of_a_receiver_under_the_light():
    """Receiver 15 of the small steep pool's 6 x 6 grid lies straight under the point light
    (`PL` vertical): with one wave every vertex normal lies in the vertical plane of the
    wave's direction, which holds `PL`, so the conic of every face is a pair of lines
    (`arc_roots.chord_on_conic`). The reference lost the path on face 183, whose arc lies on
    one of them, until such arcs became segments: it must equal the paths Newton finds
    started at the centroid of every face (3, measured)."""
    sc = scenes.wavy_pool(512, half_size=0.6, amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6), n_receivers=6,
                          depth=1.0, light_position=(0.1, -0.1, 3.0), dtype="float64")
    mesh = sc.surface
    P = np.asarray(sc.receivers)[[15]]
    L = np.asarray(sc.lights.endpoint(P))
    ex = solve(mesh, P, L, method="exhaustive", return_all=True, cull=False)
    assert_all_points_are_distinct_solutions(mesh, ex, P, L)
    F = mesh.faces.shape[0]
    start = (np.arange(F, dtype=np.int32), np.full((F, 2), 1 / 3), np.ones(F, bool))
    newton = solve(mesh, np.repeat(P, F, 0), np.repeat(L, F, 0), method="newton", start=start)
    found = np.asarray(newton.found)
    err = refraction_angle_error(mesh, np.asarray(newton.triangle)[found], np.asarray(newton.barycentric)[found],
                                 np.repeat(P, found.sum(), 0), np.repeat(L, found.sum(), 0), ETA)
    distinct: list[np.ndarray] = []
    for q in np.asarray(newton.point)[found][err < 1e-6]:  # forward rays only
        if all(np.linalg.norm(q - r) > DEDUPE for r in distinct):
            distinct.append(q)
    assert len(distinct) == 3 and ex.count[0] == 3, (distinct, ex.all_points)
    d = np.linalg.norm(np.asarray(distinct)[:, None] - ex.all_points[0][None], axis=-1).min(1)
    assert np.all(d < PLANTED_TOL), d  # measured


def test_a_receiver_mirrored_above_the_water_has_no_path():
    """Mirroring `P` across the shading plane at a planted `M` leaves `refract(-w_P, -n_s)`
    unchanged (only the normal component of `w_P` flips, and refract keeps the tangential
    one): `f` vanishes at `M` again, with `P` above the water. The reference and the tracer
    had returned that point FOUND; `bracket_objective` now calls it BACKWARD (`P` beyond the
    plane at `M`), so no lane is FOUND, as the walk and Newton answer (NO_CROSSING: the
    segment P -> L does not cross the surface)."""
    mesh = _mesh("wavy")
    p = planted_mesh_paths(mesh, 16, seed=7)
    n_s = oracle.shading_normal(np.asarray(mesh.normals)[np.asarray(mesh.faces)[p.face]], p.ab)
    up = p.P - 2 * np.sum((p.P - p.M) * n_s, -1, keepdims=True) * n_s
    assert np.all(up[:, 2] > 0.15)  # above every crest (amplitude 0.05)
    def above():  # a setup mistake, named
        return pytest.warns(UserWarning, match="the receivers are above the surface")

    for kw in ({"method": "exhaustive", "return_all": True}, {"method": "walk", "solutions": "all"}):
        with above():
            res = solve(mesh, up, p.L, **kw)
        status = np.asarray(res.solution.status)
        assert not np.any(np.asarray(res.solution.found)) and np.all(np.asarray(res.count) == 0), kw
        assert np.all((status == 1) | (status == 9)), (kw, status)  # NO_CROSSING / NO_SOLUTION
    with above():
        assert not np.any(np.asarray(solve(mesh, up, p.L, method="walk").found))
    # Started on the mirrored point itself, Newton (which accepts with the same status) had
    # converged there: FOUND 16 of 16 in both steppings.
    start = (np.asarray(p.face, np.int32), np.asarray(p.ab), np.ones(len(up), bool))
    for kw in ({"method": "walk"}, {"method": "newton"}, {"method": "newton", "stepping": "one_step"}):
        assert not np.any(np.asarray(solve(mesh, up, p.L, start=start, **kw).found)), kw
