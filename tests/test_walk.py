"""The curve walk (seed 001 §3.4) on planted paths, random meshes and crafted cases."""

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax import SurfaceMesh, scenes, solve
from caustics_jax.solvers import Solution, Status, default_tol
from caustics_jax.testing import assert_same_lanes, planted_mesh_paths, planted_paths, refraction_angle_error

DTYPES = ["float32", "float64"]
N_PATHS = 512
# Angle error (rad, float64 reference) of a found point. float64: the 1e-5 bound
# (measured max 1.1e-10, the tol). float32: measured max 1.4e-5 on these scenes (|f| <= 1e-5
# plus rounding of the returned barycentrics); the bound keeps 3.5x margin.
ANGLE_TOL = {"float32": 5e-5, "float64": 1e-5}

SCENES = {
    "flat": lambda dt: scenes.flat_pool(2048, dtype=dt),
    "wavy": lambda dt: scenes.wavy_pool(2048, amplitude=0.05, dtype=dt),
    "wavy_jittered": lambda dt: scenes.wavy_pool(2048, amplitude=0.05, choppiness=0.5, dtype=dt),
    "lagoon": lambda dt: scenes.lagoon(2048, dtype=dt),
}


def assert_solution_sane(sol: Solution, dtype):
    """No NaN/Inf anywhere; found exactly where status is FOUND, with residual within tol."""
    for name in ("point", "barycentric", "residual", "start_point"):
        assert np.all(np.isfinite(np.asarray(getattr(sol, name)))), name
    status = np.asarray(sol.status)
    assert set(np.unique(status)) <= {s.value for s in Status}
    found = np.asarray(sol.found)
    np.testing.assert_array_equal(found, status == Status.FOUND)
    assert np.all(np.abs(np.asarray(sol.residual)[found]) <= default_tol(dtype))
    ab = np.asarray(sol.barycentric)[found]
    slack = 1e-5 if dtype == "float32" else 1e-12
    assert np.all(ab >= -slack) and np.all(ab.sum(-1) <= 1 + slack)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("scene", list(SCENES))
def test_walk_finds_a_valid_solution_for_planted_paths(scene, dtype):
    ref = SCENES[scene]("float64").surface
    mesh = SCENES[scene](dtype).surface
    p = planted_mesh_paths(ref, N_PATHS, seed=7)
    sol = solve(mesh, p.P, p.L)
    assert_solution_sane(sol, dtype)
    found = np.asarray(sol.found)
    err = refraction_angle_error(ref, np.asarray(sol.triangle)[found],
                                 np.asarray(sol.barycentric)[found], p.P[found], p.L[found], 1.333)
    assert np.all(err < ANGLE_TOL[dtype])
    success = found.mean()
    assert success >= 0.995, (scene, dtype, success, sol.summary())


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**31 - 1), amplitude=st.floats(0.0, 0.1),
       choppiness=st.sampled_from([0.0, 0.4]))
def test_walk_on_random_waves_never_reports_a_bad_point(dtype, seed, amplitude, choppiness):
    sc = scenes.wavy_pool(2048, seed=seed, amplitude=amplitude, choppiness=choppiness,
                          n_receivers=16, dtype=dtype)
    rng = np.random.default_rng(seed)
    P = np.asarray(sc.receivers, np.float64)
    L = np.asarray(sc.lights.position[0], np.float64) + rng.normal(0, 0.5, (len(P), 3))
    sol = solve(sc.surface, P, L)
    assert_solution_sane(sol, dtype)
    found = np.asarray(sol.found)
    ref = sc.surface.astype("float64")
    err = refraction_angle_error(ref, np.asarray(sol.triangle)[found],
                                 np.asarray(sol.barycentric)[found], P[found], L[found], 1.333)
    assert np.all(err < ANGLE_TOL[dtype])
    assert found.mean() > 0.9


def _ellipse_cases(n_max=48):
    """Single triangles whose conic is an ellipse inside them, with a planted solution."""
    from caustics_jax.math.conic import conic_coefficients, edge_intersections

    p = planted_paths(5, 4000, normal_spread=1.0)
    coef = conic_coefficients(*(jnp.asarray(x) for x in (p.V, p.N, p.P, p.L)))
    _, valid = edge_intersections(coef)
    g = np.cross(p.V[:, 1] - p.V[:, 0], p.V[:, 2] - p.V[:, 0])
    facing = np.all(np.einsum("nkj,nj->nk", p.N, g) > 0, -1)  # a valid mesh's normals
    idx = np.nonzero(~np.asarray(valid).any(axis=(1, 2)) & facing)[0][:n_max]
    shift = np.zeros((len(idx), 3))
    shift[:, 0] = 20.0 * np.arange(len(idx))  # disjoint triangles: one start point each
    V = p.V[idx] + shift[:, None]
    mesh = SurfaceMesh.from_arrays(V.reshape(-1, 3), np.arange(3 * len(idx)).reshape(-1, 3),
                                   p.N[idx].reshape(-1, 3))
    return mesh, p.P[idx] + shift, p.L[idx] + shift


def test_ellipse_inside_the_first_triangle_is_solved():
    """Seed 001 §3.4.4: no edge crossing at all; the pencil through M0 samples the ellipse."""
    mesh, P, L = _ellipse_cases()
    assert len(P) >= 20
    sol = solve(mesh, P, L)
    assert_solution_sane(sol, "float64")
    status = np.asarray(sol.status)
    assert np.all((status == Status.FOUND) | (status == Status.UNRESOLVED_ELLIPSE))
    assert (status == Status.FOUND).mean() >= 0.9
    found = status == Status.FOUND
    err = refraction_angle_error(mesh, np.asarray(sol.triangle)[found],
                                 np.asarray(sol.barycentric)[found], P[found], L[found], 1.333)
    assert np.all(err < 1e-5)
    # The pool scheduler samples the ellipse only for these lanes (`pools.map_where`); the
    # chunked one for every lane: the same lanes either way.
    chunked = solve(mesh, P, L, scheduler="chunked")
    assert_same_lanes(sol, chunked, ("status", "point", "iterations", "crossed"))


def test_terminal_statuses_are_named_and_explained():
    sc = scenes.wavy_pool(2048, amplitude=0.05, n_receivers=8, dtype="float64")
    P = np.asarray(sc.receivers)
    L_up = np.asarray(sc.lights.endpoint(sc.receivers))
    L_down = P - [0.0, 0.0, 1.0]  # segment never reaches the water
    sol = solve(sc.surface, np.concatenate([P, P]), np.concatenate([L_up, L_down]))
    status = np.asarray(sol.status)
    assert np.all(status[len(P):] == Status.NO_CROSSING)
    assert np.all(np.asarray(sol.triangle)[len(P):] == -1)
    capped = solve(sc.surface, P, L_up, max_steps=1, fallback="none")  # the walk's own status
    assert np.any(np.asarray(capped.status) == Status.MAX_STEPS)
    # With the default Newton fallback the capped lanes are solved by Newton (its own cap).
    rescued = solve(sc.surface, P, L_up, max_steps=1)
    capped_lanes = np.asarray(capped.status) == Status.MAX_STEPS
    assert np.all(np.asarray(rescued.found)[capped_lanes])
    assert "MAX_STEPS" in Status.explain(Status.MAX_STEPS)
    assert sol.summary()["NO_CROSSING"] == len(P)


def test_walk_leaves_a_small_mesh_with_status():
    """Solution beyond a small patch: M0 is inside (and totally internally reflecting for P),
    the refraction point at x = -0.67 is outside the patch's |x| < 0.315."""
    mesh = scenes.flat_pool(2048, half_size=0.3, dtype="float64").surface
    y = np.linspace(-0.2, 0.2, 8)
    P = np.stack([np.full(8, -1.0), y, np.full(8, -0.3)], -1)
    L = np.stack([np.full(8, 1.0), y, np.full(8, 0.3)], -1)
    sol = solve(mesh, P, L)
    assert_solution_sane(sol, "float64")
    assert np.all(np.asarray(sol.status) == Status.LEFT_MESH)


def test_bisection_and_illinois_agree():
    sc = SCENES["wavy"]("float64")
    p = planted_mesh_paths(sc.surface, 256, seed=3)
    a = solve(sc.surface, p.P, p.L, bracket="bisection")
    b = solve(sc.surface, p.P, p.L)
    both = np.asarray(a.found) & np.asarray(b.found)
    assert both.mean() > 0.99
    same_face = np.asarray(a.triangle)[both] == np.asarray(b.triangle)[both]
    d = np.linalg.norm(np.asarray(a.point)[both] - np.asarray(b.point)[both], axis=-1)
    assert np.all(d[same_face] < 1e-7)
    assert np.median(np.asarray(b.iterations)) < np.median(np.asarray(a.iterations))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(P=np.zeros((4, 2)), L=np.ones((4, 3))), "shape"),
        (dict(P=np.full((4, 3), np.nan), L=np.ones((4, 3))), "NaN"),
        (dict(P=np.zeros((4, 3)), L=np.ones((3, 3))), "broadcast"),
        (dict(P=np.zeros((4, 3)), L=np.ones((4, 3)), eta=-1.0), "eta"),
        (dict(P=np.zeros((4, 3)), L=np.ones((4, 3)), method="magic"), "method"),
        (dict(P=np.zeros((4, 3)), L=np.ones((4, 3)), bogus=1), "option"),
        (dict(P=np.zeros((4, 3)), L=np.ones((4, 3)), bracket="regula"), "bracket"),
        (dict(P=np.zeros((4, 3)), L=np.ones((4, 3)), scheduler="fifo"), "scheduler"),
    ],
)
def test_bad_input_raises_value_error_naming_the_problem(kwargs, match):
    mesh = scenes.flat_pool(64, dtype="float64").surface
    with pytest.raises(ValueError, match=match):
        solve(mesh, **kwargs)
    with pytest.raises(ValueError, match="SurfaceMesh"):
        solve("not a mesh", np.zeros((1, 3)), np.ones((1, 3)))


def test_walk_turns_back_when_the_first_direction_fails():
    """Steep waves (slopes near 1): from M0 the walk sometimes heads the wrong way and meets
    total internal reflection, while the exhaustive reference has a solution behind M0.
    Measured on these 512 lanes (exhaustive: every lane has a solution): one-way walk 503
    found, with the turn-back 510; the other two end in TIR with a status."""
    sc = scenes.wavy_pool(2048, seed=1, amplitude=0.1, wavelength=(0.5, 1.2), half_size=1.0,
                          dtype="float64")
    rng = np.random.default_rng(1)
    n = N_PATHS
    P = np.c_[rng.uniform(-0.6, 0.6, (n, 2)), rng.uniform(-1.0, -0.3, n)]
    L = np.c_[rng.uniform(-0.6, 0.6, (n, 2)), rng.uniform(0.5, 1.5, n)]
    sol = solve(sc.surface, P, L)
    assert_solution_sane(sol, "float64")
    found = np.asarray(sol.found)
    status = np.asarray(sol.status)
    assert set(status[~found]) <= {Status.TOTAL_INTERNAL_REFLECTION, Status.LEFT_MESH}
    # found lanes are solutions (residual checked above); the failures are judged by the
    # reference: a failure counts against the walk when a solution exists
    missed = solve(sc.surface, P[~found], L[~found], method="exhaustive").found
    has = found.sum() + np.asarray(missed).sum()
    assert found.sum() >= 0.99 * has, (found.sum(), has)
    # Turn-backs, TIR-onset searches and lanes that refine, walk again and refine: the slot
    # pools (one per branch) give the lanes of the chunked scheduler.
    chunked = solve(sc.surface, P, L, scheduler="chunked")
    assert_same_lanes(sol, chunked, ("status", "point", "iterations", "crossed"))


@pytest.mark.parametrize("depth", [0.1, 0.01])
def test_a_shallow_receiver_finds_the_root_on_an_arc_that_turns_backward(depth):
    """Receivers 0.1 m and 0.01 m under a flat pool, general path: from `M0` one exit of the
    first triangle reads BACKWARD (the refracted ray points away from L, f -0.99) with the
    root between it and the near point (f +0.21). That exit used to end the arc like no
    bracket at all: the walk went the other way into TIR, turned back without a search,
    and walked off the mesh (29 of 32 lanes found at 0.1 m). BACKWARD now opens the onset
    search TIR opens: every lane is found, at the exhaustive reference's point."""
    sc = scenes.flat_pool(512, n_receivers=4, dtype="float64")
    L = np.asarray(sc.lights.position)[0]
    P = np.column_stack([np.random.default_rng(1).uniform(-1.5, 1.5, (32, 2)), np.full(32, -depth)])
    walk = solve(sc.surface, P, L, features=None)
    ref = solve(sc.surface, P, L, method="exhaustive")
    assert np.asarray(ref.found).all() and np.asarray(walk.found).all(), walk.summary()
    np.testing.assert_allclose(np.asarray(walk.point), np.asarray(ref.point), atol=1e-9)


def test_a_shallow_receiver_under_a_wave_finds_the_root_on_a_crossing_into_backward():
    """256 receivers 0.1 m under a gentle wave: lane 8 crosses into the face holding its
    root with f 0.007 at the entry and -0.99 BACKWARD at the exit; lane 254 meets the same
    in its first triangle. The crossing used to walk on through BACKWARD (254 of 256
    found; Newton and the exhaustive reference: 256). Such an arc is now searched as an
    arc into TIR, and without a root the walk goes on as before."""
    sc = scenes.wavy_pool(2048, n_receivers=16, depth=0.1, amplitude=0.03, dtype="float64", receiver_jitter=0.5)
    P, L = np.asarray(sc.receivers), np.asarray(sc.lights.endpoint(sc.receivers))
    walk = solve(sc.surface, P, L)
    assert np.asarray(walk.found).all(), walk.summary()
    lanes = [8, 254]
    ref = solve(sc.surface, P[lanes], L[lanes], method="exhaustive")
    np.testing.assert_allclose(np.asarray(walk.point)[lanes], np.asarray(ref.point), atol=1e-9)


def test_a_first_triangle_arc_out_of_total_internal_reflection_is_searched():
    """512 random lanes on a coarse steep pool (128 faces, amplitude 0.1 m): on 7 lanes `M0`
    is totally reflecting (or BACKWARD) and the root lies in the first triangle between the
    onset of transmission and the exit. Only the arc *into* TIR used to be searched, so
    these lanes walked off the mesh both ways (walk 491 found; on the walk's own curve
    `Trace(seeds="start")` finds 501, the exhaustive reference 507). The arc out of TIR is
    now searched as `_walk_update` searches one (tir_end -1): 498 found, float32 alike."""
    sc = scenes.wavy_pool(128, amplitude=0.1, dtype="float64")
    rng = np.random.default_rng(3)
    n = 512
    P = np.c_[rng.uniform(-1.9, 1.9, (n, 2)), rng.uniform(-1.5, -0.3, n)]
    L = np.c_[rng.uniform(-3, 3, (n, 2)), rng.uniform(0.5, 4, n)]
    lanes = [12, 50, 65, 106, 138, 470, 503]
    for dtype in ("float64", "float32"):
        mesh = sc.surface.astype(dtype)
        sol = solve(mesh, P.astype(dtype), L.astype(dtype))
        assert_solution_sane(sol, dtype)
        found = np.asarray(sol.found)
        assert found.sum() >= 498 and found[lanes].all(), (dtype, sol.summary(), found[lanes])
        err = refraction_angle_error(mesh, np.asarray(sol.triangle)[lanes], np.asarray(sol.barycentric)[lanes],
                                     P[lanes], L[lanes], 1.333)
        assert np.all(err < 10 * default_tol(dtype)), (dtype, err)


@pytest.mark.parametrize("dtype", DTYPES)
def test_segments_through_an_edge_or_a_vertex_are_walked_into_the_neighbour(dtype):
    """`M0` on an edge (a segment `P -> L` through an edge midpoint, or a light straight over
    a grid vertex): the direction that leaves the triangle across that edge used to take the
    next root in pencil order, a re-entry, and walk an arc outside the triangle; and the
    first arc in the neighbour starts on the line PL, where `g`'s sign is undefined
    (`arcs.leaving_at_start`, `_walk_update`'s `from_m0`). 256 segments through edge
    midpoints of `wavy_pool(2048)`: 168 found before, 256 now (float32: 134, 255); a light at
    (0, 0, 3) over the centre vertex with 31 x 31 floor receivers: 917 before, 958 now
    (float32: 910, 958), the exhaustive reference 961. The bounds leave two lanes in
    float32."""
    sc = scenes.wavy_pool(2048, dtype="float64")
    V, F = np.asarray(sc.surface.vertices), np.asarray(sc.surface.faces)
    rng = np.random.default_rng(41)
    fi = rng.choice(np.flatnonzero(np.abs(V[F].mean(1)[:, :2]).max(1) < 1.4), 256)
    off = np.c_[rng.uniform(-0.3, 0.3, (256, 2)), np.ones(256)]
    X = 0.5 * (V[F[fi, 0]] + V[F[fi, 1]])
    g = np.linspace(-1.5, 1.5, 31)
    grid = np.c_[np.repeat(g, 31), np.tile(g, 31), -np.ones(961)]
    P = np.concatenate([X - 0.7 * off, grid])
    L = np.concatenate([X + 1.5 * off, np.broadcast_to([0.0, 0.0, 3.0], (961, 3))])
    mesh = sc.surface.astype(dtype)
    sol = solve(mesh, P.astype(dtype), L.astype(dtype))
    assert_solution_sane(sol, dtype)
    found = np.asarray(sol.found)
    need = (256, 958) if dtype == "float64" else (254, 956)
    assert found[:256].sum() >= need[0] and found[256:].sum() >= need[1], (dtype, found[:256].sum(), found[256:].sum())
