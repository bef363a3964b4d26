"""Reference cases of the conic kernels: `conic_coefficients` (seed 001 eq. 10-12),
`conic_tangent` (eq. 13-15 with the symmetric part S) and `edge_intersections` (eq. 22-24,
corrected in math.md §3); DESIGN.md "Reference data for shader tests"."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..math.conic import (
    conic_coefficients,
    conic_tangent,
    edge_intersections,
    edge_quadratics,
    solve_quadratic,
)
from .cases import f64, planted, random_paths, split, stack_cases, unit
from .records import CASES
from .registry import register

#: Edge-root window of `edge_intersections` for a float32 consumer: its default for float32
#: inputs (64 eps), used for the float64 reference too, so that roots just outside an edge
#: are kept and clamped exactly as the float32 kernel and the shader do.
EDGE_TOL = 64 * float(np.finfo(np.float32).eps)


def _gen_conic(rng, n):
    n_pl, n_rand = split(n)
    V, N, P, L, _ = random_paths(rng, n_rand)
    pl = planted(rng, n_pl)
    z = np.array([0, 0, 1.0])
    Vf = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    adv = {  # constant normals (the conic is a line, A = B = C = 0), a tilted large-scale copy
        "V": np.stack([Vf, Vf, 100 * Vf + 50, 1e-3 * Vf]),
        "N": np.stack([np.stack([z] * 3)] * 2 + [np.stack([unit(np.array([0.1, 0, 1.0])), z, z])] * 2),
        "P": np.array([[0.2, 0.3, -1.0], [0.5, 0.5, -0.5], [80, 90, -10.0], [2e-4, 3e-4, -1e-3]]),
        "L": np.array([[0.3, 0.1, 2.0], [0.5, 0.5, 3.0], [60, 60, 120.0], [4e-4, 1e-4, 2e-3]]),
    }
    return stack_cases([({"V": V, "N": N, "P": P, "L": L}, CASES["random"]),
                        ({"V": pl.V, "N": pl.N, "P": pl.P, "L": pl.L}, CASES["planted"]),
                        (adv, CASES["adversarial"])])


@register("conic_coefficients", equations="seed 001 eq. 10-12 (math.md §2)", reference=conic_coefficients,
          inputs={"V": "vec3[3]", "N": "vec3[3]", "P": "vec3", "L": "vec3"}, outputs={"coef": "float[6]"},
          generate=_gen_conic, audit={"coef": ("conic coefficients (max abs / max |coef|)", "rel")})
def _eval_conic(x):
    return {"coef": conic_coefficients(x["V"], x["N"], x["P"], x["L"])}


def _gen_tangent(rng, n):
    n_pl, n_rand = split(n)
    V, N, P, L, ab = random_paths(rng, n_rand)
    coef = f64(conic_coefficients, V, N, P, L)
    pl = planted(rng, n_pl)
    coef_pl = f64(conic_coefficients, pl.V, pl.N, pl.P, pl.L)
    adv = {  # a singular point (crossing lines a^2 - b^2 = 0 at the origin: t = 0), a circle
        "coef": np.array([[1.0, -1, 0, 0, 0, 0], [1, 1, 0, -1, -1, 0.25], [1, 1, 0, -1, -1, 0.25],
                          [0, 0, 0, 1, -1, 0]]),
        "ab": np.array([[0.0, 0], [0.5, 0], [1, 0.5], [0.25, 0.25]]),
    }
    return stack_cases([({"coef": coef, "ab": ab}, CASES["random"]),
                        ({"coef": coef_pl, "ab": pl.ab}, CASES["planted"]), (adv, CASES["adversarial"])])


@register("conic_tangent", equations="seed 001 eq. 13-15 with the symmetric part S (math.md §2)",
          reference=conic_tangent, inputs={"coef": "float[6]", "ab": "vec2"}, outputs={"t": "vec2"},
          generate=_gen_tangent, scale={"t": "coef"})  # its cancellation is relative to the coefficients
def _eval_tangent(x):
    return {"t": conic_tangent(x["coef"], x["ab"])}


def _gen_edges(rng, n):
    n_pl, n_rand = split(n)
    V, N, P, L, _ = random_paths(rng, 4 * n_rand, normal_spread=0.6)
    coef = f64(conic_coefficients, V, N, P, L)
    # planted: known roots r0 < r1 on edge 0 (b = 0) and s0 < s1 on edge 2 (a = 0): with
    # A = 1, D = -(r0 + r1), F = r0 r1 and B = F / (s0 s1), E = -B (s0 + s1); C is free
    m = 4 * n_pl  # candidates: edge 1's quadratic is whatever follows, kept only if well conditioned
    r0, s0 = rng.uniform(0.05, 0.45, m), rng.uniform(0.05, 0.45, m)
    r1, s1 = r0 + rng.uniform(0.1, 0.5, m), s0 + rng.uniform(0.1, 0.5, m)
    F = r0 * r1
    B = F / (s0 * s1)
    planted_ = np.stack([np.ones(m), B, rng.uniform(-1, 1, m), -(r0 + r1), -B * (s0 + s1), F], -1)
    adv = np.array([  # exact in float32: tangency, roots at vertices, linear edges, no curve
        [1, 0, 0, -1, 0, 0.25],      # edge b=0: (a - 1/2)^2 (tangent, double root)
        [1, 1, 0, 0, 0, 0],          # F = 0: root at V0 on two edges
        [1, 0, 0, -3, 0, 2],         # edge b=0: roots 1 and 2 (only 1 inside, at V1)
        [0, 0, 0, 1, 1, -0.5],       # A = B = C = 0: the line a + b = 1/2 (linear quadratics)
        [0, 0, 0, 0, 0, 0],          # the whole plane: no isolated root anywhere
        [1, 1, 0, 0, 0, 1],          # a^2 + b^2 + 1 = 0: no real curve
        [1, 1, 0, -1, -1, 0.375],    # circle inside the triangle: no edge crossings
        [0, 0, 0, 0, 1, -0.25],      # b = 1/4: crosses edges 1 and 2 only
        [1, 0, 0, 2**-20 - 0.5, 0, -(2**-21)],  # roots -2^-20 (inside the window, clamped to 0), 1/2
        [1, 0, 0, -(3 + 2**-20), 0, 2 + 2**-19],  # roots 1 + 2^-20 (clamped to 1) and 2
        [1, 0, 0, -1.5, 0, 0.5 - 2**-12],  # roots 0.4995 and 1.00049 (outside the window: dropped)
    ])
    return stack_cases([({"coef": coef}, CASES["random"]), ({"coef": planted_}, CASES["planted"]),
                        ({"coef": adv}, CASES["adversarial"])])


def _keep_edges(x, ref):
    """Every edge quadratic (seed 001 eq. 22-24, `conic.edge_quadratics`) well conditioned:
    leading coefficient not near zero, discriminant not near zero (no near-double root), and
    no root (`conic.solve_quadratic`) within 1e-3 of an edge end."""
    q2, q1, q0 = np.moveaxis(f64(edge_quadratics, x["coef"]), -1, 0)  # each (records, edge)
    roots, real = f64(solve_quadratic, q2, q1, q0)  # (records, edge, 2)
    scale = np.maximum(np.maximum(np.abs(q2), np.abs(q1)), np.abs(q0))
    # the discriminant relative to its terms: how far the quadratic is from a double root
    rel_disc = (q1 * q1 - 4 * q2 * q0) / np.maximum(q1 * q1 + np.abs(4 * q2 * q0), 1e-300)
    away_from_ends = (np.abs(roots) > 1e-3) & (np.abs(roots - 1) > 1e-3)
    ok = (np.abs(q2) > 1e-2 * scale) & (np.abs(rel_disc) > 1e-2) & np.all(~real | away_from_ends, -1)
    return np.all(ok, -1)


@register("edge_intersections", equations="seed 001 eq. 22-24, corrected (math.md §3); roots edge-major, "
          "index 2 e + k; window tol = 64 float32 eps", reference=edge_intersections,
          inputs={"coef": "float[6]"}, outputs={"t": "float[6]", "valid": "uint[6]"},
          generate=_gen_edges, keep=_keep_edges, filter_planted=True)
def _eval_edges(x):
    t, valid = edge_intersections(x["coef"], tol=EDGE_TOL)
    return {"t": t.reshape(*t.shape[:-2], 6), "valid": valid.reshape(*valid.shape[:-2], 6).astype(jnp.uint32)}
