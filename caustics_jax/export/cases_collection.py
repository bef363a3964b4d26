"""Reference cases of the collection-point and denoising kernels: the resolve and temporal
EMA (seed 000 eq. 1-2), the reuse acceptance test (seed 000 eq. 4) and one pixel of the
adaptive cross-bilateral denoiser's sub-pass (seed 004 eq. 21-28, Alg. 4); DESIGN.md
"Reference data for shader tests".

A `denoise_subpass` record holds a row of `DENOISE_ROW` pixels (colour, depth, position)
and the index `x` of the pixel filtered: neighbours outside the row are skipped, as
Alg. 4 skips them at the image border.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..kernels.bilateral import C_SCENE_FACTOR, C_SCENE_FACTOR_ALG4, REC709, denoise_subpass
from ..kernels.collection import resolve, reuse_accepted, temporal_ema
from .cases import split, stack_cases, unit
from .records import CASES
from .registry import register

#: Pixels per denoiser record: the largest footprint of Alg. 4 (radius 15) around the centre.
DENOISE_ROW = 31


def _gen_resolve(rng, n):
    n_pl, n_rand = split(n)

    def rows(m, r, alpha):
        return {"tau": rng.uniform(0, 1, (m, 3)), "I": rng.uniform(0, 2e-4, (m, 3)), "r": r,
                "L_hat": rng.uniform(0, 20, (m, 3)), "alpha": alpha}

    rand = rows(n_rand, rng.uniform(1e-4, 5e-3, n_rand), rng.uniform(0, 1, n_rand))
    planted = rows(n_pl, rng.uniform(1e-3, 5e-3, n_pl), np.full(n_pl, 0.8))  # the paper's alpha
    planted["L_hat"] = planted["tau"] * planted["I"] / (np.pi * planted["r"][:, None] ** 2)  # a steady state
    adv = {"tau": np.array([[1, 1, 1.0], [0.5, 0.5, 0.5], [1, 0, 0.5], [1, 1, 1.0]]),
           "I": np.array([[1e-4, 1e-4, 1e-4], [0, 0, 0.0], [2e-4, 1e-4, 0], [1e-4, 1e-4, 1e-4]]),
           "r": np.array([0.0, 1e-3, 5e-3, 2.0**-9]), "L_hat": np.array([[1, 2, 3.0], [4, 5, 6.0], [0, 0, 0.0],
                                                                       [1, 1, 1.0]]),
           "alpha": np.array([0.8, 1.0, 0.0, 0.5])}
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


@register("resolve_ema", equations="seed 000 eq. 1: L_o = tau I / (pi r^2) (0 at r = 0); eq. 2: "
          "L_new = alpha L_hat + (1 - alpha) L_o", reference=resolve,
          inputs={"tau": "vec3", "I": "vec3", "r": "float", "L_hat": "vec3", "alpha": "float"},
          outputs={"L_o": "vec3", "L_new": "vec3"}, generate=_gen_resolve)
def _eval_resolve(x):
    L_o = resolve(x["tau"], x["I"], x["r"][:, None])
    return {"L_o": L_o, "L_new": temporal_ema(x["L_hat"], L_o, x["alpha"][:, None])}


def _gen_reuse_accepted(rng, n):
    n_pl, n_rand = split(n)

    def rows(m, k, n_prev_spread, same):
        p = rng.uniform(-2, 2, (m, 3))
        r = rng.uniform(1e-3, 5e-3, m)
        n_vec = unit(rng.normal(size=(m, 3)))
        m_id = rng.integers(0, 4, m)
        return {"p_prev": p + unit(rng.normal(size=(m, 3))) * (k * r)[:, None],
                "n_prev": unit(n_vec + rng.normal(size=(m, 3)) * n_prev_spread[:, None]),
                "m_prev": np.where(same, m_id, (m_id + 1) % 4), "p": p, "n": n_vec, "m": m_id, "r": r}

    rand = rows(n_rand, rng.uniform(0, 2, n_rand), rng.uniform(0, 0.8, n_rand), rng.uniform(0, 1, n_rand) < 0.8)
    # planted: the same normal and material, |p - p_prev| = r / 2 (accepted) or 3 r / 2 (not)
    planted = rows(n_pl, np.where(np.arange(n_pl) % 2 == 0, 0.5, 1.5), np.zeros(n_pl), np.ones(n_pl, bool))
    z, x = [0, 0, 1.0], [1.0, 0, 0]
    adv = {  # exact in float32: |d| = r exactly (accepted), r = 0 at coincident points, n.n = 0, other material
        "p_prev": np.array([[0.5, 0, 0], [0.25, 0.5, 0], [0.25, 0.5, 0], [0, 0, 0.0], [0, 0, 0.0]]),
        "n_prev": np.array([z, z, z, x, z]), "m_prev": np.array([1, 2, 2, 0, 3]),
        "p": np.array([[0.5, 0, 2.0**-8], [0.25, 0.5, 0], [0.25, 0.5, 2.0**-20], [0, 0, 0.0], [0, 0, 0.0]]),
        "n": np.array([z, z, z, z, z]), "m": np.array([1, 2, 2, 0, 2]), "r": np.array([2.0**-8, 0, 0, 1e-3, 1e-3])}
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


def _keep_reuse(x, ref):
    """Away from both thresholds, where float32 rounding would decide the outcome."""
    d2 = np.sum((x["p_prev"] - x["p"]) ** 2, -1)
    r2 = x["r"] ** 2
    cos = np.sum(x["n_prev"] * x["n"], -1)
    return (np.abs(d2 - r2) > 1e-3 * r2) & (np.abs(cos - 0.9) > 1e-4)


@register("reuse_accepted", equations="seed 000 eq. 4: |p_prev - p| <= r, n_prev . n >= 0.9, same material",
          reference=reuse_accepted,
          inputs={"p_prev": "vec3", "n_prev": "vec3", "m_prev": "int", "p": "vec3", "n": "vec3", "m": "int",
                  "r": "float"},
          outputs={"accepted": "uint"}, generate=_gen_reuse_accepted, keep=_keep_reuse, filter_planted=True)
def _eval_reuse_accepted(x):
    ok = reuse_accepted(x["p_prev"], x["n_prev"], x["m_prev"].astype(jnp.int32), x["p"], x["n"],
                        x["m"].astype(jnp.int32), x["r"])
    return {"accepted": ok.astype(jnp.uint32)}


def _lum(C):
    return C @ np.asarray(REC709)


def _gen_denoise(rng, n):
    n_pl, n_rand = split(n)
    w = DENOISE_ROW

    def rows(m, C, regime):
        x = rng.integers(0, w, m)
        depth = rng.uniform(0.5, 30, (m, 1)) + rng.normal(0, 0.3, (m, w))
        pos = rng.uniform(-5, 5, (m, 1, 3)) + np.arange(w)[None, :, None] * rng.uniform(0.001, 0.05, (m, 1, 3))
        factor = rng.choice([C_SCENE_FACTOR, C_SCENE_FACTOR_ALG4], m)
        lum_c = _lum(C[np.arange(m), x])
        # lum_l_min that puts the centre pixel in regime 0 (dark), 1 (dim) or 2 (bright) of eq. 25-28
        u = np.choose(regime, [rng.uniform(0.01, 0.09, m), rng.uniform(0.12, 0.45, m), rng.uniform(0.6, 3, m)])
        return {"C": C, "depth": np.maximum(depth, 0.1), "pos": pos, "x": x,
                "lum_l_min": lum_c / (factor * u), "c_scene_factor": factor, "eps": np.ones(m)}

    C = rng.uniform(0, 2, (n_rand, w, 3)) * rng.uniform(0, 1, (n_rand, w, 1))
    C[:, :, :] += 0.05
    rand = rows(n_rand, C, rng.integers(0, 3, n_rand))
    # planted: a constant row, whose filtered value is that constant (eq. 24 normalises)
    planted = rows(n_pl, np.broadcast_to(rng.uniform(0.05, 2, (n_pl, 1, 3)), (n_pl, w, 3)).copy(),
                   rng.integers(0, 3, n_pl))
    adv = rows(4, np.broadcast_to(rng.uniform(0.05, 2, (4, 1, 3)), (4, w, 3)).copy(), np.array([0, 0, 1, 2]))
    adv["x"] = np.array([0, w - 1, 3, w // 2])  # the row's ends: neighbours outside are skipped
    adv["depth"][2, :] = np.where(np.arange(w) < 5, 1.0, 100.0)  # a depth edge
    adv["C"][3] = 0.0  # black
    adv["lum_l_min"][3] = 0.0  # C_scene = 0: every pixel is 'bright' (lum 0 is not < 0)
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


def _keep_denoise(x, ref):
    """Centre luminance away from the regime thresholds 0.1 and 0.5 C_scene (eq. 26-28)."""
    m = len(x["x"])
    lum_c = _lum(x["C"][np.arange(m), x["x"].astype(int)])
    c_scene = x["c_scene_factor"] * x["lum_l_min"]
    return (np.abs(lum_c - 0.1 * c_scene) > 1e-3 * c_scene) & (np.abs(lum_c - 0.5 * c_scene) > 1e-3 * c_scene)


@register("denoise_subpass", equations=f"seed 004 Alg. 4, one 1-D sub-pass at pixel x of a {DENOISE_ROW}-pixel row: "
          "(rho, lambda, delta) from lum(C(x)) vs C_scene = c lum(L_min) (eq. 25-28, Rec. 709 luminance), "
          "w = w_z w_pos (eq. 21-23), centre weight 1, out = (C(x) + sum w C(q)) / (1 + sum w) (eq. 24)",
          reference=denoise_subpass,
          inputs={"C": f"vec3[{DENOISE_ROW}]", "depth": f"float[{DENOISE_ROW}]", "pos": f"vec3[{DENOISE_ROW}]",
                  "x": "int", "lum_l_min": "float", "c_scene_factor": "float", "eps": "float"},
          outputs={"C_out": "vec3"}, generate=_gen_denoise, keep=_keep_denoise, filter_planted=True)
def _eval_denoise(x):
    def one(C, depth, pos, i, lum_l_min, factor, eps):
        out = denoise_subpass(C[None], depth[None], pos[None], lum_l_min, 1, factor, eps)
        return out[0, i]

    return {"C_out": jax.vmap(one)(x["C"], x["depth"], x["pos"], x["x"].astype(jnp.int32), x["lum_l_min"],
                                   x["c_scene_factor"], x["eps"])}
