"""Reference cases of the screen-space kernels of `caustics_jax.kernels`: `reuse_weight`
(seed 000 eq. 3), `bilateral_weight` (seed 004 eq. 21-23) and `fixed_point` (seed 000
§3.2, 4.28 fixed-point accumulation); DESIGN.md "Reference data for shader tests"."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..kernels.bilateral import bilateral_weight
from ..kernels.collection import reuse_weight
from ..kernels.fixed_point import fixed_point_accumulate
from .cases import split, stack_cases, unit
from .records import CASES
from .registry import register

#: Addends per `fixed_point` record (the shader adds them into one 32-bit word).
FIXED_POINT_ADDENDS = 16


def _gen_reuse(rng, n):
    n_pl, n_rand = split(n)
    p = rng.uniform(-1, 1, (n_rand, 3))
    r = rng.uniform(1e-4, 5e-3, n_rand)
    p_prev = p + unit(rng.normal(size=(n_rand, 3))) * (r * rng.uniform(0, 2, n_rand))[:, None]
    # planted: |p - p_prev| = k sigma along an axis, so w = exp(-k^2 / 2) (seed 000 eq. 3)
    q = rng.uniform(-1, 1, (n_pl, 3))
    rq = rng.uniform(1e-3, 5e-3, n_pl)
    k = rng.uniform(0, 3, n_pl)
    q_prev = q + np.eye(3)[rng.integers(0, 3, n_pl)] * (k * 0.75 * rq)[:, None]
    adv = {  # coincident points, r = 0 (delta kernel: 1 at coincident points, else 0), far away
        "p_prev": np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.51], [100, 100, 100.0]]),
        "p": np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.6], [0.5, 0.5, 0.5], [100, 100, 100.001]]),
        "r": np.array([1e-3, 0.0, 0.0, 1e-3, 1e-3]),
    }
    return stack_cases([({"p_prev": p_prev, "p": p, "r": r}, CASES["random"]),
                        ({"p_prev": q_prev, "p": q, "r": rq}, CASES["planted"]), (adv, CASES["adversarial"])])


@register("reuse_weight", equations="seed 000 eq. 3, sigma = 0.75 r", reference=reuse_weight,
          inputs={"p_prev": "vec3", "p": "vec3", "r": "float"}, outputs={"w": "float"}, generate=_gen_reuse)
def _eval_reuse(x):
    return {"w": reuse_weight(x["p_prev"], x["p"], x["r"])}


def _gen_bilateral(rng, n):
    n_pl, n_rand = split(n)
    m = n_rand
    pos_p = rng.uniform(-5, 5, (m, 3))
    rand = {"z_p": rng.uniform(0.1, 50, m), "z_q": rng.uniform(0.1, 50, m), "pos_p": pos_p,
            "pos_q": pos_p + rng.normal(0, 1, (m, 3)), "delta": rng.choice([15.0, 2.0, 1.0], m),
            "eps": np.ones(m)}
    # planted: q = p, the centre weight of Alg. 4 is 1 / eps
    pp = rng.uniform(-5, 5, (n_pl, 3))
    z = rng.uniform(0.1, 50, n_pl)
    planted = {"z_p": z, "z_q": z, "pos_p": pp, "pos_q": pp, "delta": rng.choice([15.0, 2.0, 1.0], n_pl),
               "eps": rng.choice([1.0, 0.5, 0.25], n_pl)}
    # the last record: eps = -1, floored at the smallest normal number (as the kernel inside jit)
    adv = {"z_p": np.array([0.1, 1e4, 1.0, 1.0, 1.0]), "z_q": np.array([1e4, 0.1, 1.0, 1.0 + 2**-20, 1.5]),
           "pos_p": np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0.0], [0, 0, 0.0]]),
           "pos_q": np.array([[0, 0, 0], [1e3, 0, 0], [1e-3, 0, 0], [0, 0, 0.0], [0.5, 0, 0.0]]),
           "delta": np.array([1.0, 1.0, 1e-4, 15.0, 1.0]), "eps": np.array([1.0, 1.0, 1e-6, 1e-6, -1.0])}
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


@register("bilateral_weight", equations="seed 004 eq. 21-23 (eps of Alg. 4 line 22 as an input)",
          reference=bilateral_weight, inputs={"z_p": "float", "z_q": "float", "pos_p": "vec3", "pos_q": "vec3",
                                              "delta": "float", "eps": "float"},
          outputs={"w": "float"}, generate=_gen_bilateral)
def _eval_bilateral(x):
    return {"w": bilateral_weight(x["z_p"], x["z_q"], x["pos_p"], x["pos_q"], x["delta"], x["eps"])}


def _gen_fixed(rng, n):
    n_pl, n_rand = split(n)
    k = FIXED_POINT_ADDENDS
    rand = rng.uniform(0, 1.6, (n_rand, k)) * rng.uniform(0, 1, (n_rand, 1))  # some sums reach 16
    planted = rng.integers(0, 2**24, (n_pl, k)) * 2.0**-28  # exact multiples of the step (24 bits: exact in float32)
    ties = (2 * rng.integers(0, 2**20, k) + 1) * 2.0**-29  # half-way between two codes
    adv = np.stack([np.zeros(k), np.full(k, 1.0), ties, np.full(k, 20.0), np.full(k, 15.999),
                    np.full(k, 2.0**-29), np.full(k, 3 * 2.0**-29)])
    return stack_cases([({"x": rand}, CASES["random"]), ({"x": planted}, CASES["planted"]),
                        ({"x": adv}, CASES["adversarial"])])


@register("fixed_point", equations=f"seed 000 §3.2: 4.28 fixed point, {FIXED_POINT_ADDENDS} addends per record, "
          "wrapping 32-bit adds", reference=fixed_point_accumulate,
          inputs={"x": f"float[{FIXED_POINT_ADDENDS}]"}, outputs={"code": "uint", "overflow": "uint", "value": "float"},
          generate=_gen_fixed)
def _eval_fixed(x):
    def one(row):
        s = fixed_point_accumulate(row)
        return s.code[0], s.overflow[0], s.value[0]

    code, overflow, value = jax.vmap(one)(x["x"])
    return {"code": code, "overflow": overflow.astype(jnp.uint32), "value": value}
