"""Properties of SurfaceMesh: adjacency, edge crossing, normals, validation, pytree use."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax import barycentric_point
from caustics_jax.surface.mesh import GridInfo, SurfaceMesh, cross_edge
from caustics_jax.surface.scenes import flat_pool, lagoon, wavy_pool

DTYPES = [jnp.float32, jnp.float64]
# |world point before - after| / scene size for cross_edge on the wavy pool and lagoon,
# 2000 crossings per example. Measured maxima over the ci examples: float32 5.7e-8,
# float64 1.1e-16 (both faces store the same vertices, so only barycentric_point's
# rounding remains). Bounds keep >= 15x margin.
TRANSFER_TOL = {jnp.float32: 1e-6, jnp.float64: 4e-15}


def _generator_meshes():
    return {
        "flat_pool": flat_pool(200).surface,
        "wavy_pool": wavy_pool(300, seed=3).surface,
        "wavy_pool_choppy": wavy_pool(300, seed=4, choppiness=0.6).surface,
        "lagoon": lagoon(300, seed=5).surface,
    }


MESHES = _generator_meshes()


def _obj_roundtrip(tmp_path, mesh):
    path = tmp_path / "surface.obj"
    trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False).export(path)
    return SurfaceMesh.from_trimesh(trimesh.load(path, force="mesh"))


def _assert_adjacency_symmetric_and_correct(mesh):
    F = np.asarray(mesh.faces)
    nb, ne = np.asarray(mesh.neighbors), np.asarray(mesh.neighbor_edge)
    f, k = np.nonzero(nb >= 0)
    g, m = nb[f, k], ne[f, k]
    # Symmetric: the neighbour's neighbour across the shared edge is the face itself.
    np.testing.assert_array_equal(nb[g, m], f)
    np.testing.assert_array_equal(ne[g, m], k)
    # Correct: the shared edge has the same two vertices, in opposite order.
    np.testing.assert_array_equal(F[f, k], F[g, (m + 1) % 3])
    np.testing.assert_array_equal(F[f, (k + 1) % 3], F[g, m])
    # Boundary edges (-1) are used by exactly one face: compare with an edge census.
    lo = np.minimum(F, F[:, [1, 2, 0]])
    hi = np.maximum(F, F[:, [1, 2, 0]])
    keys, counts = np.unique(lo * len(mesh.vertices) + hi, return_counts=True)
    count_of = dict(zip(keys.tolist(), counts.tolist(), strict=True))
    boundary = (lo * len(mesh.vertices) + hi)[nb < 0]
    assert all(count_of[b] == 1 for b in boundary.tolist())
    assert np.all(ne[nb < 0] == -1)
    assert np.sum(nb >= 0) + len(boundary) == 3 * len(F)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_adjacency_is_symmetric_and_matches_shared_vertices_on_generators(name):
    _assert_adjacency_symmetric_and_correct(MESHES[name])


def test_adjacency_is_symmetric_after_writing_and_reloading_obj_ply_stl_glb(tmp_path):
    mesh = _obj_roundtrip(tmp_path, MESHES["lagoon"])
    assert mesh.faces.shape == MESHES["lagoon"].faces.shape
    _assert_adjacency_symmetric_and_correct(mesh)
    # Closed meshes from PLY, STL (one vertex copy per face: trimesh merges them) and GLB
    # (a trimesh.Scene): every edge interior, no boundary.
    for ext in ("ply", "stl", "glb"):
        path = tmp_path / f"ball.{ext}"
        trimesh.creation.icosphere(subdivisions=2).export(path)
        ball = SurfaceMesh.from_trimesh(trimesh.load(path))
        assert ball.faces.shape == (320, 3)
        _assert_adjacency_symmetric_and_correct(ball)
        assert np.all(np.asarray(ball.neighbors) >= 0)
    # Outward on a sphere: the vertex normal is the radial direction.
    V = np.asarray(ball.vertices)
    np.testing.assert_allclose(
        np.asarray(ball.normals), V / np.linalg.norm(V, axis=-1, keepdims=True), atol=0.05
    )


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**31 - 1))
def test_cross_edge_transfers_the_same_world_point_and_back(dtype, seed):
    rng = np.random.default_rng(seed)
    name = ["wavy_pool", "lagoon", "wavy_pool_choppy"][seed % 3]
    mesh = MESHES[name].astype(dtype)
    n = 2000
    face = jnp.asarray(rng.integers(0, mesh.faces.shape[0], n), jnp.int32)
    edge = jnp.asarray(rng.integers(0, 3, n), jnp.int32)
    t = jnp.asarray(rng.uniform(0, 1, n), dtype)
    g, m, t_next, ab_next = jax.jit(cross_edge)(mesh, face, edge, t)
    assert t_next.dtype == dtype and ab_next.dtype == dtype
    from caustics_jax.math.barycentric import edge_barycentric

    V, _ = mesh.triangle(face)
    before = barycentric_point(V, edge_barycentric(edge, t))
    crossed = np.asarray(g >= 0)
    assert crossed.mean() > 0.8  # most edges are interior
    Vg, _ = mesh.triangle(g)
    after = barycentric_point(Vg, ab_next)
    err = np.max(np.abs(np.asarray(before - after))[crossed])
    assert err <= TRANSFER_TOL[dtype] * 4.2
    # The entry barycentrics lie on the neighbour's entry edge at the returned parameter.
    on_entry_edge = np.asarray(edge_barycentric(m, t_next))
    np.testing.assert_array_equal(np.asarray(ab_next)[crossed], on_entry_edge[crossed])
    # Crossing back returns to the start face, edge and parameter.
    f2, k2, t2, _ = cross_edge(mesh, g, m, t_next)
    np.testing.assert_array_equal(np.asarray(f2)[crossed], np.asarray(face)[crossed])
    np.testing.assert_array_equal(np.asarray(k2)[crossed], np.asarray(edge)[crossed])
    np.testing.assert_allclose(
        np.asarray(t2)[crossed], np.asarray(t)[crossed], atol=4 * float(jnp.finfo(dtype).eps)
    )
    # Boundary: -1, and the exit point returned unchanged.
    assert np.all(np.asarray(m)[~crossed] == -1)
    np.testing.assert_array_equal(np.asarray(t_next)[~crossed], np.asarray(t)[~crossed])


def test_cross_edge_from_invalid_face_stays_invalid_and_finite():
    mesh = MESHES["wavy_pool"]
    g, m, t, ab = cross_edge(mesh, jnp.array([-1, -1]), jnp.array([0, 2]), jnp.array([0.3, 0.7]))
    assert np.all(np.asarray(g) == -1) and np.all(np.asarray(m) == -1)
    assert np.all(np.isfinite(np.asarray(ab)))


def test_angle_weighted_normals_ignore_tessellation_but_area_weighted_do_not():
    # Corner of a cube: three quarter planes meeting at the origin at right angles, the
    # y = 0 one cut to a half (one triangle). Equal corner angles give the symmetric
    # (1, 1, 1)/sqrt 3 whatever the areas; area weights tilt it away from the small face.
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1]], float)
    Fc = np.array([[0, 2, 4], [0, 4, 1], [0, 1, 3], [0, 3, 5], [0, 5, 2]])
    # Outward for the corner seen from outside the cube's octant: normals -x, -y, -z.
    mesh_angle = SurfaceMesh.from_arrays(V, Fc, normal_weighting="angle")
    mesh_area = SurfaceMesh.from_arrays(V, Fc, normal_weighting="area")
    np.testing.assert_allclose(mesh_angle.normals[0], -np.ones(3) / np.sqrt(3), atol=1e-12)
    assert np.max(np.abs(mesh_area.normals[0] + np.ones(3) / np.sqrt(3))) > 0.01
    np.testing.assert_allclose(np.linalg.norm(mesh_area.normals, axis=-1), 1, atol=1e-12)


def test_face_normals_are_unit_and_follow_winding_and_vertex_normals_point_outward():
    for mesh in MESHES.values():
        n = np.asarray(mesh.face_normals)
        np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1, atol=1e-12)
        assert np.all(n[:, 2] > 0.9)  # +z: toward the light
        assert np.all(np.asarray(mesh.normals)[:, 2] > 0.9)


@pytest.mark.parametrize("dtype", DTYPES)
def test_mesh_is_a_pytree_usable_in_jit_and_astype_keeps_dtype(dtype):
    mesh = MESHES["wavy_pool"].astype(dtype)
    assert mesh.vertices.dtype == dtype and mesh.normals.dtype == dtype
    assert mesh.face_normals.dtype == dtype and mesh.faces.dtype == jnp.int32
    assert mesh.grid == MESHES["wavy_pool"].grid

    @jax.jit
    def centroid_normal(m, f):
        V, N = m.triangle(f)
        return V.mean(-2), N.mean(-2)

    f = jnp.arange(12).reshape(3, 4)
    c, n = centroid_normal(mesh, f)
    assert c.shape == (3, 4, 3) and c.dtype == dtype and n.dtype == dtype
    F = np.asarray(mesh.faces)[np.asarray(f)]
    np.testing.assert_allclose(c, np.asarray(mesh.vertices)[F].mean(-2), rtol=1e-6)


def test_from_arrays_keeps_float32_input_float32():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    mesh = SurfaceMesh.from_arrays(V, [[0, 1, 2]])
    assert mesh.vertices.dtype == jnp.float32 and mesh.normals.dtype == jnp.float32
    np.testing.assert_array_equal(mesh.neighbors, [[-1, -1, -1]])


def test_grid_layout_matches_from_heightfield_and_cell_faces():
    mesh = MESHES["wavy_pool"]
    g = mesh.grid
    assert isinstance(g, GridInfo) and 2 * g.nx * g.ny == mesh.faces.shape[0]
    i, j = 3, 5
    lower, upper = g.cell_faces(i, j)
    V = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[[lower, upper]]]
    x, y = g.x0 + i * g.dx, g.y0 + j * g.dy
    assert np.all((V[..., 0] >= x - 1e-12) & (V[..., 0] <= x + g.dx + 1e-12))
    assert np.all((V[..., 1] >= y - 1e-12) & (V[..., 1] <= y + g.dy + 1e-12))


# --------------------------------------------------------------------------- validation

_SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
_SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])


def _up_except(vertex, value):
    N = np.tile([0.0, 0.0, 1.0], (4, 1))
    N[vertex] = value
    return N


BAD_MESHES = {
    "nan vertex": (np.where([[0], [0], [1], [0]], np.nan, _SQUARE_V), _SQUARE_F, None,
                   r"NaN or Inf coordinates: vertices \[2\]"),
    "inf vertex": (np.where([[0], [1], [0], [0]], np.inf, _SQUARE_V), _SQUARE_F, None,
                   r"NaN or Inf coordinates: vertices \[1\]"),
    "index out of range": (_SQUARE_V, np.array([[0, 1, 2], [0, 2, 4]]), None,
                           r"out of range \[0, 4\): faces \[1\]"),
    "negative index": (_SQUARE_V, np.array([[0, 1, -1], [0, 2, 3]]), None,
                       r"out of range \[0, 4\): faces \[0\]"),
    "repeated index": (_SQUARE_V, np.array([[0, 1, 2], [0, 3, 3]]), None,
                       r"repeated vertex index\): faces \[1\]"),
    "zero area": (np.vstack([_SQUARE_V, [[2, 2, 0]]]), np.array([[0, 1, 2], [0, 2, 4]]), None,
                  r"zero area\): faces \[1\]"),
    "non-manifold edge": (np.vstack([_SQUARE_V, [[0.5, 0.5, 1]]]),
                          np.array([[0, 1, 2], [0, 2, 3], [2, 0, 4]]), None,
                          r"non-manifold edges .*vertex pairs \[\(0, 2\)\].*faces \[0, 1, 2\]"),
    "inconsistent winding": (_SQUARE_V, np.array([[0, 1, 2], [0, 3, 2]]), None,
                             r"inconsistent winding.*faces \[0, 1\]"),
    "zero normal": (_SQUARE_V, _SQUARE_F, _up_except(1, [0, 0, 0]),
                    r"given normals are zero: vertices \[1\]"),
    "nan normal": (_SQUARE_V, _SQUARE_F, _up_except(3, [0, np.nan, 1]),
                   r"given normals contain NaN or Inf: vertices \[3\]"),
    "flipped normal": (_SQUARE_V, _SQUARE_F, _up_except(2, [0, 0, -1]),
                       r"against the face winding at vertices \[2\]"),
    "unreferenced vertex": (np.vstack([_SQUARE_V, [[5, 5, 5]]]), _SQUARE_F, None,
                            r"computed normals are zero.*vertices \[4\]"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_MESHES))
def test_each_validation_error_names_what_is_wrong(case):
    V, F, N, message = BAD_MESHES[case]
    with pytest.raises(ValueError, match=message):
        SurfaceMesh.from_arrays(V, F, N)


def test_the_unbroken_square_is_accepted():
    mesh = SurfaceMesh.from_arrays(_SQUARE_V, _SQUARE_F)
    np.testing.assert_array_equal(mesh.neighbors, [[-1, -1, 1], [0, -1, -1]])
    np.testing.assert_array_equal(mesh.neighbor_edge, [[-1, -1, 0], [2, -1, -1]])


def test_shape_errors_and_bad_grid_are_rejected():
    with pytest.raises(ValueError, match=r"vertices must have shape \(V, 3\)"):
        SurfaceMesh.from_arrays(np.zeros((4, 2)), _SQUARE_F)
    with pytest.raises(ValueError, match=r"faces must have shape \(F, 3\)"):
        SurfaceMesh.from_arrays(_SQUARE_V, np.zeros((0, 3), int))
    with pytest.raises(ValueError, match="integer"):
        SurfaceMesh.from_arrays(_SQUARE_V, _SQUARE_F.astype(float))
    with pytest.raises(ValueError, match="heights contain NaN or Inf at vertices \\[3\\]"):
        SurfaceMesh.from_heightfield([[0, 0], [0, np.nan]], x0=0, y0=0, dx=1, dy=1)
    grid = GridInfo(nx=1, ny=1, x0=0.0, y0=0.0, dx=1.0, dy=1.0)
    flat = np.concatenate([grid.vertex_xy(), np.zeros((4, 1))], -1)
    SurfaceMesh.from_arrays(flat, grid.faces(), grid=grid)  # on the grid: accepted
    bent = flat.copy()
    bent[3, 0] += 0.1
    with pytest.raises(ValueError, match=r"off the regular grid xy positions: vertices \[3\]"):
        SurfaceMesh.from_arrays(bent, grid.faces(), grid=grid)


# --------------------------------------------------------------------------- input contract
# (docs/input_contract.md "Meshes")


@pytest.mark.parametrize("kwargs, match", [
    (dict(vertices=_SQUARE_V * 1e39, dtype="float32"), r"vertices overflow float32.*vertices \[1, 2, 3\]"),
    (dict(vertices=_SQUARE_V.astype(bool)), "vertices must hold real numbers"),
    (dict(vertices=_SQUARE_V.astype(complex)), "vertices must hold real numbers"),
    (dict(vertices="abc"), "vertices must hold real numbers"),
    (dict(vertices=None), "vertices must be a real number"),
    (dict(faces=_SQUARE_F.astype(bool)), "faces must be integer"),
    (dict(faces=_SQUARE_F + 2**40), "out of range"),
    (dict(normals=np.tile([0, 0, 1j], (4, 1))), "normals must hold real numbers"),
    (dict(normals="up"), "normals must hold real numbers"),
    (dict(normal_weighting="x"), "normal_weighting must be one of"),
    (dict(dtype="float16"), "dtype must be float32 or float64"),
    (dict(dtype="x"), "dtype must be float32 or float64"),
    (dict(grid="x"), "grid must be None or a caustics_jax.surface.mesh.GridInfo"),
])
def test_bad_from_arrays_arguments_are_value_errors_naming_them(kwargs, match):
    args = dict(vertices=_SQUARE_V, faces=_SQUARE_F) | kwargs
    with pytest.raises(ValueError, match=match):
        SurfaceMesh.from_arrays(args.pop("vertices"), args.pop("faces"), **args)


def test_integer_and_half_vertices_are_values_half_builds_float32():
    assert SurfaceMesh.from_arrays(_SQUARE_V.astype(np.float16), _SQUARE_F).dtype == jnp.float32
    mesh = SurfaceMesh.from_arrays(_SQUARE_V.astype(int), _SQUARE_F.astype(np.uint16), dtype="float64")
    np.testing.assert_array_equal(mesh.vertices, _SQUARE_V)


@pytest.mark.parametrize("kwargs, match", [
    (dict(heights=np.full((3, 3), 1e39), dtype="float32"), "heights overflow float32"),
    (dict(x0=1e39, dtype="float32"), "grid positions .* overflow float32"),
    (dict(heights=np.ones((3, 3), bool)), "heights must hold real numbers"),
    (dict(heights=np.ones((3, 3), complex)), "heights must hold real numbers"),
    (dict(dx=0.0), "dx must be a finite non-zero"), (dict(dy=float("nan")), "dy must be a finite real"),
    (dict(dx="1"), "dx must be a finite real"), (dict(x0=float("inf")), "x0 must be a finite real"),
    (dict(normals=np.ones((2, 2, 3))), "normals must have shape"),
])
def test_bad_from_heightfield_arguments_are_value_errors_naming_them(kwargs, match):
    args = dict(heights=np.zeros((3, 3)), x0=0.0, y0=0.0, dx=1.0, dy=1.0) | kwargs
    with pytest.raises(ValueError, match=match):
        SurfaceMesh.from_heightfield(args.pop("heights"), **args)


@pytest.mark.parametrize("obj", ["x", None, _SQUARE_V, 3])
def test_from_trimesh_refuses_what_is_not_a_trimesh(obj):
    with pytest.raises(ValueError, match="trimesh.Trimesh or trimesh.Scene"):
        SurfaceMesh.from_trimesh(obj)


def _user_warnings(fn):
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fn()
    return [str(w.message) for w in caught if issubclass(w.category, UserWarning)]


def _closed_cube():
    box = trimesh.creation.box()
    return np.asarray(box.vertices), np.asarray(box.faces)


def test_a_surface_wound_clockwise_warns_with_the_fix():
    (msg,) = _user_warnings(lambda: SurfaceMesh.from_arrays(_SQUARE_V, _SQUARE_F[:, ::-1]))
    assert "point mostly down" in msg and "faces[:, ::-1]" in msg
    wavy = MESHES["wavy_pool"]
    (msg,) = _user_warnings(lambda: SurfaceMesh.from_arrays(np.asarray(wavy.vertices), np.asarray(wavy.faces)[:, ::-1]))
    assert "of the area faces down" in msg
    V, F = _closed_cube()
    (msg,) = _user_warnings(lambda: SurfaceMesh.from_arrays(V, F[:, ::-1]))
    assert "into the closed mesh" in msg and "faces[:, ::-1]" in msg


def test_legitimate_meshes_do_not_warn_about_winding():
    V, F = _closed_cube()
    wall = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1.0]])
    bowl = trimesh.creation.icosphere(2)  # the lower half of a sphere, seen from above: a bowl
    keep = bowl.triangles_center[:, 2] < 0
    bowl_V, bowl_F = np.asarray(bowl.vertices), np.asarray(bowl.faces)[keep][:, ::-1]  # inside faces up
    cases = {
        "square": (_SQUARE_V, _SQUARE_F), "closed cube": (V, F),
        "vertical wall": (wall, np.array([[0, 1, 2], [1, 3, 2]])),
        "bowl": (bowl_V, bowl_F), "far from the origin": (V + 1e6, F),
        **{name: (np.asarray(m.vertices), np.asarray(m.faces)) for name, m in MESHES.items()},
    }
    for name, (V_, F_) in cases.items():
        used = np.unique(F_)
        remap = np.full(len(V_), -1)
        remap[used] = np.arange(len(used))
        assert _user_warnings(lambda V_=V_, F_=F_, used=used, remap=remap: SurfaceMesh.from_arrays(
            V_[used], remap[F_])) == [], name



def test_a_float64_face_that_float32_collapses_is_kept_and_solved_around():
    """Zero area is judged on the input (float64 here): a face 1e-5 high at x = 1000 is a
    triangle in float64 and a segment once stored in float32, and is accepted, as the
    stress suite's `sliver` category accepts needles below float32 resolution (its solvers
    find every planted path there, docs/stability.md). The same vertices given as float32
    arrays are refused: in float32 the face has no area to begin with."""
    o = 1000.0
    V = np.array([[o, o, 0], [o + 1, o, 0], [o + 0.5, o + 1e-5, 0], [o, o + 1, 0]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    SurfaceMesh.from_arrays(V, F, dtype="float32")
    with pytest.raises(ValueError, match=r"degenerate faces \(zero area\): faces \[0\]"):
        SurfaceMesh.from_arrays(V.astype(np.float32), F)


def test_heightfield_normals_must_have_the_layout_of_the_heights():
    """Normals are `(ny + 1, nx + 1, 3)` like `heights`: a transposed `(nx + 1, ny + 1, 3)`
    array (same element count) had been reshaped silently into scrambled normals, and a
    flat `(3 V,)` one accepted too."""
    X, Y = np.meshgrid(np.linspace(0, 3, 7), np.linspace(0, 2, 5))  # heights (5, 7)
    H = 0.05 * np.sin(2 * X) * np.cos(3 * Y)
    N = np.stack([-0.1 * np.cos(2 * X), 0.15 * np.sin(3 * Y), np.ones_like(H)], -1)
    mesh = SurfaceMesh.from_heightfield(H, x0=0, y0=0, dx=0.5, dy=0.5, normals=N, dtype="float64")
    np.testing.assert_allclose(mesh.normals, N.reshape(-1, 3) / np.linalg.norm(N, axis=-1).reshape(-1, 1))
    for bad in (N.transpose(1, 0, 2).copy(), N.ravel(), N.reshape(-1, 3), N[..., :2]):
        with pytest.raises(ValueError, match=r"normals must have shape \(5, 7, 3\) \(heights' \(ny \+ 1, nx \+ 1\)"):
            SurfaceMesh.from_heightfield(H, x0=0, y0=0, dx=0.5, dy=0.5, normals=bad)
    with pytest.raises(ValueError, match="normals must hold real numbers"):
        SurfaceMesh.from_heightfield(H, x0=0, y0=0, dx=0.5, dy=0.5, normals="up")


@pytest.mark.parametrize("face, edge", [(0, 3), (0, 5), (0, -1), (-1, -2), (-1, 3), ([0, 1, 2], [0, 1, 7]),
                                        ([[1], [-1]], [[2], [-2]])])
def test_cross_edge_refuses_an_edge_outside_0_1_2(face, edge):
    """Edge 5 had been clipped silently to edge 2 (and -1 to 0), crossing a different edge;
    -1 stays accepted where face < 0 (cross_edge's own answer on a boundary)."""
    mesh = SurfaceMesh.from_heightfield(np.zeros((3, 3)), x0=0, y0=0, dx=1, dy=1)
    face, edge = np.asarray(face), np.asarray(edge)
    with pytest.raises(ValueError, match=r"cross_edge: edge must be 0, 1 or 2"):
        cross_edge(mesh, face, edge, np.full(edge.shape, 0.3))
    g, k, _, _ = cross_edge(mesh, np.array([-1, 0]), np.array([-1, 2]), np.array([0.3, 0.3]))
    assert g.tolist() == [-1, 1] and k.tolist() == [-1, 0]
