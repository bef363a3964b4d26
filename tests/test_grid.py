"""Regular heightfield grids recognised from arrays in any layout (grid.detect_grid), and the
grid start-point path on them equal to the BVH reference."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from caustics_jax import barycentric_point
from caustics_jax.accel.start_points import start_points
from caustics_jax.surface.grid import detect_grid, grid_layout
from caustics_jax.surface.mesh import GridInfo, SurfaceMesh
from caustics_jax.surface.scenes import lagoon, wavy_pool

NX, NY = 7, 5  # fixed sizes: one compile per dtype for the whole module
DTYPES = [jnp.float32, jnp.float64]


def _grid_arrays(rng, *, y_fastest, sx, sy, up_axis=2, cell=0.3):
    """A heightfield grid as a user might load it: vertices x- or y-fastest, spacing signs
    `sx`, `sy`, a random diagonal per cell, faces counter-clockwise seen from the up axis,
    vertices and faces shuffled. Returns `(vertices, faces)`."""
    i, j = np.meshgrid(np.arange(NX + 1), np.arange(NY + 1), indexing="xy")
    i, j = (i.T.ravel(), j.T.ravel()) if y_fastest else (i.ravel(), j.ravel())
    index = np.empty((NX + 1, NY + 1), np.int64)
    index[i, j] = np.arange(len(i))
    x, y = 1.5 + sx * cell * i, -0.7 + sy * cell * j
    z = 0.05 * np.sin(2.0 * x) * np.cos(1.5 * y) + 0.01 * rng.uniform(-1, 1, len(x))
    V = np.stack([x, y, z], -1)
    faces = []
    for ci in range(NX):
        for cj in range(NY):
            v00, v10 = index[ci, cj], index[ci + 1, cj]
            v01, v11 = index[ci, cj + 1], index[ci + 1, cj + 1]
            pair = [(v00, v10, v11), (v00, v11, v01)] if rng.random() < 0.5 else [(v00, v10, v01), (v10, v11, v01)]
            faces += pair
    F = np.array(faces)
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    flip = np.cross(e1, e2)[:, 2] < 0
    F[flip] = F[flip][:, ::-1]
    perm_v = rng.permutation(len(V))
    F = np.argsort(perm_v)[F][rng.permutation(len(F))]
    V = V[perm_v]
    if up_axis != 2:
        V = V[:, [0, 2, 1]] if up_axis == 1 else V[:, [2, 1, 0]]
        F = F[:, ::-1]  # swapping two axes mirrors the mesh: keep it counter-clockwise
    return V, F


@settings(max_examples=8)
@given(seed=st.integers(0, 2**31 - 1), y_fastest=st.booleans(), sx=st.sampled_from([1, -1]),
       sy=st.sampled_from([1, -1]), up_axis=st.sampled_from([2, 2, 1, 0]))  # fmt: skip
def test_detect_grid_recognises_any_layout_and_its_cells_hold_their_faces(seed, y_fastest, sx, sy, up_axis):
    rng = np.random.default_rng(seed)
    V, F = _grid_arrays(rng, y_fastest=y_fastest, sx=sx, sy=sy, up_axis=up_axis)
    layout = detect_grid(V, F)
    assert layout is not None
    u, v, w = layout.axes
    assert w == up_axis and {u, v, w} == {0, 1, 2}
    assert np.all(np.diff(layout.u_lines) > 0) and np.all(np.diff(layout.v_lines) > 0)
    assert layout.cell_faces.shape[:2] in ((NY, NX), (NX, NY))
    np.testing.assert_array_equal(np.sort(layout.cell_faces.ravel()), np.arange(len(F)))
    # Each cell's two faces lie in it and cover it (their projected areas sum to the cell's).
    nv, nu, _ = layout.cell_faces.shape
    T = V[F[layout.cell_faces]][..., [u, v]]  # (nv, nu, 2, 3, 2)
    jj, ii = np.meshgrid(np.arange(nv), np.arange(nu), indexing="ij")
    lo = np.stack([layout.u_lines[ii], layout.v_lines[jj]], -1)[:, :, None, None]
    hi = np.stack([layout.u_lines[ii + 1], layout.v_lines[jj + 1]], -1)[:, :, None, None]
    assert np.all((T >= lo - 1e-12) & (T <= hi + 1e-12))
    e1, e2 = T[..., 1, :] - T[..., 0, :], T[..., 2, :] - T[..., 0, :]
    area = np.abs(e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]).sum(-1) / 2
    np.testing.assert_allclose(area, np.prod(hi - lo, -1)[:, :, 0, 0], rtol=1e-12)


@pytest.mark.parametrize("dtype", DTYPES)
@settings(max_examples=4)
@given(seed=st.integers(0, 2**31 - 1), y_fastest=st.booleans(), sx=st.sampled_from([1, -1]),
       sy=st.sampled_from([1, -1]))  # fmt: skip
def test_grid_path_on_a_mesh_from_arrays_equals_the_bvh(dtype, seed, y_fastest, sx, sy):
    rng = np.random.default_rng(seed)
    V, F = _grid_arrays(rng, y_fastest=y_fastest, sx=sx, sy=sy)
    mesh = SurfaceMesh.from_arrays(V.astype(dtype), F)
    assert mesh.grid is None
    lo, hi = V.min(0), V.max(0)
    n = 256
    P = np.concatenate([rng.uniform(lo[:2] - 0.2, hi[:2] + 0.2, (n, 2)), rng.uniform(-1, -0.2, (n, 1))], -1)
    L = np.concatenate([rng.uniform(lo[:2] - 1, hi[:2] + 1, (n, 2)), rng.uniform(0.2, 3, (n, 1))], -1)
    # A quarter through grid vertices, vertically: crossings exactly on vertices.
    P[: n // 4, :2] = L[: n // 4, :2] = V[rng.integers(0, len(V), n // 4), :2]
    P, L = P.astype(dtype), L.astype(dtype)
    grid = start_points(mesh, P, L, method="grid")
    bvh = start_points(mesh, P, L, method="general")
    found = np.asarray(grid.found)
    np.testing.assert_array_equal(found, np.asarray(bvh.found))
    assert found[: n // 4].all() and 0.3 < found.mean() < 1
    M_grid = np.asarray(barycentric_point(mesh.triangle(grid.face)[0], grid.barycentric), np.float64)
    M_bvh = np.asarray(barycentric_point(mesh.triangle(bvh.face)[0], bvh.barycentric), np.float64)
    # Measured max difference 0 (same face and barycentrics) on these seeds.
    assert np.max(np.abs(M_grid - M_bvh)[found], initial=0) <= {jnp.float32: 1e-6, jnp.float64: 1e-14}[dtype]


def test_detect_grid_refuses_meshes_that_are_not_grids():
    rng = np.random.default_rng(0)
    V, F = _grid_arrays(rng, y_fastest=False, sx=1, sy=1)
    assert detect_grid(V, F) is not None
    moved = V.copy()
    moved[3, 0] += 0.01  # one vertex off its grid line
    assert detect_grid(moved, F) is None
    assert detect_grid(V, F[2:]) is None  # a cell without its faces (a hole)
    # One cell split into four around its centre: a vertex off the lines.
    centre = V[F[:2]].reshape(-1, 3).mean(0)
    a, b, c = F[0]
    d = next(x for x in F[1] if x not in F[0])
    quad = [a, b, c, d] if np.cross(V[b] - V[a], V[c] - V[a])[2] > 0 else [a, c, b, d]
    k = len(V)
    split = np.concatenate([F[2:], [[quad[0], quad[1], k], [quad[1], quad[2], k], [quad[2], quad[3], k],
                                    [quad[3], quad[0], k]]])  # fmt: skip
    assert detect_grid(np.concatenate([V, centre[None]]), split) is None
    assert detect_grid(np.asarray(lagoon(500, seed=1).surface.vertices),
                       np.asarray(lagoon(500, seed=1).surface.faces)) is None  # fmt: skip
    choppy = wavy_pool(500, seed=1, choppiness=0.5).surface  # grid connectivity, vertices off it
    assert detect_grid(np.asarray(choppy.vertices), np.asarray(choppy.faces)) is None


def test_the_generators_grids_are_recognised_from_their_arrays():
    mesh = wavy_pool(2000, seed=3).surface
    layout = detect_grid(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    ref = grid_layout(mesh.grid)
    np.testing.assert_array_equal(layout.cell_faces, ref.cell_faces)
    np.testing.assert_allclose(layout.u_lines, ref.u_lines, rtol=0, atol=1e-15)
    np.testing.assert_allclose(layout.v_lines, ref.v_lines, rtol=0, atol=1e-15)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("sx, sy", [(-1, 1), (1, -1), (-1, -1)])
def test_heightfields_with_negative_spacing_find_the_crossings(dtype, sx, sy):
    # Issue 14 class 3: with dx < 0 the grid path found nothing where the BVH found the
    # crossings. GridInfo cells are now walked in reverse (grid.grid_layout).
    rng = np.random.default_rng(1)
    H = 0.05 * rng.uniform(-1, 1, (NY + 1, NX + 1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # one negative spacing: normals point down
        mesh = SurfaceMesh.from_heightfield(H, x0=0.5, y0=-0.3, dx=0.2 * sx, dy=0.25 * sy, dtype=dtype)
    assert mesh.grid.dx * sx > 0 and mesh.grid.dy * sy > 0
    layout = grid_layout(mesh.grid)
    assert np.all(np.diff(layout.u_lines) > 0) and np.all(np.diff(layout.v_lines) > 0)
    xy = np.asarray(mesh.vertices)[:, :2]
    n = 128
    P = np.concatenate([rng.uniform(xy.min(0), xy.max(0), (n, 2)), np.full((n, 1), -1.0)], -1)
    L = P + np.concatenate([rng.normal(0, 0.2, (n, 2)), np.full((n, 1), 2.0)], -1)
    P, L = P.astype(dtype), L.astype(dtype)
    grid = start_points(mesh, P, L, method="grid")
    bvh = start_points(mesh, P, L, method="general")
    assert np.asarray(grid.found).mean() > 0.8
    np.testing.assert_array_equal(grid.found, bvh.found)
    np.testing.assert_array_equal(grid.face, bvh.face)


def test_grid_layout_of_gridinfo_matches_its_faces():
    g = GridInfo(nx=3, ny=2, x0=1.0, y0=2.0, dx=-0.5, dy=0.25)
    layout = grid_layout(g)
    np.testing.assert_allclose(layout.u_lines, [-0.5, 0.0, 0.5, 1.0])
    np.testing.assert_allclose(layout.v_lines, [2.0, 2.25, 2.5])
    # Cell (0, 0) of the layout is GridInfo cell (2, 0): faces 4 and 5.
    np.testing.assert_array_equal(layout.cell_faces[0, 0], [4, 5])
    np.testing.assert_array_equal(layout.cell_faces[1, 2], [6, 7])
