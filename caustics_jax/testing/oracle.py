"""The numpy float64 oracle: math.md transcribed once, independently of the JAX kernels.

Tests and experiments judge the package against these functions. They are written from
math.md and the papers, in plain numpy float64, and call no JAX kernel: a wrong sign or
a misprinted line in `geometry.py`, `objectives.py` or the solvers then shows up as a
disagreement instead of being reproduced on both sides. For the same reason they follow
the textbook form of each formula, not the regrouping the kernels use for accuracy
(`refract`'s `k` is GLSL's `1 - eta^2 (1 - cos^2)` here, not the kernel's cancellation-free
`(1 - eta)(1 + eta) + (eta cos)^2`).

Every formula appears once in this module; the planted-path generators
(`testing.planted`), the stress suite and the experiments build on it.
"""

from __future__ import annotations

import dataclasses

import numpy as np


def unit(v):
    """`v / |v|` along the last axis."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def refraction_discriminant(cos_i, eta):
    """GLSL `refract`'s `k = 1 - eta^2 (1 - cos_i^2)` (math.md §1); negative under TIR."""
    return 1 - eta**2 * (1 - cos_i**2)


def refract(I, N, eta):
    """GLSL `refract(I, N, eta)` (math.md §1; seed 002 eq. 3.1-3.2).

    `I` unit incident direction, `N` unit normal with `dot(N, I) <= 0`, `eta` the ratio
    incident / transmitted (broadcast against `I[..., :1]`). Returns
    `eta I - (eta dot(N, I) + sqrt(k)) N`, or the zero vector where `k < 0`.
    """
    cos_i = np.sum(N * I, -1, keepdims=True)
    k = refraction_discriminant(cos_i, eta)
    out = eta * I - (eta * cos_i + np.sqrt(np.maximum(k, 0))) * N
    return np.where(k >= 0, out, 0.0)


def barycentric_point(V, ab):
    """`M = V0 + a (V1 - V0) + b (V2 - V0)` (seed 001 eq. 3); `V (..., 3, 3)`, `ab (..., 2)`."""
    a, b = ab[..., :1], ab[..., 1:]
    return V[..., 0, :] + a * (V[..., 1, :] - V[..., 0, :]) + b * (V[..., 2, :] - V[..., 0, :])


def interpolated_normal(N, ab):
    """Unnormalised `n~ = n0 + a (n1 - n0) + b (n2 - n0)` (seed 001 eq. 6-8; math.md §1)."""
    return barycentric_point(N, ab)


def shading_normal(N, ab):
    """`n_s = n~ / |n~|` (math.md §1)."""
    return unit(interpolated_normal(N, ab))


def inside_triangle(ab, tol=0.0):
    """`a >= -tol`, `b >= -tol`, `a + b <= 1 + tol` (seed 001 eq. 3; math.md §1)."""
    a, b = ab[..., 0], ab[..., 1]
    return (a >= -tol) & (b >= -tol) & (a + b <= 1 + tol)


def triple_product(V, N, P, L, ab, relative: bool = False):
    """The coplanarity constraint `n~ . (PL x PM)` at `ab` (seed 001 eq. 9; math.md §2),
    with `M` from eq. 3 and the unnormalised `n~` of eq. 6-8: zero on the conic.

    With `relative`, `|n~ . (PL x PM)| / (|n~| |PL| |PM|)`: the sine-like residual of a
    curve point, comparable across scenes and dtypes.
    """
    M, n = barycentric_point(V, ab), interpolated_normal(N, ab)
    PL, PM = L - P, M - P
    c = np.sum(n * np.cross(PL, PM), -1)
    if not relative:
        return c
    return np.abs(c) / (np.linalg.norm(n, axis=-1) * np.linalg.norm(PL, axis=-1) * np.linalg.norm(PM, axis=-1))


def conic_on_line(coef, ab0, d):
    """The conic `A a^2 + B b^2 + C a b + D a + E b + F` (seed 001 eq. 12) on the line
    `(a, b) = ab0 + t d`: coefficients `(q2, q1, q0)` of `q2 t^2 + q1 t + q0`.

    `coef (..., 6)` in the order `A..F`, `ab0` and `d` `(..., 2)`. On `a = a0`
    (`ab0 = (a0, 0)`, `d = (0, 1)`) this is `B b^2 + (C a0 + E) b + (A a0^2 + D a0 + F)`.
    """
    A, B, C, D, E, F = np.moveaxis(np.asarray(coef), -1, 0)
    x, y = ab0[..., 0], ab0[..., 1]
    dx, dy = d[..., 0], d[..., 1]
    q2 = A * dx * dx + B * dy * dy + C * dx * dy
    q1 = 2 * A * x * dx + 2 * B * y * dy + C * (x * dy + y * dx) + D * dx + E * dy
    q0 = A * x * x + B * y * y + C * x * y + D * x + E * y + F
    return q2, q1, q0


def fresnel_transmittance(cos_i, eta):
    """Unpolarised dielectric Fresnel transmittance `1 - (r_s^2 + r_p^2) / 2`, `eta = n_i / n_t`
    (the `F` of seed 001 eq. 25; math.md §6), textbook form with `sin_t = eta sin_i`."""
    sin_t = eta * np.sqrt(np.maximum(1 - cos_i**2, 0))
    cos_t = np.sqrt(np.maximum(1 - sin_t**2, 0))
    r_s = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    r_p = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return 1 - (r_s**2 + r_p**2) / 2


@dataclasses.dataclass(frozen=True)
class NumpyMesh:
    """A surface as float64 numpy arrays: what the oracle reads from any mesh.

    Attributes:
        vertices: `(V, 3)` float64.
        faces: `(F, 3)` integer vertex indices.
        normals: `(V, 3)` float64 unit vertex normals.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray

    @classmethod
    def from_mesh(cls, mesh) -> NumpyMesh:
        """Any object with `vertices`, `faces`, `normals` (a `SurfaceMesh` of either dtype:
        its values exactly, in float64)."""
        return cls(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces),
                   np.asarray(mesh.normals, np.float64))

    def triangles(self, face):
        """`(V, N)`, `(..., 3, 3)` float64: vertices and vertex normals of faces `face`."""
        idx = self.faces[face]
        return self.vertices[idx], self.normals[idx]


def refraction_angle_error(mesh, face, ab, P, L, eta: float) -> np.ndarray:
    """Angle (rad) between `refract(-w_P, -n_s, eta)` and `w_L` at `(face, ab)` (math.md §1, §4).

    The check every solver result is judged by. `mesh` is anything `NumpyMesh.from_mesh`
    reads; `L` light positions or a `Directional` (then `w_L` is its direction toward the
    light, the limit itself). Returns `pi` where the refraction is total internal reflection.
    """
    V, N = NumpyMesh.from_mesh(mesh).triangles(face)
    ab = np.asarray(ab, np.float64)
    M = barycentric_point(V, ab)
    n_s = shading_normal(N, ab)
    w_P = unit(np.asarray(P, np.float64) - M)
    # A directional light (caustics_jax.Directional): w_L is its constant `toward`, the
    # limit of L at infinity itself (math.md §9), not a far point.
    toward = getattr(L, "toward", None)
    w_L = np.broadcast_to(toward, M.shape) if toward is not None else unit(np.asarray(L, np.float64) - M)
    r = refract(-w_P, -n_s, eta)
    tir = np.all(r == 0, -1)
    cos = np.clip(np.sum(unit(np.where(tir[:, None], 1.0, r)) * w_L, -1), -1, 1)
    sin = np.linalg.norm(np.cross(np.where(tir[:, None], 1.0, r), w_L), axis=-1)
    return np.where(tir, np.pi, np.arctan2(sin, cos))


def refraction_rounding_bound(mesh, face, ab, P, eta: float, dtype) -> np.ndarray:
    """First-order rounding bound (rad) of `refract(-w_P, -n_s, eta)` in `dtype` at `(face, ab)`.

    In GLSL `refract` (math.md §1) `k = 1 - eta^2 (1 - c^2)`, `c = w_P . n_s`; a rounding
    `dc ~ eps` of `c` moves `k` by `2 eta^2 c dc` and `sqrt(k)` by `eta^2 c dc / sqrt(k)`,
    so the refracted direction (and the signed sine `f`) carries an error of about
    `eta^2 eps / sqrt(k)` that no solver can remove. It exceeds the float32 acceptance
    tolerance (1e-5) within about 2e-4 of `k = 0`, i.e. near the critical angle.
    `mesh` is anything `NumpyMesh.from_mesh` reads; float64 evaluation.
    """
    V, N = NumpyMesh.from_mesh(mesh).triangles(face)
    ab = np.asarray(ab, np.float64)
    c = np.sum(unit(np.asarray(P, np.float64) - barycentric_point(V, ab)) * shading_normal(N, ab), -1)
    k = refraction_discriminant(c, eta)
    return eta**2 * float(np.finfo(dtype).eps) / np.sqrt(np.maximum(k, np.finfo(np.float64).tiny))


def flat_interface_irradiance_directional(toward, eta: float, E_perp: float = 1.0):
    """Exact irradiance on a horizontal receiver under a flat horizontal interface lit by a
    directional light (math.md §9): the parallel beam's irradiance on the surface,
    `E_perp cos(theta_i)`, times the Fresnel transmittance `T(theta_i)`; below the surface
    the beam stays parallel, so a horizontal receiver gets the same flux per area.
    `toward`: unit vector toward the light (`Directional.toward`)."""
    cos_i = float(np.asarray(toward, np.float64)[2])
    return E_perp * cos_i * fresnel_transmittance(cos_i, 1 / eta)


def flat_interface_irradiance(P, L, z_surface: float, eta: float, intensity: float = 1.0,
                              sigma_t: float = 0.0, return_point: bool = False):
    """Exact irradiance on a horizontal receiver at `P` under a flat interface `z = z_surface`
    (math.md §6, without the paraxial approximation).

    With light height `h = L_z - z_surface`, receiver depth `d = z_surface - P_z` and
    horizontal distance `rho`, the ray leaving the light at angle `theta_a` from the
    vertical lands at `rho(theta_a) = h tan(theta_a) + d tan(theta_w)`,
    `sin(theta_a) = eta sin(theta_w)`; `theta_a` is found by bisection. The flux
    `I_e sin(theta_a) dtheta_a dphi` lands on the horizontal area `rho drho dphi`, so
    `E = I_e T sin(theta_a) / (rho drho/dtheta_a)`, with
    `drho/dtheta_a = h / cos^2(theta_a) + d cos(theta_a) / (eta cos^3(theta_w))` and the
    exact Fresnel `T`; at `rho = 0` the limit `I_e T / (h + d/eta)^2`. Beer-Lambert
    attenuation `exp(-sigma_t d / cos(theta_w))`. With `return_point`, also the refraction
    point `M` (on an unbounded interface: a mesh of finite extent has no path where `M`
    lies outside it).
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
    T = fresnel_transmittance(cos_a, 1 / eta)
    on_axis = rho <= 1e-12 * (h + d)
    E = np.where(on_axis, T / (h + d / eta) ** 2,
                 T * np.sin(th_a) / np.where(on_axis, 1, rho * drho))
    E = intensity * E * np.exp(-sigma_t * d / cos_w)
    if not return_point:
        return E
    u = (P[..., :2] - L[..., :2]) / np.where(on_axis, 1, rho)[..., None]
    M_xy = L[..., :2] + (h * np.tan(th_a))[..., None] * u
    return E, np.concatenate([M_xy, np.full(M_xy.shape[:-1] + (1,), z_surface)], -1)
