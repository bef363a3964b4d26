"""Closed-form refraction points on a flat surface (`SceneFeatures.flat`).

With one constant normal `n` every coplanarity conic is the line through the projections
of `P` and `L` (seed 001 eq. 1-2, math.md §2): the refraction point `M` lies in the plane
through `P` and `L` that contains `n`. With `d = c - n.P` the depth of `P` below the
plane `n.x = c`, `h = n.L - c` the height of `L`, `P_f`, `L_f` their feet on the plane,
`rho = |L_f - P_f|` and `M = P_f + t (L_f - P_f)`, Snell's law (math.md §1, `refract`
with `eta = eta_in / eta_out`) is

    g(t) = eta t rho / sqrt((t rho)^2 + d^2) - (1 - t) rho / sqrt(((1 - t) rho)^2 + h^2) = 0,

`eta sin(theta_water) = sin(theta_air)`. `g` increases strictly on `[0, 1]` (the first
term grows, the second shrinks) with `g(0) <= 0 <= g(1)`, so the root is unique and
bisection finds it to the last bit in `nmant + 2` halvings, branch-free. No conic, no
walk; `caustics_jax.testing.flat_interface_irradiance` solves the same geometry
independently in numpy.

`M` is then located in its face by the start-point search of the vertical segment
through it (the grid DDA on a heightfield: one cell), and accepted exactly as the walk
accepts its points: `|f| <= tol` for the signed sine `f` (seed 001 eq. 21, "plane"
orientation) at the returned barycentric point. Lanes the closed form does not settle
(`P` or `L` on the plane, `M` outside the mesh, `|f| > tol`) are left to the walk.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..math.barycentric import barycentric_point
from ..math.geometry import dot, norm
from ..math.objectives import ObjectiveStatus, signed_sine_and_status
from ..surface.mesh import SurfaceMesh
from ._solution import Solution, Status


@jax.jit
def flat_root(mesh: SurfaceMesh, P, L, eta):
    """Closed-form `M` on the plane of a flat mesh (module docstring), and the segment
    `(M - d n, M + h n)` whose crossing locates it; `usable` is False where `d <= 0` or
    `h <= 0` (no transmitted path through the plane, or `P`/`L` on it)."""
    dtype = P.dtype
    n_hat = mesh.normals[0] / norm(mesh.normals[0])
    c = dot(n_hat, mesh.vertices[0])
    d = c - dot(P, n_hat)
    h = dot(L, n_hat) - c
    usable = (d > 0) & (h > 0)
    d_s, h_s = jnp.where(usable, d, 1), jnp.where(usable, h, 1)
    P_f = P + d[:, None] * n_hat
    L_f = L - h[:, None] * n_hat
    rho = norm(L_f - P_f)
    eta = jnp.asarray(eta, dtype)

    def g(t):
        x, y = t * rho, (1 - t) * rho
        return eta * x / jnp.sqrt(x * x + d_s * d_s) - y / jnp.sqrt(y * y + h_s * h_s)

    def halve(_, lohi):
        lo, hi = lohi
        mid = (lo + hi) / 2
        below = g(mid) < 0
        return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

    zeros = jnp.zeros_like(rho)
    lo, hi = jax.lax.fori_loop(0, jnp.finfo(dtype).nmant + 2, halve, (zeros, zeros + 1))
    t = (lo + hi) / 2
    M = P_f + t[:, None] * (L_f - P_f)
    return M, M - d_s[:, None] * n_hat, M + h_s[:, None] * n_hat, usable


@jax.jit
def flat_solution(mesh: SurfaceMesh, P, L, eta, tol, usable, located, start_face, start_ab):
    """The `Solution` of the closed-form lanes and the mask of lanes it settles (FOUND)."""
    face, ab, hit = located
    V, N = mesh.triangle(face)
    eta = jnp.asarray(eta, P.dtype)
    f, st = signed_sine_and_status(V, N, P, L, ab, eta, orientation="plane")
    good = usable & hit & (st == ObjectiveStatus.OK) & (jnp.abs(f) <= jnp.asarray(tol, P.dtype))
    V0, _ = mesh.triangle(start_face)
    sol = Solution(
        point=barycentric_point(V, ab),
        triangle=face.astype(jnp.int32),
        barycentric=ab,
        found=good,
        status=jnp.where(good, Status.FOUND, Status.NOT_CONVERGED).astype(jnp.int32),
        iterations=jnp.full(P.shape[:1], jnp.finfo(P.dtype).nmant + 2, jnp.int32),
        residual=f,
        crossed=jnp.zeros(P.shape[:1], jnp.int32),
        start_point=barycentric_point(V0, start_ab),
    )
    return sol, good
