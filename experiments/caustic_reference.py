"""The reference caustic of the seeds' claims experiments (`denoiser`, `differential`): a
pre-focal Gerstner pool and its irradiance map on the floor, certified.

The map is the cell average of walk + D irradiance (seed 001 eq. 25-33 with math.md §6) at
`k x k` midpoints per receiver cell, float64. It is certified against the all-path
reference: on a random subsample of the midpoints the exhaustive solver (float64, every
path on the mesh) must find exactly one path where the walk found one, at the same point,
and the all-path irradiance must equal the walk's (`certify`); past the focal distance a
single-path map would not be the total, so the pool is chosen pre-focal (amplitude 0.1 m,
floor 1 m down, as in `irradiance_agreement`).
"""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from caustics_jax import scenes  # noqa: E402
from caustics_jax.transport import ReceiverGrid, irradiance  # noqa: E402

LIGHT = np.array([0.4, -0.3, 3.0])
UP = np.array([0.0, 0.0, 1.0])
ETA = 1.333
DEPTH = 1.0


def pool(triangles: int = 8192, amplitude: float = 0.1):
    """The float64 pre-focal pool (`scenes.wavy_pool`)."""
    return scenes.wavy_pool(triangles, amplitude=amplitude, depth=DEPTH, dtype=jnp.float64).surface


def receiver_grid(n: int) -> ReceiverGrid:
    """`n x n` floor cells over the lit middle of the pool, 1 m down."""
    return ReceiverGrid(-DEPTH, -1.6, 1.6, -1.6, 1.6, n, n)


def reference_map(mesh, receiver: ReceiverGrid, k: int = 2, *, light=LIGHT, sigma_t: float = 0.0,
                  all_paths: bool = False) -> np.ndarray:
    """`(ny, nx)` cell-average irradiance (W/m^2 for a 1 W/sr light at `light`) by walk + D,
    attenuated by `exp(-sigma_t |P - M|)`; `all_paths`: every path on the traced curve
    summed (`irradiance(..., all_paths=True)`), where one light has several per receiver."""
    P = jnp.asarray(receiver.subsamples(k).reshape(-1, 3))
    E = irradiance(mesh, P, jnp.asarray(light), intensity=1.0, eta=ETA, receiver_normal=UP, sigma_t=sigma_t,
                   all_paths=all_paths)
    return np.asarray(E, np.float64).reshape(receiver.ny, receiver.nx, k * k).mean(-1)


def certify(mesh, receiver: ReceiverGrid, k: int = 2, lanes: int = 256, seed: int = 0, *, light=LIGHT,
            all_paths: bool = False) -> dict:
    """Walk + D (`all_paths`: every path on the traced curve) against the exhaustive all-path
    irradiance at `lanes` random midpoints: the largest differences."""
    P_all = receiver.subsamples(k).reshape(-1, 3)
    pick = np.random.default_rng(seed).choice(len(P_all), size=min(lanes, len(P_all)), replace=False)
    P = jnp.asarray(P_all[pick])
    L = jnp.asarray(light)
    walk = np.asarray(irradiance(mesh, P, L, intensity=1.0, eta=ETA, receiver_normal=UP, all_paths=all_paths))
    total = np.asarray(irradiance(mesh, P, L, intensity=1.0, eta=ETA, receiver_normal=UP, method="exhaustive",
                                  all_paths=True))
    scale = max(float(np.max(total)), 1e-300)
    return {"lanes": int(len(pick)), "max_abs_diff_over_max": float(np.max(np.abs(walk - total)) / scale),
            "max_rel_diff_lit": float(np.max(np.abs(walk - total)[total > 0] / total[total > 0]))
            if np.any(total > 0) else 0.0}


def errors(E: np.ndarray, ref: np.ndarray, lit: np.ndarray | None = None) -> dict:
    """Relative L1 and RMS errors of a map against the reference, over the cells `lit`
    (default: the cells the reference lights)."""
    lit = ref > 0 if lit is None else lit
    diff = (E - ref)[lit]
    return {"rel_L1": float(np.sum(np.abs(diff)) / np.sum(ref[lit])),
            "rel_rms": float(np.sqrt(np.mean(diff**2)) / np.sqrt(np.mean(ref[lit] ** 2)))}
