"""float32 walk lanes that float64 and Newton find (issue 14 class 6), and the mechanism.

Two rounding traps of `arcs.next_crossing` made the float32 walk leave the curve's path:

1. A root close to the current point on a gentle curve: its offset across the tangent
   (curvature x dist^2 / 2) is below the barycentrics' absolute rounding, so the sign of
   `across` is noise; `arctan2(-0, -1)` wrapped a root *behind* the point to pencil angle
   ~0 ("first ahead"), in both directions of travel.
2. A genuine exit within `64 eps` of the current point (a start point 5e-6 from an edge, a
   curve clipping a corner 1e-5 from a vertex) was excluded as a "duplicate vertex root":
   the walk went backwards (and TIR) or lost the curve.

Each lane below failed before the fix (measured: the sine-surface lane LEFT_MESH after 32
steps; 4 of 16384 lanes of the 2048-triangle pool TOTAL_INTERNAL_REFLECTION, 3 of 20000
on the default 8192-triangle pool) and is found after it, with every other lane's status,
point and iteration count unchanged (bit-identical in float64, docs/stability.md).
"""

import numpy as np
import pytest

import caustics_jax as cj
from caustics_jax.app import compare
from caustics_jax.surface.mesh import GridInfo
from caustics_jax.testing import refraction_angle_error


def sine_surface(dtype, scale=1.0, shift=(0.0, 0.0, 0.0)):
    """The issue's gentle 10 x 10 cell sine surface, heights 0.05 sin 2x cos 1.5y on [-2, 2]^2."""
    x = np.linspace(-2, 2, 11)
    X, Y = np.meshgrid(x, x, indexing="xy")
    H = 0.05 * np.sin(2 * X) * np.cos(1.5 * Y)
    V = np.stack([X.ravel(), Y.ravel(), H.ravel()], -1) * scale + np.asarray(shift)
    faces = GridInfo(nx=10, ny=10, x0=-2, y0=-2, dx=0.4, dy=0.4).faces()
    return cj.SurfaceMesh.from_arrays(V, faces, dtype=dtype)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_walk_finds_the_root_next_to_an_edge_on_a_gentle_sine_surface_under_rigid_moves(dtype):
    """The issue's lane: FOUND in place, scaled by 1e-3 and 1e3 and translated, at the
    point Newton finds (up to the acceptance tolerance), in both precisions."""
    P = np.array([[-0.659, -0.678, -1.0]])
    L = np.array([[0.4, -0.3, 3.0]])
    with cj.precision(dtype):
        for s, t in ((1.0, (0.0, 0.0, 0.0)), (1e-3, (0.0, 0.0, 0.0)), (1e3, (0.0, 0.0, 0.0)), (1.0, (3.0, -2.0, 1.0))):
            mesh = sine_surface(dtype, s, t)
            Ps, Ls = P * s + np.asarray(t), L * s + np.asarray(t)
            walk = cj.solve(mesh, Ps, Ls, features=None)
            newton = cj.solve(mesh, Ps, Ls, method="newton", features=None)
            assert walk.summary() == {"FOUND": 1}, (s, t, walk.summary())
            assert newton.summary() == {"FOUND": 1}
            # Both accept |sin(angle error)| <= tol; 6 cm from M0, so within tol x distance.
            gap = np.linalg.norm(np.asarray(walk.point, np.float64) - np.asarray(newton.point, np.float64))
            assert gap <= 1e-4 * s, (s, t, gap)


def test_float32_walk_lanes_near_edges_and_vertices_of_the_default_pool_are_found():
    """The 4 float32 lanes of the 2048-triangle pool (16384 floor receivers of the
    comparison) that ended TOTAL_INTERNAL_REFLECTION before the fix, where float64 finds
    them; found now, and their points refract within float32's acceptance."""
    cfg = compare.CompareConfig(n=16384, n_triangles=2048)
    with cj.precision("float64"):
        sc64, ref_mesh, P, L = compare.scene_arrays(cfg)
    lanes = np.array([2911, 3605, 11313, 11958])
    with cj.precision("float32"):
        mesh = sc64.surface.astype("float32")
        sol = cj.solve(mesh, P[lanes].astype("float32"), L[lanes].astype("float32"), features=None)
    assert sol.summary() == {"FOUND": 4}
    angle = refraction_angle_error(ref_mesh, np.asarray(sol.triangle), np.asarray(sol.barycentric), P[lanes],
                                   L[lanes], cfg.eta)
    assert np.all(angle <= 2e-5), angle  # |f| <= 1e-5 plus float32 rounding of the inputs
