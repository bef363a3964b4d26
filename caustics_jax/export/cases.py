"""Building blocks of the case generators (DESIGN.md "Reference data for shader tests").

Each kernel's `generate(rng, n)` (in `cases_*.py`) returns float64 inputs for `n` random
and planted candidates (a quarter planted, `split`) plus its fixed adversarial set, tagged
with `records.CASES` (`stack_cases`). Random geometry comes from `caustics_jax.testing`
(`random_triangles`, `planted_paths`), the same generators the tests use. `f64` runs a
package kernel in float64 on numpy arrays: generators and conditioning filters use it so
that no formula of the package is written a second time in numpy.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .. import testing
from ..math.barycentric import barycentric_point
from ..runtime.precision import precision


def f64(fn, *args):
    """`fn` (a package kernel) on float64 numpy arguments, as numpy: to build and select cases."""
    with precision("float64"):
        out = jax.jit(fn)(*(jnp.asarray(a, jnp.float64) for a in args))
        return jax.tree_util.tree_map(np.asarray, out)


def unit(v):
    """`v / |v|` over the last axis, in numpy (inputs are built before any kernel runs)."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def split(n: int) -> tuple[int, int]:
    """Planted and random record counts for `count = n` (a quarter planted)."""
    planted = n // 4
    return planted, n - planted


def stack_cases(parts):
    """Concatenate `(inputs, case_code)` parts into one inputs dict and a case array."""
    keys = parts[0][0].keys()
    inputs = {k: np.concatenate([np.asarray(p[0][k], np.float64) for p in parts]) for k in keys}
    case = np.concatenate([np.full(len(p[0][next(iter(keys))]), p[1], np.uint32) for p in parts])
    return inputs, case


def random_paths(rng, n, normal_spread=0.3):
    """Random triangles (testing.random_triangles), a random interior `ab`, P below, L above."""
    V, N = testing.random_triangles(rng, n, normal_spread=normal_spread)
    ab = rng.dirichlet([2.0, 2.0, 2.0], n)[:, 1:]
    M = f64(barycentric_point, V, ab)
    P = M + rng.uniform(-1, 1, (n, 3)) * [1, 1, 0] - rng.uniform(0.2, 2.0, (n, 1)) * [0, 0, 1]
    L = M + rng.uniform(-2, 2, (n, 3)) * [1, 1, 0] + rng.uniform(0.5, 5.0, (n, 1)) * [0, 0, 1]
    return V, N, P, L, ab


def planted(rng, n, **kw):
    """`n` planted refracted paths (testing.planted_paths) seeded from `rng`."""
    return testing.planted_paths(int(rng.integers(2**31)), n, **kw)


def path_inputs(V, N, P, L, ab, eta):
    """The inputs of the path kernels (`signed_sine`, `d_factor`), `eta` broadcast per record."""
    return {"V": V, "N": N, "P": P, "L": L, "ab": ab, "eta": np.broadcast_to(eta, (len(V),)).astype(np.float64)}


def adversarial_paths():
    """TIR (P far off the normal), M = P exactly (degenerate), P above the surface; then a
    refracting path with `eta` outside its domain (0, -1.333: `d_factor` invalid, as a traced
    eta in the kernel) and beyond every physical ratio (1e30: total internal reflection;
    refract's `k` had been `inf - inf` there and `signed_sine` a root with status OK)."""
    z = np.array([0, 0, 1.0])
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    N = np.stack([z] * 3)
    ab = np.array([0.25, 0.25])
    M = np.array([0.25, 0.25, 0])
    P = np.stack([M + [1.5, 0, -0.5], M, M + [0.1, 0.2, 0.5], M + [0, 0, -1.0]] + [M + [0.2, 0.1, -1.0]] * 3)
    L = np.stack([M + [0, 0, 1.0], M + [0, 0, 1.0], M + [0, 0, 2.0], M + [0, 0, 2.0]] + [M + [-0.1, 0.3, 2.0]] * 3)
    eta = np.array([1.333] * 4 + [0.0, -1.333, 1e30])
    n = len(P)
    return path_inputs(np.stack([V] * n), np.stack([N] * n), P, L, np.stack([ab] * n), eta)
