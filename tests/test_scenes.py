"""Properties of the scene generators: reproducible, valid, physically arranged."""

import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax import scenes
from caustics_jax.surface.mesh import SurfaceMesh
from caustics_jax.surface.scenes import flat_pool, lagoon, wavy_pool

GENERATORS = {
    "flat_pool": lambda n, seed, **kw: flat_pool(n, seed=seed, receiver_jitter=0.5, **kw),
    "wavy_pool": lambda n, seed, **kw: wavy_pool(n, seed=seed, **kw),
    "wavy_pool_choppy": lambda n, seed, **kw: wavy_pool(n, seed=seed, choppiness=0.7, **kw),
    "lagoon": lambda n, seed, **kw: lagoon(n, seed=seed, **kw),
}


def _arrays(scene):
    s = scene.surface
    return [s.vertices, s.normals, s.faces, scene.receivers, scene.receiver_normals,
            scene.lights.position]  # fmt: skip


@pytest.mark.parametrize("name", sorted(GENERATORS))
def test_same_seed_gives_identical_scene_and_other_seed_differs(name):
    a, b = GENERATORS[name](400, 7), GENERATORS[name](400, 7)
    for x, y in zip(_arrays(a), _arrays(b), strict=True):
        np.testing.assert_array_equal(x, y)
    c = GENERATORS[name](400, 8)
    differs = [
        x.shape != y.shape or not np.array_equal(x, y)
        for x, y in zip(_arrays(a), _arrays(c), strict=True)
    ]
    assert any(differs)


@pytest.mark.parametrize("name", sorted(GENERATORS))
@pytest.mark.parametrize("n", [100, 4_000, 30_000])
def test_triangle_count_follows_the_request(name, n):
    F = GENERATORS[name](n, 0).surface.faces.shape[0]
    # Grids round up to 2 n^2 faces; Delaunay of jittered points lands within a few percent.
    assert 0.9 * n <= F <= 1.25 * n, F


@pytest.mark.parametrize("name", sorted(GENERATORS))
def test_receivers_lie_under_the_water_and_lights_above(name):
    scene = GENERATORS[name](2000, 1, light="both")
    V = np.asarray(scene.surface.vertices)
    R = np.asarray(scene.receivers)
    assert np.all(R[:, 2] < V[:, 2].min() - 0.5)
    lo, hi = V[:, :2].min(0), V[:, :2].max(0)
    assert np.all((R[:, :2] > lo) & (R[:, :2] < hi))  # under the surface, not beside it
    np.testing.assert_allclose(np.linalg.norm(scene.receiver_normals, axis=-1), 1, atol=1e-12)
    assert np.all(np.asarray(scene.receiver_normals)[:, 2] > 0.5)
    assert scene.lights.directional == (False, True)
    L_point = np.asarray(scene.lights.endpoint(scene.receivers, 0))
    L_dir = np.asarray(scene.lights.endpoint(scene.receivers, 1))
    assert np.all(L_point[:, 2] > V[:, 2].max() + 2)
    d = np.asarray(scene.lights.direction[1])
    np.testing.assert_allclose(L_dir, R + scene.lights.far * d, atol=1e-12)
    assert np.all(L_dir[:, 2] > V[:, 2].max() + 2)


@pytest.mark.parametrize("name", sorted(GENERATORS))
def test_is_grid_means_the_surface_is_a_regular_heightfield_grid(name):
    scene = GENERATORS[name](500, 2)
    s = scene.surface
    assert scene.is_grid == (s.grid is not None)
    if scene.is_grid:
        g = s.grid
        V = np.asarray(s.vertices)
        np.testing.assert_allclose(V[:, :2], g.vertex_xy(), atol=1e-12)
        np.testing.assert_array_equal(s.faces, g.faces())
    assert scene.is_grid == (name in ("flat_pool", "wavy_pool"))


@pytest.mark.parametrize("name", ["wavy_pool", "wavy_pool_choppy", "lagoon"])
def test_analytic_normals_match_normals_computed_from_a_fine_mesh(name):
    scene = GENERATORS[name](60_000, 3)
    s = scene.surface
    remeshed = SurfaceMesh.from_arrays(np.asarray(s.vertices), np.asarray(s.faces))
    interior = np.ones(s.vertices.shape[0], bool)
    interior[np.asarray(s.faces)[np.asarray(s.neighbors) < 0]] = False
    cos = np.sum(np.asarray(s.normals) * np.asarray(remeshed.normals), -1)[interior]
    # Measured: the angle between analytic and angle-weighted mesh normals is at most
    # 1.0e-3 rad (wavy), 4.1e-3 (choppy), 4.6e-3 (lagoon's irregular triangles): mesh
    # discretisation error. A dropped factor k in the x derivative gives 0.048 rad.
    assert np.max(np.arccos(np.clip(cos, -1, 1))) < 2e-2


def test_gerstner_heights_are_bounded_by_the_amplitude_and_choppy_waves_do_not_fold():
    for seed in range(3):
        V = np.asarray(wavy_pool(3000, seed=seed, amplitude=0.05).surface.vertices)
        assert np.abs(V[:, 2]).max() <= 0.05
        choppy = wavy_pool(3000, seed=seed, amplitude=0.05, choppiness=0.9).surface
        assert np.all(np.asarray(choppy.face_normals)[:, 2] > 0)  # no face turned over
    with pytest.raises(ValueError, match="choppiness"):
        wavy_pool(100, choppiness=1.0)


@pytest.mark.parametrize("name", sorted(GENERATORS))
def test_float32_scene_is_float32_throughout(name):
    scene = GENERATORS[name](300, 0, dtype="float32")
    for x in [scene.surface.vertices, scene.surface.normals, scene.surface.face_normals,
              scene.receivers, scene.receiver_normals, scene.lights.position,
              scene.lights.direction]:  # fmt: skip
        assert x.dtype == jnp.float32
    assert scene.lights.endpoint(scene.receivers, 0).dtype == jnp.float32


@pytest.mark.parametrize("make, match", [
    # float32 scenes: the light's position had become inf
    (lambda: scenes.wavy_pool(8, light_position=(0, 0, 1e39), dtype="float32"), "light_position overflows float32"),
    # lagoon: the bound is depth - floor_relief, and the message had said "amplitude < 0.01" only
    (lambda: scenes.lagoon(8, floor_relief=0.99), r"below depth - floor_relief = 1 - 0.99"),
    # waves far shorter than a cell: the mesh's internal message had been all the user saw
    (lambda: scenes.wavy_pool(8, wavelength=(1e-9, 1e-9)), "wavy_pool: waves of amplitude .* are not resolved by 8"),
])
def test_generator_arguments_name_their_cause(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_the_animated_pools_advance_with_time_and_time_zero_is_the_still_mesh():
    """`time` (the experiments' animated pool, experiments/temporal.py and reuse.py): the
    default is today's mesh bit for bit, a later time moves the waves (deep-water
    dispersion) and not the connectivity."""
    for make in (lambda **kw: scenes.wavy_pool(512, **kw), lambda **kw: scenes.lagoon(512, **kw)):
        still, zero, later = make(), make(time=0.0), make(time=1 / 30)
        assert np.array_equal(np.asarray(still.surface.vertices), np.asarray(zero.surface.vertices))
        assert np.array_equal(np.asarray(still.surface.normals), np.asarray(zero.surface.normals))
        moved = np.abs(np.asarray(later.surface.vertices) - np.asarray(still.surface.vertices)).max()
        assert 0 < moved < 0.05  # a frame at 30 frames/s moves the water by millimetres to centimetres
        assert np.array_equal(np.asarray(later.surface.faces), np.asarray(still.surface.faces))
