"""Specular manifold sampling (SMS) irradiance estimators on the testbed's Newton solver:
the comparison seed 001 makes in §5 (Fig. 7-8) against Zeltner et al. 2020.

The caustic irradiance at a receiver is a sum over every refracted path,
`E(P) = sum_k E_k` with `E_k` = `path_irradiance` at refraction point `M_k` (seed 001
eq. 25 with math.md §6's factors). A Newton solve (`caustics_jax.Newton`, the MNEE/SMS
baseline) started at a random point of the surface converges to one solution `M_k` with
an unknown probability `p_k` (its basin's share of the surface area), or fails. SMS
(Zeltner et al. 2020, "Specular manifold sampling for rendering high-frequency caustics
and glints", §4.3 and §5) turns that into estimators of `E`:

- **biased** (`sms_biased`): `k` solves from independent random starts; the distinct
  solutions found are summed, each once. Solutions with small basins are missed with
  probability `(1 - p_k)^k`: the estimate is low, and converges as `k` grows.
- **unbiased** (`sms_unbiased`): one solve gives `M_k` (with probability `p_k`); then
  Bernoulli trials, more solves from fresh random starts until `M_k` is found again: the
  number of trials `T` is geometric with mean `1 / p_k`, so `E_k T` has expectation
  `sum_k p_k E_k / p_k = E`. As in Mitsuba 3's SMS (`manifold_ss.cpp`), the count starts at
  1 and grows by one per trial that misses, and a lane that reaches `max_trials` gets
  weight 0 (a bias of at most `sum_k E_k (1 - p_k)^max_trials`).

Random starts are uniform over the surface area (face by area, uniform barycentrics),
as Mitsuba 3's implementation samples them ("uniformly samples on the surface of the
shape"). Solutions count as "the same" within `same_radius` (m). A Newton point counts
only where the refracted ray points towards `L` (`objectives.bracket_objective` status
OK): the half-vector constraint also vanishes on non-physical configurations.

Both are seeded (`seed`, an integer in [0, 2^31 - 1]), vectorised over receivers, and
return the number of Newton solves each receiver used, the cost they compare by.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..accel.prepared import PreparedSurface, prepare
from ..accel.start_points import StartPoint
from ..math.objectives import ObjectiveStatus, bracket_objective
from ..runtime.arguments import check_eta, check_fits, check_int, check_real
from ..runtime.blocks import lanes_per_block
from ..runtime.precision import check_mesh_dtype
from ..solvers import Newton, solve
from ..solvers._solve import check_lanes
from ..surface.features import check as check_features
from ..surface.lights import light_points, scene_size
from ..surface.mesh import SurfaceMesh
from .contribution import check_intensity, check_receiver_normal, path_irradiance


class EstimatorResult(NamedTuple):
    """An irradiance estimate per receiver.

    Attributes:
        irradiance: `(N,)` the estimate (W/m^2).
        solves: `(N,)` Newton solves spent on the receiver.
        paths: `(N,)` biased: distinct solutions summed; unbiased: the Bernoulli trial
            count `T` (the estimated `1 / p_k`; 0 where the first solve failed or the cap
            was reached).
    """

    irradiance: np.ndarray
    solves: np.ndarray
    paths: np.ndarray


def surface_starts(mesh: SurfaceMesh, n: int, rng: np.random.Generator) -> StartPoint:
    """`n` start points uniform over the surface area: a face with probability proportional
    to its area, then `a = sqrt(u1) (1 - u2)`, `b = sqrt(u1) u2` (uniform in the triangle,
    seed 001 eq. 3 coordinates)."""
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"mesh must be a SurfaceMesh, got {type(mesh).__name__}")
    check_mesh_dtype(mesh.dtype)
    n = check_int("n", n, 0)
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator (np.random.default_rng(seed)), got {rng!r}")
    V = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)]
    area = np.linalg.norm(np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]), axis=-1) / 2
    face = rng.choice(len(area), size=n, p=area / area.sum())
    u1, u2 = rng.random(n), rng.random(n)
    r = np.sqrt(u1)
    ab = np.stack([r * (1 - u2), r * u2], -1)
    return StartPoint(jnp.asarray(face, jnp.int32), jnp.asarray(ab, mesh.dtype), jnp.ones(n, bool))


@jax.jit
def _forward(mesh, face, ab, P, L, eta):
    """True where the point refracts towards `L` (status OK: not TIR, not backward)."""
    V, N = mesh.triangle(face)
    _, st, _ = jax.vmap(lambda v, n_, p, l, x: bracket_objective(v, n_, p, l, x[None], eta))(V, N, P, L, ab)
    return st[:, 0] == ObjectiveStatus.OK


def _newton_from(prep: PreparedSurface, P, L, eta, start: StartPoint, newton: Newton, features):
    """One Newton solve per lane from `start`; `(found, point, face, ab)` numpy, `found` only
    for forward refraction points."""
    sol = solve(prep, P, L, eta=eta, method=newton, start=tuple(start), features=features)
    face, ab = sol.triangle, sol.barycentric
    found = np.asarray(sol.found) & np.asarray(_forward(prep.mesh, jnp.maximum(face, 0), ab, P, L, eta))
    return found, np.asarray(sol.point, np.float64), np.asarray(face), np.asarray(ab)


def _path_irradiance(mesh, face, ab, P, L, eta, intensity, n_P, sigma_t, at_infinity):
    V, N = mesh.triangle(jnp.asarray(face))
    E, _ = path_irradiance(V, N, P, L, jnp.asarray(ab, mesh.dtype), eta, jnp.asarray(intensity, mesh.dtype),
                           jnp.asarray(n_P, mesh.dtype), sigma_t, at_infinity=jnp.asarray(at_infinity))
    return np.asarray(E, np.float64)


def _inputs(mesh, P, L, intensity, receiver_normal, eta, sigma_t, same_radius):
    """The estimators' arguments, checked as `irradiance` checks them (docs/input_contract.md);
    the surface and the points come back in the frame of `prep.local`, as `irradiance`
    works (a far mesh moved near the origin, `frames.local_origin`); a `Directional` `L`
    as its points on the receivers' rays (surface/lights.py), `intensity` its `E_perp`."""
    prep = prepare(mesh)
    dtype = prep.dtype
    L_in = L
    P, L = check_lanes(prep.mesh, P, L, prep.origin)  # (N, 3) each, as `solve` takes them
    n = P.shape[0]
    n_P = check_receiver_normal(receiver_normal, n)
    I_e = check_fits("intensity", check_intensity(intensity), dtype)
    try:
        I_e = np.broadcast_to(I_e, (n,))
    except ValueError:
        raise ValueError(f"intensity must be a scalar or shape ({n},), got {I_e.shape}") from None
    check_fits("eta", check_eta(eta), dtype, positive=True)
    check_fits("sigma_t", check_real("sigma_t", sigma_t, 0), dtype)
    check_real("same_radius", same_radius, 0, lo_open=True)
    # A light at infinity (directional, or a point beyond the limit distance): its lanes'
    # intensity becomes the irradiance perpendicular to the rays (surface/lights.py).
    P_global = np.asarray(P, np.float64) + prep.origin
    placed = light_points(L_in, P_global, scene_size(np.asarray(prep.mesh.vertices), P_global), dtype)
    I_e = np.where(placed.at_infinity, I_e * placed.gain, I_e)
    check_fits("intensity", I_e, dtype)
    return prep.local, P, L, n, n_P, I_e, placed.at_infinity


def _check_count(name, value, lo):
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def sms_biased(mesh: SurfaceMesh | PreparedSurface, P, L, *, k: int, seed: int, intensity,
               receiver_normal, eta: float = 1.333, sigma_t: float = 0.0, same_radius: float = 1e-6,
               features="auto", **newton_options) -> EstimatorResult:
    """Biased SMS: `k` Newton solves per receiver from area-uniform random starts, the
    distinct forward solutions summed (Zeltner et al. 2020 §4.3; module docstring).
    `newton_options` go to
    `caustics_jax.Newton` (solver, constraint, tol, max_patches, ...) and `features` to
    `solve`; anything else (`method`, `start`: the estimator sets them) is a `ValueError`."""
    newton = Newton(**newton_options)
    check_features(features)
    k = _check_count("k", k, 1)
    seed = check_int("seed", seed, 0)
    prep, P, L, n, n_P, I_e, at_infinity = _inputs(mesh, P, L, intensity, receiver_normal, eta, sigma_t, same_radius)
    rng = np.random.default_rng(seed)
    lane = np.repeat(np.arange(n), k)
    idx = jnp.asarray(lane)
    found, M, face, ab = _newton_from(prep, P[idx], L[idx], eta, surface_starts(prep.mesh, n * k, rng),
                                      newton, features)
    E = np.zeros(n)
    paths = np.zeros(n, np.int64)
    hit = np.nonzero(found)[0]
    if hit.size:
        E_path = _path_irradiance(prep.mesh, face[hit], ab[hit], P[idx[hit]], L[idx[hit]], eta, I_e[lane[hit]],
                                  n_P[lane[hit]], sigma_t, at_infinity[lane[hit]])
        owner, pts = lane[hit], M[hit]
        # Distinct per receiver: a solution within same_radius of an earlier one is the same.
        order = np.lexsort((pts[:, 0], owner))
        keep = np.ones(len(order), bool)
        o, p = owner[order], pts[order]
        for shift in range(1, k):
            same = np.zeros(len(o), bool)
            same[shift:] = (o[shift:] == o[:-shift]) & (np.linalg.norm(p[shift:] - p[:-shift], axis=-1) <= same_radius)
            keep &= ~same
        np.add.at(E, o[keep], E_path[order][keep])
        np.add.at(paths, o[keep], 1)
    return EstimatorResult(E, np.full(n, k, np.int64), paths)


def sms_unbiased(mesh: SurfaceMesh | PreparedSurface, P, L, *, seed: int, intensity, receiver_normal,
                 eta: float = 1.333, sigma_t: float = 0.0, max_trials: int = 1000, same_radius: float = 1e-6,
                 features="auto", **newton_options) -> EstimatorResult:
    """Unbiased SMS: one solve, then Bernoulli trials until the same solution recurs; the
    path's irradiance times the trial count (Zeltner et al. 2020 §4.3; module docstring).
    `newton_options` as `sms_biased`'s."""
    newton = Newton(**newton_options)
    check_features(features)
    max_trials = _check_count("max_trials", max_trials, 1)
    seed = check_int("seed", seed, 0)
    prep, P, L, n, n_P, I_e, at_infinity = _inputs(mesh, P, L, intensity, receiver_normal, eta, sigma_t, same_radius)
    rng = np.random.default_rng(seed)
    found, M, face, ab = _newton_from(prep, P, L, eta, surface_starts(prep.mesh, n, rng), newton, features)
    solves = np.ones(n, np.int64)
    trials = np.where(found, 1, 0).astype(np.int64)
    E_path = np.zeros(n)
    hit = np.nonzero(found)[0]
    if hit.size:
        g = jnp.asarray(hit)
        E_path[hit] = _path_irradiance(prep.mesh, face[hit], ab[hit], P[g], L[g], eta, I_e[hit], n_P[hit], sigma_t,
                                       at_infinity[hit])
    # The trials run in rounds: each active lane draws `m` fresh starts at once (enough to
    # fill one block of `solve`, `blocks.lanes_per_block`), and its outcomes are read in
    # order as the sequential loop would: the first recurrence ends the lane, a miss adds
    # one to its count, the miss that takes the count past `max_trials` caps it. Starts
    # drawn after a lane's end are discarded and not counted in `solves`.
    active = found.copy()
    block = lanes_per_block()
    while active.any():
        idx = np.nonzero(active)[0]
        allowed = max_trials - trials[idx] + 1  # misses until the cap
        m = int(max(1, min(block // idx.size, allowed.max())))
        rep = np.repeat(idx, m)
        g = jnp.asarray(rep)
        f_t, M_t, _, _ = _newton_from(prep, P[g], L[g], eta, surface_starts(prep.mesh, rep.size, rng),
                                      newton, features)
        again = (f_t & (np.linalg.norm(M_t - M[rep], axis=-1) <= same_radius)).reshape(idx.size, m)
        first = np.where(again.any(1), again.argmax(1), m)  # misses before the first recurrence
        capped = first >= allowed
        ended = ~capped & (first < m)
        solves[idx] += np.where(capped, allowed, np.where(ended, first + 1, m))
        trials[idx] += np.where(capped, 0, first)
        trials[idx[capped]] = 0
        active[idx[capped | ended]] = False
    return EstimatorResult(E_path * trials, solves, trials)
