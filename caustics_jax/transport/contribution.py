"""Caustic irradiance at a receiver from a solved path (seed 001 eq. 25, corrected per math.md §6).

Seed 001 eq. 25 weights a path `P -> M -> L` by `I_e F A rho / D`. As irradiance at `P`
(flux per unit receiver area) from a point light of intensity `I_e` (W/sr), the formula
this module uses is

    E(P) = eta^2 T(M) A(d_P) cos(theta_P) I_e / D

- `D` the distance correction factor (eq. 26-33, `ray_differential_D`): the area on the
  plane at `L` orthogonal to `w_L` per unit solid angle of directions leaving `P`.
- `eta^2`: D is measured from the receiver's side (directions in water), while `I_e` is
  per solid angle at the light (in air). Conservation of etendue across the interface,
  `eta_in^2 dA_P dw_P = eta_out^2 dA_L dw_L`, turns `1/D` (solid angle at `P` per area
  at `L`) into `eta^2 / D` (solid angle at `L` per area at `P`).
- `T` the exact unpolarised Fresnel transmittance at `M` (the `F` of eq. 25), for light
  arriving from the light's side at `cos = w_L . n_s` with index ratio `1 / eta`.
- `cos(theta_P) = -w_P . n_P`: eq. 25 gives irradiance on a plane orthogonal to the ray;
  a receiver with normal `n_P` catches `cos(theta_P)` of it (0 when it faces away).
- `A = exp(-sigma_t d_P)` Beer-Lambert attenuation in the medium (1 by default).

The paper's `rho` (BRDF) turns irradiance into reflected radiance and is left to the
caller. The formula is established by experiment, not assumed: `photon_irradiance`
(brute-force photon tracing) and the photon-differential irradiance agree with it
(`docs/irradiance.md`, `experiments/irradiance_agreement.py`, `tests/transport/`).
On a flat interface at normal incidence it reduces to math.md §6's paraxial
`E = I_e T / (h + d/eta)^2` (light height `h`, receiver depth `d`).
"""

from __future__ import annotations

from typing import cast

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ..accel.prepared import PreparedSurface, prepare
from ..math.barycentric import barycentric_coordinates, barycentric_point
from ..math.geometry import beer_lambert, dot, fresnel_transmittance, norm, unit_vector
from ..math.objectives import path_vectors
from ..runtime.arguments import check_bool, check_fits, check_points, check_real, real_array
from ..runtime.kernel_contract import float_inputs, in_domain
from ..runtime.lanes import compact_index, scatter_lanes
from ..solvers import Exhaustive, ExhaustiveSolution, Solution, Trace
from ..solvers._solve import returns_every_path, solve_local
from ..surface.features import check as check_features
from ..surface.lights import Directional, light_points, scene_size
from ..surface.mesh import SurfaceMesh
from .differentials import ray_differential_D
from .visibility import path_visible


@float_inputs("V", "N", "P", "L", "ab", "receiver_normal", params=("eta", "intensity", "sigma_t"),
               positive=("eta",), nonnegative=("intensity", "sigma_t"))
@jax.jit
def path_irradiance(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
    ab: Float[Array, "*batch 2"],
    eta,
    intensity,
    receiver_normal: Float[Array, "*batch 3"],
    sigma_t=0.0,
    at_infinity=False,
) -> tuple[Float[Array, "*batch"], Bool[Array, "*batch"]]:
    """Irradiance at `P` through refraction point `ab`: `eta^2 T A cos(theta_P) I_e / D`.

    Formed as `eta^2 T A cos(theta_P) (I_e / d_L^2) / (D / d_L^2)`
    (`ray_differential_D(..., normalized=True)`), finite for far lights in float32.
    `at_infinity` (bool, per lane or one): True where `L` stands for a light at infinity
    (a directional light's point on the ray, `surface/lights.py`) and `intensity` is its
    irradiance `E_perp` on a plane perpendicular to the rays (W/m^2), the limit of
    `I_e / d_L^2`: `E = eta^2 T A cos(theta_P) E_perp / (D / d_L^2)` (math.md §9).

    Seed 001 eq. 25 with the factors math.md §6 says it leaves out (module docstring).
    `receiver_normal` is normalised here (any finite length, `unit_vector`). Returns
    `(E, valid)`; `E = 0` where `valid` is False (`ray_differential_D` invalid: TIR,
    grazing, degenerate; a zero or non-finite `receiver_normal`, which had given `E = 0`
    valid, as had a float32 one of length 1e20 or 1e-20) and where the receiver faces away
    from the arriving light (there `valid` stays True: the irradiance is 0). `eta > 0`,
    `intensity >= 0`, `sigma_t >= 0`, all finite: concrete values outside are refused
    (`ValueError`), traced ones give invalid lanes (`intensity = inf` had given `E = inf`
    valid).
    """
    _, n_s, w_P, w_L, _ = path_vectors(V, N, P, L, ab)
    dtype = w_P.dtype
    eta, intensity, sigma_t = (jnp.asarray(x, dtype) for x in (eta, intensity, sigma_t))
    n_P, ok_normal = unit_vector(jnp.asarray(receiver_normal, dtype))
    # traced parameters outside their domain mark the lane invalid (concrete ones are refused)
    ok = ok_normal & in_domain(eta, lo=0, strict=True) & in_domain(intensity, lo=0) & in_domain(sigma_t, lo=0)
    D_n, valid = ray_differential_D(V, N, P, L, ab, eta, normalized=True)
    T = fresnel_transmittance(dot(w_L, n_s), 1 / eta)
    cos_P = jnp.maximum(-dot(w_P, n_P), 0)
    M = barycentric_point(V, ab)
    A = beer_lambert(sigma_t, norm(P - M))
    d_L = norm(L - M)
    # I_e / d_L^2: the irradiance perpendicular to the rays at M (a directional light's E_perp)
    E_perp = jnp.where(at_infinity, intensity, intensity / jnp.where(d_L > 0, d_L, 1) ** 2)
    ok = ok & valid & (D_n > 0)
    E = eta**2 * T * A * cos_P * E_perp / jnp.where(ok, D_n, 1)
    return jnp.where(ok, E, 0), ok


def _lane_count(P: np.ndarray, L: np.ndarray) -> int:
    """Lanes of `P`, `L` broadcast as `solve` does (`(3,)` is one lane)."""
    try:
        shape = np.broadcast_shapes(P.reshape(-1, 3).shape if P.ndim == 1 else P.shape,
                                    L.reshape(-1, 3).shape if L.ndim == 1 else L.shape)
    except ValueError:
        raise ValueError(f"P {P.shape} and L {L.shape} do not broadcast") from None
    if len(shape) != 2:
        raise ValueError(f"P and L must broadcast to (N, 3), got {shape}")
    return shape[0]


def check_receiver_normal(receiver_normal, n: int) -> np.ndarray:
    """`(n, 3)` unit receiver normals from `(3,)` or `(n, 3)` finite, non-zero input of any
    length (host, float64; shared by `irradiance` and the SMS estimators)."""
    n_P = real_array("receiver_normal", receiver_normal)
    if n_P.shape[-1:] != (3,):
        raise ValueError(f"receiver_normal must have shape (3,) or (N, 3), got {n_P.shape}")
    try:
        n_P = np.broadcast_to(n_P, (n, 3))
    except ValueError as exc:
        raise ValueError(f"receiver_normal {n_P.shape} does not broadcast to ({n}, 3)") from exc
    # Normalised here, in float64 and scaled by the largest component first, so that a
    # finite normal of any length (1e-160 or 1e160) gives the unit normal, also once cast
    # to float32 (safe_normalize of a float32 1e20 vector squares past the range).
    big = np.max(np.abs(n_P), axis=-1, keepdims=True)
    if not np.all(np.isfinite(big)) or np.any(big == 0):
        raise ValueError("receiver_normal must be finite and non-zero")
    n_P = n_P / big
    return n_P / np.linalg.norm(n_P, axis=-1, keepdims=True)


def check_intensity(intensity) -> np.ndarray:
    """Radiant intensity (W/sr): real, finite, `>= 0`, scalar or per lane (host, float64;
    the caller checks its shape against the lanes and `check_fits` against its dtype)."""
    intensity_np = real_array("intensity", intensity)
    if not np.all(np.isfinite(intensity_np)) or np.any(intensity_np < 0):
        raise ValueError(f"intensity must be finite and >= 0 (W/sr), got {intensity!r}")
    return intensity_np


def irradiance(mesh: SurfaceMesh | PreparedSurface, P, L, *, intensity, eta: float = 1.333, receiver_normal,
               method: str = "walk", sigma_t: float = 0.0, all_paths: bool = False,
               visibility: bool = False, return_solution: bool = False, features="auto", **options):
    """Caustic irradiance (W/m^2) at receivers `P` from a point light at `L` through the surface.

    Args:
        mesh: the refractive surface (normals outward, toward the light).
        P: `(N, 3)` receivers inside the medium.
        L: `(N, 3)` or `(3,)` light position, or a `Directional(direction)` (the sun;
            surface/lights.py).
        intensity: the light's radiant intensity `I_e` (W/sr) for a point light; for a
            `Directional`, its irradiance on a plane perpendicular to the rays (W/m^2).
            Scalar or `(N,)`.
        eta: `eta_in / eta_out`.
        receiver_normal: `(3,)` or `(N, 3)` receiver normals (normalised here).
        method: the solver (`solve`'s `method`); `**options` go to it.
        sigma_t: Beer-Lambert extinction coefficient of the medium (1/m), `A = exp(-sigma_t d_P)`.
        all_paths: sum over every refracted path. Past the focal distance several paths
            reach one receiver; a single-path solver returns one of them, so only this
            sum is the total irradiance there. `method="exhaustive"` (float64) sums every
            path on the mesh (the certified reference); `method="walk"` sums every path
            on the traced curve (`solve(..., solutions="all")`, `solvers/trace.py`).
        visibility: drop paths whose segment `P -> M` or `M -> L` the surface itself
            blocks (seed 001 §4; `transport/visibility.py`, docs/irradiance.md
            "Visibility").
        return_solution: also return the solver's `Solution` (its `status` says why a
            lane has no path: none exists, or the solver failed to find it).
        features: `"auto"` (default), `None` (the general path) or a `SceneFeatures`:
            passed to `solve`, and with `compact_lanes` the D factor and the rest of
            `path_irradiance` run only on the found lanes (docs/features.md). Ignored
            with `all_paths`.

    Returns `(N,)` irradiance in the mesh's dtype, 0 where no path was found (and
    `(E, Solution)` with `return_solution`). Per path: `path_irradiance` (module
    docstring). Bad input raises `ValueError` before any solve.
    """
    intensity_np = check_intensity(intensity)
    sigma_t = check_real("sigma_t", sigma_t, 0)
    all_paths, return_solution = check_bool("all_paths", all_paths), check_bool("return_solution", return_solution)
    check_features(features)
    if all_paths and not (method in ("exhaustive", "walk", "trace") or isinstance(method, Exhaustive | Trace)):
        raise ValueError("all_paths=True sums every solution: it needs method='exhaustive' (every path "
                         "on the mesh), 'walk' or 'trace' (every path on the traced curve), or a Trace(...) or "
                         f"Exhaustive(...) object (a Walk object returns one path: use Trace(...)), got {method!r}")
    if all_paths and "solutions" in options:
        raise ValueError("all_paths=True sets solutions='all' itself: leave solutions out")
    if not isinstance(visibility, bool | np.bool_):
        raise ValueError(f"visibility must be True or False, got {visibility!r}")
    # A solver that returns every path per receiver (`Trace`, `Exhaustive(return_all=True)`,
    # `solutions="all"`) is summed only with all_paths.
    if not all_paths and returns_every_path(method, options):
        raise ValueError(f"method {method!r} with options {options} returns every path per receiver: pass "
                         "all_paths=True to sum them")
    prep = prepare(mesh)
    dtype = prep.dtype
    check_fits("intensity", intensity_np, dtype)
    check_fits("sigma_t", sigma_t, dtype)
    P_np = check_points("P", P, dtype)
    n = _lane_count(P_np, P_np if isinstance(L, Directional) else check_points("L", L, dtype))
    n_P = check_receiver_normal(receiver_normal, n)
    if intensity_np.ndim > 0 and intensity_np.shape not in ((n,), (1,)):
        raise ValueError(f"intensity must be a scalar or shape ({n},), got {intensity_np.shape}")
    # A directional light, or a point light beyond the limit distance, is at infinity for
    # its lanes: their intensity becomes the irradiance perpendicular to the rays
    # (surface/lights.py, math.md §9).
    P_lanes = np.broadcast_to(P_np.reshape(-1, 3), (n, 3))
    placed = light_points(L, P_lanes, scene_size(np.asarray(prep.mesh.vertices), P_lanes), dtype)
    at_infinity = placed.at_infinity
    intensity_np = np.where(at_infinity, np.broadcast_to(intensity_np, (n,)) * placed.gain, intensity_np)
    check_fits("intensity", intensity_np, dtype)
    # Solved and summed in the frame of `prep.local` (a far mesh moved near the origin,
    # `frames.local_origin`); only a returned Solution moves back.
    if all_paths:
        ls = solve_local(prep, P, L, eta=eta, method=method, solutions="all", **options)
        res = cast(ExhaustiveSolution, ls.result)  # every path per receiver
        E = _sum_all_paths(ls.prep, res, ls.P, ls.L, eta, intensity_np, n_P, sigma_t, visibility, at_infinity)
        return (E, cast(ExhaustiveSolution, ls.to_global()).solution) if return_solution else E
    feats = prep.features if isinstance(features, str) else features
    ls = solve_local(prep, P, L, eta=eta, method=method, features=feats, **options)
    mesh, sol, P_b, L_b = ls.prep.mesh, cast(Solution, ls.result), ls.P, ls.L
    if feats is not None and feats.compact_lanes:
        E = _found_lanes_irradiance(mesh, sol, P_b, L_b, eta, intensity_np, n_P, sigma_t, at_infinity)
    else:
        V, N = mesh.triangle(sol.triangle)
        E, _ = path_irradiance(V, N, P_b, L_b, sol.barycentric, eta, jnp.asarray(intensity_np, dtype),
                               jnp.asarray(n_P, dtype), sigma_t, at_infinity=jnp.asarray(at_infinity))
        E = jnp.where(sol.found, E, 0)
    if visibility:
        E = _visible_only(ls.prep, E, sol.found, P_b, sol.point, L_b)
    return (E, ls.to_global()) if return_solution else E


def _visible_only(prep, E, found, P, M, L):
    """`E` with the found lanes whose path the surface blocks set to 0 (only those tested)."""
    idx = np.flatnonzero(np.asarray(found))
    if idx.size == 0:
        return E
    g = jnp.asarray(idx)
    blocked = ~path_visible(prep, P[g], M[g], L[g])
    return E.at[g[blocked]].set(0) if blocked.any() else E


def _found_lanes_irradiance(mesh, sol, P, L, eta, intensity, n_P, sigma_t, at_infinity):
    """`path_irradiance` (D factor included) on the found lanes only, compacted, then
    scattered into zeros: the general path's `where(found, E, 0)` without the work."""
    n, dtype = P.shape[0], mesh.dtype
    E = jnp.zeros(n, dtype)
    idx = np.flatnonzero(np.asarray(sol.found))
    if idx.size == 0:
        return E
    if idx.size == n:  # every lane found: nothing to skip
        V, N = mesh.triangle(sol.triangle)
        return path_irradiance(V, N, P, L, sol.barycentric, eta, jnp.asarray(intensity, dtype),
                               jnp.asarray(n_P, dtype), sigma_t, at_infinity=jnp.asarray(at_infinity))[0]
    g, real = compact_index(idx)
    V, N = mesh.triangle(sol.triangle[g])
    I_e = np.broadcast_to(intensity, (n,))[g]
    E_g, _ = path_irradiance(V, N, P[g], L[g], sol.barycentric[g], eta, jnp.asarray(I_e, dtype),
                             jnp.asarray(n_P[g], dtype), sigma_t, at_infinity=jnp.asarray(at_infinity)[g])
    return scatter_lanes(E, g, real, E_g)


def _sum_all_paths(prep: PreparedSurface, res, P, L, eta, intensity, n_P, sigma_t, visibility: bool = False,
                   at_infinity=False):
    """Sum `path_irradiance` over every solution of an `ExhaustiveSolution` (only the visible
    ones with `visibility`), on the surface it was solved on."""
    mesh = prep.mesh
    pts, tris, count = np.asarray(res.all_points), np.asarray(res.all_triangles), np.asarray(res.count)
    n, width = tris.shape
    V, N = mesh.triangle(jnp.asarray(tris))
    E1, E2 = V[..., 1, :] - V[..., 0, :], V[..., 2, :] - V[..., 0, :]
    ab = barycentric_coordinates(E1, E2, jnp.asarray(pts, mesh.dtype) - V[..., 0, :])
    P_b = jnp.broadcast_to(jnp.asarray(P, mesh.dtype).reshape(-1, 1, 3), (n, width, 3))
    L_b = jnp.broadcast_to(jnp.asarray(L, mesh.dtype).reshape(-1, 1, 3), (n, width, 3))
    I_b = jnp.broadcast_to(jnp.asarray(intensity, mesh.dtype).reshape(-1, 1), (n, width))
    # arrays in the mesh's dtype, as in the single-path `irradiance` (a float64 `n_P` under
    # x64 had made a float32 mesh's sum float64; `sigma_t` is a Python float, weakly typed)
    E, _ = path_irradiance(V, N, P_b, L_b, ab, eta, I_b, jnp.asarray(n_P, mesh.dtype)[:, None, :], sigma_t,
                           at_infinity=jnp.asarray(at_infinity).reshape(-1, 1))
    used = np.arange(width)[None] < count[:, None]
    if visibility and used.any():
        lane, k = np.nonzero(used)
        visible = path_visible(prep, P_b[lane, k], jnp.asarray(pts[lane, k], mesh.dtype), L_b[lane, k])
        used[lane[~visible], k[~visible]] = False
    return jnp.sum(jnp.where(jnp.asarray(used), E, 0), axis=1)
