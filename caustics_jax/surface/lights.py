"""Lights: a point light is a position `L`; a directional light is `Directional(direction)`.

Every function that takes a light `L` (`solve`, `irradiance`, `photon_irradiance`, the SMS
estimators, the export) takes either: an array of positions `(3,)` or `(N, 3)`, or a
`Directional`. `direction` is the way the light travels (Mitsuba 3's `directional`
emitter: a sun overhead is `(0, 0, -1)`), and with a directional light `intensity=` means
the irradiance on a plane perpendicular to it (W/m^2), where for a point light it is the
radiant intensity (W/sr).

How the limit is taken (math.md §9 "Lights at infinity"). Every formula of a path
`P -> M -> L` reads the light through `L - M` or `L - P`: the unit vector `w_L` toward it
and the distance `d_L`. For a directional light `w_L` is the constant `u = -direction`
and `d_L` is infinite; the D factor and the irradiance keep their limits
(`ray_differential_D(..., normalized=True)` is `D / d_L^2`, and `E = ... E_perp / (D / d_L^2)`).
The solvers receive the light as the point `L = P + R u` on the ray from each receiver
toward the light, with `R = limit_distance(size, dtype)`: `2^(p + 3)` times the scene's
size, `p` the dtype's mantissa bits. Then `w_L` at any surface point differs from `u` by
less than `size / R = 2^-(p + 3)`, an eighth of the dtype's rounding of a unit vector, so
every objective, start point and status equals its limit to within rounding, and the
start point is found along the ray from `P` toward the light
(`tests/test_lights.py` checks both against the closed-form limit). A far point light
(a sun at 1.5e11 m) is the same computation with its own `R`.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import numpy as np

from ..runtime.arguments import check_points, real_array

__all__ = ["Directional", "PlacedLights", "light_points", "limit_distance", "scene_size"]


class Directional(eqx.Module):
    """A directional light (the sun): parallel rays travelling along `direction`.

    `direction`: `(3,)` real, finite, non-zero, normalised here (float64); the way the
    light travels (Mitsuba 3's convention: a sun overhead is `(0, 0, -1)`). Pass it as `L`
    wherever a point light's position goes; `intensity=` then means the irradiance on a
    plane perpendicular to the rays (W/m^2).
    """

    direction: np.ndarray = eqx.field(converter=lambda d: _unit("direction", d))

    @property
    def toward(self) -> np.ndarray:
        """`u = -direction`: the unit vector from the scene toward the light (`w_L`)."""
        return -self.direction


def _unit(name: str, value) -> np.ndarray:
    d = real_array(name, value)
    if d.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {d.shape}")
    big = float(np.max(np.abs(d)))
    if not np.isfinite(big) or big == 0:
        raise ValueError(f"{name} must be finite and non-zero, got {value!r}")
    d = d / big  # scaled first: a direction of any finite length normalises
    return d / np.linalg.norm(d)


def limit_distance(size: float, dtype) -> float:
    """`R = 2^(p + 3) size` (`p` the mantissa bits of `dtype`: 23 for float32, 52 for
    float64): how far along `u` a directional light is placed for a scene of extent `size`
    (module docstring). float32: 6.7e7 x size; float64: 3.6e16 x size."""
    return float(size) * 2.0 ** (np.finfo(dtype).nmant + 3)


def scene_size(vertices: np.ndarray, P: np.ndarray) -> float:
    """The extent `limit_distance` scales: the largest side of the mesh's bounding box or
    twice the farthest receiver from its centre, whichever is larger (float64, host)."""
    V = np.asarray(vertices, np.float64).reshape(-1, 3)
    if V.size == 0:
        return 1.0
    lo, hi = V.min(0), V.max(0)
    far = float(np.max(np.abs(np.asarray(P, np.float64).reshape(-1, 3) - (lo + hi) / 2), initial=0.0))
    return max(float(np.max(hi - lo)), 2 * far)


class PlacedLights(NamedTuple):
    """The light of every lane as the solvers receive it (`light_points`).

    points: `(N, 3)` float64 light points.
    at_infinity: `(N,)` True where the light is directional or a point light farther than
        `limit_distance` (then `points` lies on the ray from `P` toward it, at that
        distance).
    gain: `(N,)` what turns the caller's `intensity` into the irradiance perpendicular to
        the rays where `at_infinity`: 1 for a directional light (its intensity is that
        irradiance), `1 / |L - P|^2` for a far point light; 1 elsewhere (unused).
    """

    points: np.ndarray
    at_infinity: np.ndarray
    gain: np.ndarray


def light_points(L, P: np.ndarray, size: float, dtype, *, checked: bool = False) -> PlacedLights:
    """Each lane's light as a float64 point (`PlacedLights`), for receivers `P` `(N, 3)`
    (float64) in a scene of extent `size` (`scene_size`).

    `L`: positions `(3,)` or `(N, 3)` (checked by `check_points`) or a `Directional`. A
    directional light, and a point light farther from `P` than `R = limit_distance(size,
    dtype)`, become the point at distance `R` on the ray from `P` toward the light: every
    formula's value then equals its limit to within rounding (module docstring), and the
    solvers' products of lengths stay inside the dtype's range (a light 1e18 m away from a
    10 km pool had overflowed float32's conic products: 90% of its lanes kept their status,
    against all at 2.5e12 m). `checked=True`: `L` is already `check_points`' float64 array
    (`solve`'s boundary checked it), not checked again."""
    P = np.asarray(P, np.float64).reshape(-1, 3)
    R = limit_distance(max(size, np.finfo(np.float64).tiny), dtype)
    if isinstance(L, Directional):
        n = P.shape[0]
        return PlacedLights(P + R * L.toward, np.ones(n, bool), np.ones(n))
    L_np = L if checked else check_points("L", L, dtype)
    L_np, P_b = np.broadcast_arrays(L_np.reshape(-1, 3) if L_np.ndim == 1 else L_np, P)
    v = L_np - P_b
    big = np.max(np.abs(v), axis=-1, keepdims=True)  # scaled first: |v|^2 of 1e200 overflows
    n = P_b.shape[0]
    # No lane can be far (|v| <= sqrt(3) max|v_i|, the rounding of the norm bounded by the
    # 1e-15): every point is the light itself, and the lanes skip the normalisation below.
    if n == 0 or float(np.max(big)) * np.sqrt(3.0) * (1 + 1e-15) <= R:
        return PlacedLights(np.array(L_np), np.zeros(n, bool), np.ones(n))
    unit = v / np.where(big > 0, big, 1)
    dist = big[:, 0] * np.linalg.norm(unit, axis=-1)
    far = dist > R
    u = unit / np.maximum(np.linalg.norm(unit, axis=-1, keepdims=True), np.finfo(np.float64).tiny)
    points = np.where(far[:, None], P_b + R * u, L_np)
    with np.errstate(over="ignore", under="ignore"):
        gain = np.where(far, 1 / np.where(far, dist, 1) ** 2, 1.0)
    return PlacedLights(points, far, gain)
