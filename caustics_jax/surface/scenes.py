"""Reproducible scenes of the papers: flat pool, wavy pool (Gerstner waves), lagoon.

Each generator is seeded (numpy `default_rng(seed)`, float64, then cast) and returns a
`Scene`: the water surface (a `SurfaceMesh`, outward normals +z), receiver points on the
floor (under the water, inside the medium) with their floor normals, and the lights.

Geometry (metres): water around `z = 0`, floor at about `z = -depth` (`depth = 1`), pool
`2 half_size` wide (4 m), the water surface extended a little past the pool walls as in
seed 001 §5, lights a few metres above.

`Scene.is_grid` is True when the surface is a regular heightfield grid: vertices exactly
at `(x0 + i dx, y0 + j dy)` with the `GridInfo` face layout (`surface.grid` is set), the
property the O(1)-per-cell start-point fast path relies on. Gerstner waves with horizontal
displacement (`wavy_pool(..., choppiness > 0)`) move vertices off that grid, so those
surfaces are built as general meshes (`is_grid = False`).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..runtime.arguments import check_choice, check_fits, check_int, check_real, real_array
from ..runtime.precision import check_float_dtype, default_float_dtype
from .lights import Directional
from .mesh import GridInfo, SurfaceMesh

GRAVITY = 9.81
#: Largest `n_triangles` a generator builds (64 M faces, about 5 GB of float64 vertices
#: and adjacency on the host); larger requests are refused rather than left to exhaust memory.
MAX_TRIANGLES = 2**26
#: Largest `n_receivers` (receivers per side: up to 16.7 M receivers).
MAX_RECEIVERS_PER_SIDE = 4096
LIGHTS = ("point", "directional", "both")


class Lights(eqx.Module):
    """Point and directional lights.

    `source(k)` is light `k` as every solver, irradiance and photon function takes it: a
    position `(3,)`, or a `Directional` (surface/lights.py) for a directional light.

    Attributes:
        position: `(K, 3)` position of each point light; for a directional light, the
            point `far * direction` (only a representative; pass `source(k)`).
        direction: `(K, 3)` unit vector toward the light (for a point light, from the
            origin toward it).
        directional: static tuple of K flags, True for a directional light.
        far: static distance of `endpoint`'s stand-in point for a directional light.
    """

    position: Float[Array, "K 3"]
    direction: Float[Array, "K 3"]
    directional: tuple[bool, ...] = eqx.field(static=True)
    far: float = eqx.field(static=True, default=100.0)

    def source(self, k: int = 0):
        """Light `k` in `[0, K)` as the functions take `L`: its position `(3,)` (float64
        numpy), or `Directional(-direction[k])` for a directional light (the rays travel
        away from the light, `direction` points toward it)."""
        k = check_int("k", k, 0, len(self.directional) - 1)
        if self.directional[k]:
            return Directional(-np.asarray(self.direction[k], np.float64))
        return np.asarray(self.position[k], np.float64)

    def endpoint(self, P: Float[Array, "*batch 3"], k: int = 0) -> Float[Array, "*batch 3"]:
        """Segment end `L` for receivers `P` `(..., 3)` and light `k` in `[0, K)` (the light
        itself, or `P + far d`: a point light `far` m away standing in for a directional
        one, not its limit; `source(k)` is the light itself); in `P`'s float dtype (the
        lights' for integer `P`)."""
        k = check_int("k", k, 0, len(self.directional) - 1)
        P = jnp.asarray(P)
        if P.ndim == 0 or P.shape[-1] != 3:
            raise ValueError(f"P must have shape (..., 3), got {P.shape}")
        if P.dtype == jnp.bool_ or not (jnp.issubdtype(P.dtype, jnp.floating) or jnp.issubdtype(P.dtype, jnp.integer)):
            raise ValueError(f"P must hold real numbers, got dtype {P.dtype}")
        if not jnp.issubdtype(P.dtype, jnp.floating):
            P = P.astype(self.position.dtype)
        if self.directional[k]:
            return P + self.far * self.direction[k].astype(P.dtype)
        return jnp.broadcast_to(self.position[k].astype(P.dtype), P.shape)


class Scene(eqx.Module):
    """A generated scene.

    Attributes:
        surface: the water surface.
        receivers: `(R, 3)` receiver points on the floor, under the water.
        receiver_normals: `(R, 3)` unit floor normals at the receivers (+z up).
        lights: the lights.
        is_grid: static; True when `surface` is a regular heightfield grid (`surface.grid`).
        name: static scene name with its parameters.
    """

    surface: SurfaceMesh
    receivers: Float[Array, "R 3"]
    receiver_normals: Float[Array, "R 3"]
    lights: Lights
    is_grid: bool = eqx.field(static=True)
    name: str = eqx.field(static=True)


# --------------------------------------------------------------------------- generators


def flat_pool(
    n_triangles: int = 512,
    *,
    seed: int = 0,
    half_size: float = 2.0,
    depth: float = 1.0,
    n_receivers: int = 32,
    receiver_jitter: float = 0.0,
    light: str = "point",
    light_position=(0.4, -0.3, 3.0),
    dtype=None,
) -> Scene:
    """A still pool: the plane `z = 0` as a regular grid of about `n_triangles` triangles."""
    light_position = _check_pool(n_triangles, seed, half_size, depth, n_receivers, receiver_jitter, light,
                                 light_position, dtype, top=0.0)
    rng = np.random.default_rng(seed)
    g = _pool_layout(half_size, n_triangles)
    mesh = SurfaceMesh.from_heightfield(
        np.zeros((g.ny + 1, g.nx + 1)),
        x0=g.x0,
        y0=g.y0,
        dx=g.dx,
        dy=g.dy,
        normals=np.broadcast_to([0.0, 0.0, 1.0], (g.ny + 1, g.nx + 1, 3)),
        dtype=dtype,
    )
    R, Rn = _pool_receivers(rng, half_size, depth, n_receivers, receiver_jitter)
    return _scene(
        mesh, R, Rn, light, light_position, True, f"flat_pool(n_triangles={mesh.faces.shape[0]})"
    )


def wavy_pool(
    n_triangles: int = 8192,
    *,
    seed: int = 0,
    amplitude: float = 0.03,
    n_waves: int = 4,
    wavelength=(0.6, 2.0),
    choppiness: float = 0.0,
    time: float = 0.0,
    half_size: float = 2.0,
    depth: float = 1.0,
    n_receivers: int = 32,
    receiver_jitter: float = 0.0,
    light: str = "point",
    light_position=(0.4, -0.3, 3.0),
    dtype=None,
) -> Scene:
    """A pool whose water is a sum of `n_waves` Gerstner waves (GPU Gems 1 ch. 1).

    Wave `i`: amplitude `A_i` (the `A_i` sum to `amplitude`, so `|z| <= amplitude`),
    wavelength uniform in `wavelength`, direction `D_i` within +-45 degrees of a random
    wind, phase uniform, deep-water dispersion `omega_i = sqrt(g k_i)`. Surface point of
    the rest position `x`: `(x - sum Q_i A_i D_i sin theta_i, sum A_i cos theta_i)`,
    `theta_i = k_i D_i . x - omega_i time + phi_i`. The default gentle sea has maximum
    slope `sum A_i k_i` of about 0.1-0.3.

    `choppiness = 0` (default) keeps vertices on the regular xy grid: a heightfield grid
    (`is_grid = True`) of `2 nx ny >= n_triangles` faces. `0 < choppiness < 1` sets
    `sum Q_i A_i k_i = choppiness`, which displaces x/y (no fold-over below 1) and gives a
    general mesh (`is_grid = False`). Normals are analytic: the cross product of the
    surface's partial derivatives at each vertex, not mesh averages.
    """
    if not (0 <= check_real("choppiness", choppiness) < 1):
        raise ValueError(
            f"choppiness must be in [0, 1) so the surface does not fold, got {choppiness}"
        )
    amplitude = _check_waves(amplitude, n_waves, wavelength, time, depth)
    light_position = _check_pool(n_triangles, seed, half_size, depth, n_receivers, receiver_jitter, light,
                                 light_position, dtype, top=amplitude)
    rng = np.random.default_rng(seed)
    g = _pool_layout(half_size, n_triangles)
    waves = _gerstner_waves(rng, amplitude, n_waves, wavelength, choppiness)
    X, N = _gerstner_surface(waves, g.vertex_xy(), time)
    R, Rn = _pool_receivers(rng, half_size, depth, n_receivers, receiver_jitter)
    name = (
        f"wavy_pool(n_triangles={2 * g.nx * g.ny}, seed={seed}, amplitude={amplitude}, "
        f"choppiness={choppiness})"
    )
    try:
        if choppiness == 0:
            mesh = SurfaceMesh.from_heightfield(X[:, 2].reshape(g.ny + 1, g.nx + 1), x0=g.x0, y0=g.y0, dx=g.dx,
                                                dy=g.dy, normals=N.reshape(g.ny + 1, g.nx + 1, 3), dtype=dtype)
        else:  # same connectivity as the grid, but the vertices have moved off it: a general mesh
            mesh = SurfaceMesh.from_arrays(X, g.faces(), N, dtype=default_float_dtype(None, dtype))
    except ValueError as exc:  # waves far shorter than a cell: the normals do not fit the faces
        raise ValueError(f"wavy_pool: waves of amplitude {amplitude:g} m and wavelengths {tuple(wavelength)} m "
                         f"are not resolved by {2 * g.nx * g.ny} triangles (cells of {abs(g.dx):.3g} m): "
                         f"{exc}. Use longer waves, a smaller amplitude or more triangles") from None
    return _scene(mesh, R, Rn, light, light_position, choppiness == 0, name)


def lagoon(
    n_triangles: int = 8192,
    *,
    seed: int = 0,
    size=(6.0, 4.0),
    amplitude: float = 0.03,
    n_waves: int = 4,
    wavelength=(0.6, 2.0),
    time: float = 0.0,
    depth: float = 1.0,
    floor_relief: float = 0.3,
    n_receivers: int = 32,
    light: str = "point",
    light_position=(0.4, -0.3, 3.0),
    dtype=None,
) -> Scene:
    """A lagoon: irregular floor, water triangulated irregularly (Delaunay of jittered points).

    The water covers the rectangle `size` (centred at the origin) with about `n_triangles`
    Delaunay triangles of randomly jittered points (no grid structure, `is_grid = False`);
    its height is a sum of Gerstner waves without horizontal displacement, with analytic
    normals. The floor is `z = -depth + relief(x, y)`, a seeded sum of random sinusoids
    with `|relief| <= floor_relief`; receivers sit on it on an `n_receivers`-per-side grid,
    with the floor's analytic normals.
    """
    from scipy.spatial import Delaunay

    depth = check_real("depth", depth, 0, lo_open=True)
    if not 0 <= check_real("floor_relief", floor_relief) < depth:
        raise ValueError(
            f"floor_relief {floor_relief} must lie in [0, depth = {depth}) (floor under water)"
        )
    size_np = real_array("size", size)
    if size_np.shape != (2,) or not np.all(np.isfinite(size_np)) or np.any(size_np <= 0):
        raise ValueError(f"size must be two finite positive lengths (width, height) in m, got {size!r}")
    amplitude = _check_waves(amplitude, n_waves, wavelength, time, depth - floor_relief,
                             below=f"depth - floor_relief = {depth:g} - {floor_relief:g}, the highest floor")
    light_position = _check_pool(n_triangles, seed, 1.0, depth, n_receivers, 0.0, light, light_position,
                                 dtype, top=amplitude)
    rng = np.random.default_rng(seed)
    W, H = (float(x) for x in size_np)
    # Delaunay of n points in convex position-free general position: F ~ 2 n - hull.
    h = math.sqrt(W * H / max(n_triangles / 2, 1))
    mx, my = max(round(W / h), 2), max(round(H / h), 2)
    gx, gy = np.meshgrid(
        np.linspace(-W / 2, W / 2, mx + 1), np.linspace(-H / 2, H / 2, my + 1), indexing="xy"
    )
    pts = np.stack([gx.ravel(), gy.ravel()], -1)
    interior = (np.abs(pts[:, 0]) < W / 2 - 1e-9) & (np.abs(pts[:, 1]) < H / 2 - 1e-9)
    # Interior points jittered by up to 0.35 cell: irregular yet no two points coincide.
    pts[interior] += rng.uniform(-0.35, 0.35, (interior.sum(), 2)) * [W / mx, H / my]
    tri = Delaunay(pts).simplices
    p0, p1, p2 = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    cw = (p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (
        p2[:, 0] - p0[:, 0]
    ) < 0
    tri[cw] = tri[cw][:, [0, 2, 1]]
    waves = _gerstner_waves(rng, amplitude, n_waves, wavelength, 0.0)
    X, N = _gerstner_surface(waves, pts, time)
    mesh = SurfaceMesh.from_arrays(X, tri, N, dtype=default_float_dtype(None, dtype))
    relief = _relief(rng, floor_relief, size)
    rx, ry = np.meshgrid(
        *[(np.arange(n_receivers) + 0.5) / n_receivers * s - s / 2 for s in size], indexing="xy"
    )
    rxy = np.stack([rx.ravel(), ry.ravel()], -1)
    z, grad = relief(rxy)
    R = np.concatenate([rxy, (z - depth)[:, None]], -1)
    Rn = np.concatenate([-grad, np.ones((len(R), 1))], -1)
    Rn /= np.linalg.norm(Rn, axis=-1, keepdims=True)
    return _scene(
        mesh,
        R,
        Rn,
        light,
        light_position,
        False,
        f"lagoon(n_triangles={mesh.faces.shape[0]}, seed={seed})",
    )


# --------------------------------------------------------------------------- helpers


#: File suffixes `load_mesh` reads (what trimesh reads that holds triangles).
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def load_mesh(path, dtype="float64") -> SurfaceMesh:
    """The `SurfaceMesh` of a mesh file trimesh reads (`MESH_SUFFIXES`), in `dtype`; a
    `ValueError` naming the file when it is missing, unreadable or holds no usable mesh."""
    import pathlib

    import trimesh

    path = pathlib.Path(path).expanduser()
    if not path.is_file():
        raise ValueError(f"scene file {str(path)!r} does not exist")
    try:
        loaded = trimesh.load(path)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise ValueError(f"scene file {str(path)!r} could not be read by trimesh: {exc}") from None
    try:
        return SurfaceMesh.from_trimesh(loaded, dtype=dtype)
    except ValueError as exc:
        raise ValueError(f"scene file {str(path)!r} holds no usable triangle mesh: {exc}") from None


def scene_around(surface: SurfaceMesh, *, light=None, floor_depth: float | None = None, n_receivers: int = 32,
                 name: str = "mesh") -> Scene:
    """A scene around any surface: receivers on a floor under it and a point light above it.

    With `W` the larger side of the surface's xy bounding box, the floor is the plane
    `floor_depth` (default `W / 4`) below the lowest vertex, under the whole xy extent
    (receivers on an `n_receivers x n_receivers` grid there, normals +z), and the light is
    `light` (a point `(3,)`, or a `Directional`: the sun), by default at `centre + (0.1 W, -0.075 W)` in xy, `0.75 W`
    above the highest vertex: the proportions of the built-in pools (4 m wide, floor 1 m
    down, light at (0.4, -0.3, 3) m). The surface's normals must face the light (+z);
    refraction is from above into the medium below, as in every scene.
    """
    V = np.asarray(surface.vertices, np.float64)
    lo, hi = V.min(0), V.max(0)
    W = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    if not W > 0:
        raise ValueError(f"scene {name!r}: the surface has no xy extent (bounding box {lo} .. {hi})")
    n_receivers = check_int("n_receivers", n_receivers, 1, MAX_RECEIVERS_PER_SIDE)
    depth = W / 4 if floor_depth is None else check_real("floor_depth", floor_depth, 0, lo_open=True)
    centre = 0.5 * (lo[:2] + hi[:2])
    if light is None:
        light = np.array([centre[0] + 0.1 * W, centre[1] - 0.075 * W, hi[2] + 0.75 * W])
    kind = "directional" if isinstance(light, Directional) else "point"
    light = light.toward if kind == "directional" else real_array("light", light)
    if light.shape != (3,) or not np.all(np.isfinite(light)):
        raise ValueError(f"light must be one finite point (x, y, z) or a Directional, got {light.tolist()}")
    u = (np.arange(n_receivers) + 0.5) / n_receivers
    X, Y = np.meshgrid(lo[0] + u * (hi[0] - lo[0]), lo[1] + u * (hi[1] - lo[1]), indexing="xy")
    R = np.stack([X.ravel(), Y.ravel(), np.full(X.size, lo[2] - depth)], -1)
    return _scene(surface, R, np.broadcast_to([0.0, 0.0, 1.0], R.shape), kind, light, False, name)


def _check_pool(n_triangles, seed, half_size, depth, n_receivers, receiver_jitter, light, light_position,
                dtype, *, top: float) -> np.ndarray:
    """The generators' shared arguments, refused with `ValueError` before any work
    (docs/input_contract.md); returns `light_position` as a float64 `(3,)` array."""
    check_int("n_triangles", n_triangles, 2, MAX_TRIANGLES)
    check_int("seed", seed, 0, 2**63 - 1)
    check_real("half_size", half_size, 0, lo_open=True)
    check_real("depth", depth, 0, lo_open=True)
    check_int("n_receivers", n_receivers, 1, MAX_RECEIVERS_PER_SIDE)
    check_real("receiver_jitter", receiver_jitter, 0, 1)
    check_choice("light", light, LIGHTS)
    if dtype is not None:
        check_float_dtype(dtype)
    pos = real_array("light_position", light_position)
    if pos.shape != (3,) or not np.all(np.isfinite(pos)) or not pos[2] > top:
        raise ValueError(f"light_position must be a finite point (x, y, z) above the water (z > {top:g} m; "
                         f"for a directional light, its direction from the origin), got {light_position!r}")
    check_fits("light_position", light_position, default_float_dtype(None, dtype))  # (1e39 had become inf in float32)
    return pos


def _check_waves(amplitude, n_waves, wavelength, time, depth, below: str = "the floor depth") -> float:
    """Gerstner wave arguments: `0 <= amplitude < depth` (receivers stay under water;
    `below` says what `depth` is), `n_waves` in [1, 1024], `wavelength = (lo, hi)` with
    `0 < lo <= hi`, finite `time`."""
    depth = check_real("depth", depth, 0, lo_open=True)
    amplitude = check_real("amplitude", amplitude, 0)
    if not amplitude < depth:
        raise ValueError(f"amplitude must lie in [0, {depth:g}) m (below {below}, so the receivers "
                         f"stay under water), got {amplitude!r}")
    check_int("n_waves", n_waves, 1, 1024)
    lam = real_array("wavelength", wavelength)
    if lam.shape != (2,) or not np.all(np.isfinite(lam)) or not 0 < lam[0] <= lam[1]:
        raise ValueError(f"wavelength must be a range (lo, hi) in m with 0 < lo <= hi, got {wavelength!r}")
    check_real("time", time)
    return amplitude



def _pool_layout(half_size: float, n_triangles: int) -> GridInfo:
    """Grid of `2 nx ny >= n_triangles` faces (nearly square cells) over the pool.

    The water extends 5% past the pool walls (seed 001 §5 extends it "slightly").
    """
    if n_triangles < 2:
        raise ValueError(f"n_triangles must be >= 2, got {n_triangles}")
    ny = max(round(math.sqrt(n_triangles / 2)), 1)
    nx = max(math.ceil(n_triangles / (2 * ny)), 1)
    half = 1.05 * half_size
    return GridInfo(nx=nx, ny=ny, x0=-half, y0=-half, dx=2 * half / nx, dy=2 * half / ny)


def _gerstner_waves(rng, amplitude, n_waves, wavelength, choppiness):
    w = rng.uniform(0.5, 1.0, n_waves)
    A = amplitude * w / w.sum()
    lam = rng.uniform(*wavelength, n_waves)
    k = 2 * np.pi / lam
    wind = rng.uniform(0, 2 * np.pi)
    ang = wind + rng.uniform(-np.pi / 4, np.pi / 4, n_waves)
    D = np.stack([np.cos(ang), np.sin(ang)], -1)
    phase = rng.uniform(0, 2 * np.pi, n_waves)
    slope = np.sum(A * k)
    Q = np.full(n_waves, choppiness / slope if slope > 0 else 0.0)
    return dict(A=A, k=k, D=D, phase=phase, Q=Q, omega=np.sqrt(GRAVITY * k))


def _gerstner_surface(waves, xy, time):
    """Surface points `(n, 3)` and analytic unit normals `(n, 3)` at rest positions `xy`."""
    A, k, D, Q = waves["A"], waves["k"], waves["D"], waves["Q"]
    theta = k * (xy @ D.T) - waves["omega"] * time + waves["phase"]  # (n, waves)
    s, c = np.sin(theta), np.cos(theta)
    X = np.concatenate([xy - (Q * A * s) @ D, (c @ A)[:, None]], -1)
    # Partial derivatives of the displaced point along the rest x and y axes.
    QAkc = Q * A * k * c
    dXdx = np.stack(
        [1 - QAkc @ (D[:, 0] ** 2), -QAkc @ (D[:, 0] * D[:, 1]), -(A * k * s) @ D[:, 0]], -1
    )
    dXdy = np.stack(
        [-QAkc @ (D[:, 0] * D[:, 1]), 1 - QAkc @ (D[:, 1] ** 2), -(A * k * s) @ D[:, 1]], -1
    )
    N = np.cross(dXdx, dXdy)
    return X, N / np.linalg.norm(N, axis=-1, keepdims=True)


def _relief(rng, amplitude, size, n_terms: int = 6):
    """Random smooth floor relief `r(x, y)` with `|r| <= amplitude`, and its gradient."""
    lam = rng.uniform(0.8, 3.0, n_terms)
    ang = rng.uniform(0, 2 * np.pi, n_terms)
    K = (2 * np.pi / lam)[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    phase = rng.uniform(0, 2 * np.pi, n_terms)
    a = rng.uniform(0.5, 1.0, n_terms)
    a *= amplitude / a.sum()

    def relief(xy):
        theta = xy @ K.T + phase
        return np.sin(theta) @ a, (np.cos(theta) * a) @ K

    return relief


def _pool_receivers(rng, half_size, depth, n, jitter):
    u = (np.arange(n) + 0.5) / n * 2 * half_size - half_size
    X, Y = np.meshgrid(u, u, indexing="xy")
    xy = np.stack([X.ravel(), Y.ravel()], -1)
    if jitter:
        xy += rng.uniform(-0.5, 0.5, xy.shape) * jitter * 2 * half_size / n
    R = np.concatenate([xy, np.full((len(xy), 1), -depth)], -1)
    return R, np.broadcast_to([0.0, 0.0, 1.0], R.shape)


def _scene(mesh, R, Rn, light, light_position, is_grid, name) -> Scene:
    kinds = {"point": (False,), "directional": (True,), "both": (False, True)}
    directional = kinds[check_choice("light", light, LIGHTS)]
    pos = np.asarray(light_position, dtype=np.float64)
    d = pos / np.linalg.norm(pos)
    far = 100.0
    position = np.stack([far * d if is_dir else pos for is_dir in directional])
    direction = np.stack([d for _ in directional])
    dtype = mesh.dtype
    lights = Lights(
        position=jnp.asarray(position, dtype),
        direction=jnp.asarray(direction, dtype),
        directional=directional,
        far=far,
    )
    return Scene(
        surface=mesh,
        receivers=jnp.asarray(R, dtype),
        receiver_normals=jnp.asarray(Rn, dtype),
        lights=lights,
        is_grid=is_grid,
        name=name,
    )
