"""Generators shared by tests and experiments: random triangles and planted refracted paths.

Everything is drawn with numpy from an integer seed, in float64, then cast, so the same
seed gives the same float64 reference and float32 copy (MATH.md §4 "verify with planted
solutions").
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class PlantedPath(NamedTuple):
    """A refracted path `P -> M -> L` through triangle `(V, N)` at barycentric `ab`.

    Attributes:
        V: `(n, 3, 3)` vertex positions (rows V0, V1, V2).
        N: `(n, 3, 3)` unit vertex normals, outward (+z side, toward the light).
        P: `(n, 3)` receiver below the surface (inside the medium).
        L: `(n, 3)` light above the surface.
        ab: `(n, 2)` barycentric coordinates of `M`, strictly inside the triangle.
        M: `(n, 3)` the refraction point.
        eta: the index ratio the path was planted with.
    """

    V: np.ndarray
    N: np.ndarray
    P: np.ndarray
    L: np.ndarray
    ab: np.ndarray
    M: np.ndarray
    eta: float

    def astype(self, dtype) -> PlantedPath:
        cast = lambda x: np.asarray(x, dtype=dtype)  # noqa: E731
        return self._replace(V=cast(self.V), N=cast(self.N), P=cast(self.P), L=cast(self.L),
                             ab=cast(self.ab), M=cast(self.M))


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_triangles(rng: np.random.Generator, n: int, *, size: float = 1.0,
                     normal_spread: float = 0.3, min_angle_deg: float = 15.0):
    """`n` random triangles near the plane `z = 0` with perturbed, outward (+z) unit normals.

    Triangles are rejection-sampled to have every angle above `min_angle_deg` (no slivers:
    the stress suite makes those on purpose). Returns `(V, N)` in float64.
    """
    V = np.empty((0, 3, 3))
    while len(V) < n:
        cand = rng.uniform(-size, size, (2 * n, 3, 3))
        cand[..., 2] *= 0.15
        e = [cand[:, (k + 1) % 3] - cand[:, k] for k in range(3)]
        ang = []
        for k in range(3):
            u, w = -e[(k + 2) % 3], e[k]
            c = np.sum(u * w, -1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(w, axis=-1))
            ang.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
        ok = np.min(np.stack(ang, -1), -1) > min_angle_deg
        # counter-clockwise seen from +z, so that the geometric normal points up like N
        nz = np.cross(e[0], -e[2])[:, 2]
        V = np.concatenate([V, cand[ok & (nz > 0)]])[:n]
    N = _unit(np.array([0.0, 0.0, 1.0]) + normal_spread * rng.normal(size=(n, 3, 3)))
    N[..., 2] = np.abs(N[..., 2])
    return V, _unit(N)


def _refract_np(I, N, eta):
    """Float64 numpy GLSL refract, written independently of `geometry.refract`."""
    cos_i = np.sum(N * I, -1, keepdims=True)
    k = 1 - eta**2 * (1 - cos_i**2)
    out = eta * I - (eta * cos_i + np.sqrt(np.maximum(k, 0))) * N
    return np.where(k >= 0, out, 0.0)


def planted_paths(seed: int, n: int, *, eta: float = 1.333, max_angle_deg: float = 40.0,
                  depth: tuple[float, float] = (0.2, 2.0), height: tuple[float, float] = (0.5, 5.0),
                  normal_spread: float = 0.3) -> PlantedPath:
    """`n` refracted paths with known solution `M` (float64).

    Pick a triangle, an interior `ab`, the shading normal `n_s` there, and a direction
    `w_P` into the medium within `max_angle_deg` of `-n_s` (below the critical angle for
    water, 48.6 deg); refract `-w_P` to get `w_L` and place `L = M + d_L w_L`.
    """
    rng = np.random.default_rng(seed)
    V, N = random_triangles(rng, n, normal_spread=normal_spread)
    w = rng.dirichlet([2.0, 2.0, 2.0], n)
    ab = w[:, 1:]
    M = V[:, 0] + ab[:, :1] * (V[:, 1] - V[:, 0]) + ab[:, 1:] * (V[:, 2] - V[:, 0])
    n_tilde = N[:, 0] + ab[:, :1] * (N[:, 1] - N[:, 0]) + ab[:, 1:] * (N[:, 2] - N[:, 0])
    n_s = _unit(n_tilde)
    # w_P in a cone around -n_s; also keep it below the geometric plane side.
    cos_max = np.cos(np.radians(max_angle_deg))
    cos_t = rng.uniform(cos_max, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    helper = np.where(np.abs(n_s[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    s = _unit(np.cross(n_s, helper))
    t = np.cross(n_s, s)
    sin_t = np.sqrt(1 - cos_t**2)[:, None]
    w_P = -cos_t[:, None] * n_s + sin_t * (np.cos(phi)[:, None] * s + np.sin(phi)[:, None] * t)
    w_L = _refract_np(-w_P, -n_s, eta)
    P = M + rng.uniform(*depth, (n, 1)) * w_P
    L = M + rng.uniform(*height, (n, 1)) * _unit(w_L)
    return PlantedPath(V=V, N=N, P=P, L=L, ab=ab, M=M, eta=eta)


def line_plane_barycentric(V, P, L):
    """Barycentric `(a, b)` of `M0`, where line `PL` meets the triangle's plane (seed 001 §3.4.2).

    Float64 numpy reference: solves `P + s (L - P) = V0 + a E1 + b E2`.
    """
    E1, E2 = V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]
    A = np.stack([E1, E2, -(L - P)], -1)
    sol = np.linalg.solve(A, (P - V[:, 0])[..., None])[..., 0]
    return sol[:, :2]


class PlantedMeshPaths(NamedTuple):
    """Refracted paths planted on a mesh: `P -> M -> L` refracts at `M` (face, ab).

    Attributes: `P`, `L`, `M` `(n, 3)`; `face` `(n,)`; `ab` `(n, 2)` (all float64 numpy).
    """

    P: np.ndarray
    L: np.ndarray
    M: np.ndarray
    face: np.ndarray
    ab: np.ndarray


def planted_mesh_paths(mesh, n: int, seed: int, *, eta: float = 1.333, max_angle_deg: float = 35.0,
                       depth: tuple[float, float] = (0.2, 0.9),
                       height: tuple[float, float] = (1.0, 4.0), margin: float = 0.15):
    """`n` paths with a known refraction point on random faces of `mesh` (float64).

    Faces are drawn among those whose centroid lies at least `margin` of the mesh's xy
    extent inside its bounding box (so a walk from `M0` does not start at the boundary).
    `w_P` lies within `max_angle_deg` of `-n_s` (below water's critical angle, 48.6 deg).
    """
    rng = np.random.default_rng(seed)
    Vx = np.asarray(mesh.vertices, np.float64)
    Fx = np.asarray(mesh.faces)
    Nx = np.asarray(mesh.normals, np.float64)
    cen = Vx[Fx].mean(1)
    lo, hi = Vx.min(0), Vx.max(0)
    span = hi - lo
    inner = np.all((cen[:, :2] > lo[:2] + margin * span[:2]) & (cen[:, :2] < hi[:2] - margin * span[:2]), -1)
    faces = rng.choice(np.nonzero(inner)[0], n)
    V, N = Vx[Fx[faces]], Nx[Fx[faces]]
    ab = rng.dirichlet([2.0, 2.0, 2.0], n)[:, 1:]
    M = V[:, 0] + ab[:, :1] * (V[:, 1] - V[:, 0]) + ab[:, 1:] * (V[:, 2] - V[:, 0])
    n_s = _unit(N[:, 0] + ab[:, :1] * (N[:, 1] - N[:, 0]) + ab[:, 1:] * (N[:, 2] - N[:, 0]))
    cos_t = rng.uniform(np.cos(np.radians(max_angle_deg)), 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    helper = np.where(np.abs(n_s[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    s = _unit(np.cross(n_s, helper))
    t = np.cross(n_s, s)
    sin_t = np.sqrt(1 - cos_t**2)[:, None]
    w_P = -cos_t[:, None] * n_s + sin_t * (np.cos(phi)[:, None] * s + np.sin(phi)[:, None] * t)
    w_L = _unit(_refract_np(-w_P, -n_s, eta))
    P = M + rng.uniform(*depth, (n, 1)) * w_P
    L = M + rng.uniform(*height, (n, 1)) * w_L
    return PlantedMeshPaths(P=P, L=L, M=M, face=faces.astype(np.int32), ab=ab)


def refraction_angle_error(mesh, face, ab, P, L, eta: float) -> np.ndarray:
    """Angle (rad) between `refract(-w_P, -n_s, eta)` and `w_L` at `(face, ab)`, float64 numpy.

    Independent of the package's kernels: the check every solver result is judged by.
    Returns `pi` where the refraction is total internal reflection.
    """
    Vx = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)[face]]
    Nx = np.asarray(mesh.normals, np.float64)[np.asarray(mesh.faces)[face]]
    ab = np.asarray(ab, np.float64)
    a, b = ab[:, :1], ab[:, 1:]
    M = Vx[:, 0] + a * (Vx[:, 1] - Vx[:, 0]) + b * (Vx[:, 2] - Vx[:, 0])
    n_s = _unit(Nx[:, 0] + a * (Nx[:, 1] - Nx[:, 0]) + b * (Nx[:, 2] - Nx[:, 0]))
    w_P = _unit(np.asarray(P, np.float64) - M)
    w_L = _unit(np.asarray(L, np.float64) - M)
    r = _refract_np(-w_P, -n_s, eta)
    tir = np.all(r == 0, -1)
    cos = np.clip(np.sum(_unit(np.where(tir[:, None], 1.0, r)) * w_L, -1), -1, 1)
    sin = np.linalg.norm(np.cross(np.where(tir[:, None], 1.0, r), w_L), axis=-1)
    return np.where(tir, np.pi, np.arctan2(sin, cos))


def assert_solution_sane(sol, tol: float, slack: float) -> None:
    """Checks every solver test shares: no NaN/Inf in any field, `found` exactly where
    `status == FOUND` (a named code), `|residual| <= tol` where found, and the returned
    barycentrics inside the face up to `slack`."""
    from .solvers import Status

    for name in ("point", "barycentric", "residual", "start_point", "iterations", "crossed"):
        assert np.all(np.isfinite(np.asarray(getattr(sol, name)))), name
    status = np.asarray(sol.status)
    assert set(np.unique(status)) <= {s.value for s in Status}
    found = np.asarray(sol.found)
    np.testing.assert_array_equal(found, status == Status.FOUND)
    assert np.all(np.abs(np.asarray(sol.residual)[found]) <= tol)
    ab = np.asarray(sol.barycentric)[found]
    assert np.all(ab >= -slack) and np.all(ab.sum(-1) <= 1 + slack)


def _fresnel_T_np(cos_i, eta):
    """Unpolarised Fresnel transmittance, `eta = n_i / n_t`, numpy float64 (independent)."""
    sin_t = eta * np.sqrt(np.maximum(1 - cos_i**2, 0))
    cos_t = np.sqrt(np.maximum(1 - sin_t**2, 0))
    r_s = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    r_p = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return 1 - (r_s**2 + r_p**2) / 2


def flat_interface_irradiance(P, L, z_surface: float, eta: float, intensity: float = 1.0,
                              sigma_t: float = 0.0, return_point: bool = False):
    """Exact irradiance on a horizontal receiver at `P` under a flat interface `z = z_surface`.

    Independent of the package's transport code (float64 numpy): with light height
    `h = L_z - z_surface`, receiver depth `d = z_surface - P_z` and horizontal distance
    `rho`, the ray leaving the light at angle `theta_a` from the vertical lands at
    `rho(theta_a) = h tan(theta_a) + d tan(theta_w)`, `sin(theta_a) = eta sin(theta_w)`;
    `theta_a` is found by bisection. The flux `I_e sin(theta_a) dtheta_a dphi` lands on the
    horizontal area `rho drho dphi`, so `E = I_e T sin(theta_a) / (rho drho/dtheta_a)`,
    with `drho/dtheta_a = h / cos^2(theta_a) + d cos(theta_a) / (eta cos^3(theta_w))` and
    the exact Fresnel `T`; at `rho = 0` the limit `I_e T / (h + d/eta)^2`. With
    `return_point`, also the refraction point `M` (on an unbounded interface: a mesh of
    finite extent has no path where `M` lies outside it).
    """
    P, L = np.asarray(P, np.float64), np.broadcast_to(np.asarray(L, np.float64), np.shape(P))
    h = L[..., 2] - z_surface
    d = z_surface - P[..., 2]
    rho = np.linalg.norm(P[..., :2] - L[..., :2], axis=-1)
    lo, hi = np.zeros_like(rho), np.full_like(rho, np.pi / 2 * (1 - 1e-12))
    for _ in range(200):
        mid = (lo + hi) / 2
        sin_w = np.sin(mid) / eta
        r = h * np.tan(mid) + d * sin_w / np.sqrt(1 - sin_w**2)
        lo, hi = np.where(r < rho, mid, lo), np.where(r < rho, hi, mid)
    th_a = (lo + hi) / 2
    cos_a = np.cos(th_a)
    cos_w = np.sqrt(1 - (np.sin(th_a) / eta) ** 2)
    drho = h / cos_a**2 + d * cos_a / (eta * cos_w**3)
    T = _fresnel_T_np(cos_a, 1 / eta)
    on_axis = rho <= 1e-12 * (h + d)
    E = np.where(on_axis, T / (h + d / eta) ** 2,
                 T * np.sin(th_a) / np.where(on_axis, 1, rho * drho))
    E = intensity * E * np.exp(-sigma_t * d / cos_w)
    if not return_point:
        return E
    u = (P[..., :2] - L[..., :2]) / np.where(on_axis, 1, rho)[..., None]
    M_xy = L[..., :2] + (h * np.tan(th_a))[..., None] * u
    return E, np.concatenate([M_xy, np.full(M_xy.shape[:-1] + (1,), z_surface)], -1)


def partly_covered_floor(dtype, *, n_triangles: int = 512, n: int = 16, half: float = 3.5):
    """A wavy pool (water to |x|, |y| = 2.1 m) over an `n x n` receiver grid on a floor to
    `half` m, every 4th receiver 0.3 m above the water: many segments P -> L miss the
    surface (`NO_CROSSING`). Returns `(mesh, P, L)` (shared by the features tests and
    benchmark)."""
    import jax.numpy as jnp

    from . import scenes

    scene = scenes.wavy_pool(n_triangles, n_receivers=16, dtype=dtype)
    u = (np.arange(n) + 0.5) / n * 2 * half - half
    X, Y = np.meshgrid(u, u, indexing="xy")
    z = np.where(np.arange(n * n) % 4 == 0, 0.3, -1.0)
    P = jnp.asarray(np.stack([X.ravel(), Y.ravel(), z], -1), dtype)
    return scene.surface, P, scene.lights.endpoint(P)
