"""Reference cases of the photon pipeline kernels of seed 004: the cascade dispatch (Alg. 1
with its three fixed lines, eq. 4-6), the photon intensity (attenuation and the
Schlick-like Fresnel, eq. 12-15) and the photon sprite (size, stretch, basis, corners and
intensity, eq. 16-20); DESIGN.md "Reference data for shader tests".

The cascade and sprite kernels take static configuration (map sizes, light range) in the
package; a record carries it as inputs, drawn from the fixed lists `CASCADE_CONFIGS` and
`SPRITE_CONFIGS`, and the reference runs the package kernel once per configuration.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..kernels.attenuation import (
    fresnel_reflect_approx,
    fresnel_refract_approx,
    intensity_attenuation,
    ray_intensity,
)
from ..kernels.cascades import cascade_deltas, cascade_dispatch, cascade_thread_counts
from ..kernels.sprites import (
    sprite_basis,
    sprite_corners,
    sprite_foreshortening,
    sprite_intensity,
    sprite_size,
)
from .cases import split, stack_cases, unit
from .records import CASES
from .registry import register

#: (ccm0_x, ccm0_y, s, n_levels) of the exported cascade dispatches (whole-texel rings).
CASCADE_CONFIGS = ((8, 8, 2, 1), (16, 16, 2, 3), (32, 16, 2, 2), (24, 24, 3, 3), (64, 64, 4, 2), (256, 256, 2, 4))
#: (r_width, r_height, ccm0_x, ccm0_y) of the exported sprites (light range in m, map size).
SPRITE_CONFIGS = ((4.0, 4.0, 256, 256), (6.0, 4.0, 512, 256), (1.0, 1.0, 1024, 1024))


def _cascade_bounds(cfg):
    """Thread ids where Alg. 1's regions start or end: level starts, Region0, Region1."""
    W, H, s, n = cfg
    dx, dy = cascade_deltas(W, H, s)
    counts = cascade_thread_counts(W, H, s, n)
    marks = [0, W * H - 1, sum(counts) - 1, sum(counts)]
    for c in range(1, n):
        start = W * H + (c - 1) * counts[-1]
        region0, region1 = W * dy, W * dy + 2 * dx * (H - 2 * dy)
        marks += [start, start + region0 - 1, start + region0, start + region1 - 1, start + region1]
    return marks


def _band_starts(cfg):
    """First thread of level 0 and of each later level's bottom, side and top band."""
    W, H, s, n = cfg
    dx, dy = cascade_deltas(W, H, s)
    ring = cascade_thread_counts(W, H, s, n)[-1]
    starts = [0]
    for c in range(1, n):
        start = W * H + (c - 1) * ring
        starts += [start, start + W * dy, start + W * dy + 2 * dx * (H - 2 * dy)]
    return starts


def _gen_cascade(rng, n):
    n_pl, n_rand = split(n)
    cfg = np.asarray(CASCADE_CONFIGS, np.float64)

    def rows(which, tid):
        c = cfg[which]
        return {"tid": tid, "ccm0_x": c[:, 0], "ccm0_y": c[:, 1], "s": c[:, 2], "n_levels": c[:, 3]}

    which = rng.integers(0, len(cfg), n_rand)
    total = np.array([sum(cascade_thread_counts(*c)) for c in CASCADE_CONFIGS])
    rand = rows(which, np.floor(rng.uniform(0, 1, n_rand) * total[which]))
    # planted: the first thread of each band (a known texel: each band starts at its corner)
    marks = [(i, m) for i, c in enumerate(CASCADE_CONFIGS) for m in _band_starts(c)]
    pick = rng.integers(0, len(marks), n_pl)
    planted = rows(np.array([marks[p][0] for p in pick]), np.array([marks[p][1] for p in pick], np.float64))
    adv_pairs = [(i, m + d) for i, c in enumerate(CASCADE_CONFIGS) for m in _cascade_bounds(c) for d in (-1, 0)]
    adv = rows(np.array([p[0] for p in adv_pairs]), np.array([p[1] for p in adv_pairs], np.float64))
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


@register("cascade_dispatch", equations="seed 004 Alg. 1 with lines 24, 26, 33 fixed (Region0, >=, Region1), "
          "thread counts eq. 4-6 (math.md §8)", reference=cascade_dispatch,
          inputs={"tid": "int", "ccm0_x": "int", "ccm0_y": "int", "s": "int", "n_levels": "int"},
          outputs={"texel": "int[2]", "level": "int", "valid": "uint"}, generate=_gen_cascade)
def _eval_cascade(x):
    tid = x["tid"].astype(jnp.int32)
    texel, level, valid = jnp.zeros(tid.shape + (2,), jnp.int32), jnp.zeros_like(tid), jnp.zeros(tid.shape, bool)
    for cfg in CASCADE_CONFIGS:
        this = (x["ccm0_x"] == cfg[0]) & (x["ccm0_y"] == cfg[1]) & (x["s"] == cfg[2]) & (x["n_levels"] == cfg[3])
        t, lv, ok = cascade_dispatch(tid, *cfg)
        texel = jnp.where(this[:, None], t, texel)
        level = jnp.where(this, lv, level)
        valid = jnp.where(this, ok, valid)
    return {"texel": texel, "level": level, "valid": valid.astype(jnp.uint32)}


def _gen_photon_intensity(rng, n):
    n_pl, n_rand = split(n)

    def rows(m, t_frac, n_vec, l_dir, f_frac, f_exp):
        t_max = rng.uniform(0.5, 5.0, m)
        return {"t": t_frac * t_max, "t_max": t_max, "gamma": rng.uniform(0.5, 0.99, m), "l_dir": l_dir, "n": n_vec,
                "f_frac": f_frac, "f_exp": f_exp, "L": rng.uniform(0.1, 4.0, m)}

    n_up = unit(rng.normal(size=(n_rand, 3)) * [0.3, 0.3, 0] + [0, 0, 1])
    rand = rows(n_rand, rng.uniform(-0.1, 1.1, n_rand), n_up, unit(rng.normal(size=(n_rand, 3)) * [1, 1, 0.5]
                                                                   - [0, 0, 1]),
                rng.uniform(0, 0.2, n_rand), rng.choice([5.0, 3.0, 1.5], n_rand))
    # planted: normal incidence, F_refl = F_frac exactly (eq. 14 with cos = 1)
    n_pl_up = unit(rng.normal(size=(n_pl, 3)) * [0.2, 0.2, 0] + [0, 0, 1])
    planted = rows(n_pl, rng.uniform(0, 1, n_pl), n_pl_up, -n_pl_up, rng.uniform(0, 0.2, n_pl), np.full(n_pl, 5.0))
    z = np.array([0, 0, 1.0])
    # t at the surface, at the peak (1 - gamma) t_max, at t_max; grazing and back-facing light;
    # then t_max = 0, gamma = -1 and 2: floored and clipped into (0, 1) as the kernel inside jit
    # (the port had given NaN and other finite values)
    m = 9
    adv = {"t": np.array([0.0, 0.25, 4.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]),
           "t_max": np.array([4.0, 5.0, 4.0, 2.0, 2.0, 2.0, 0.0, 2.0, 2.0]),
           "gamma": np.array([0.95, 0.95, 0.95, 0.5, 0.5, 0.5, 0.5, -1.0, 2.0]),
           "l_dir": np.array([[0, 0, -1.0], [0, 0, -1.0], [0, 0, -1.0], [1.0, 0, 0], [0, 0, 1.0], [0.6, 0, -0.8]]
                             + [[0.6, 0, -0.8]] * 3),
           "n": np.stack([z] * m), "f_frac": np.array([0.02, 0.02, 0.02, 0.02, 0.02, 1.0, 0.02, 0.02, 0.02]),
           "f_exp": np.full(m, 5.0), "L": np.array([1.0, 2.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0])}
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


@register("photon_intensity", equations="seed 004 eq. 12-15: R = L I_att F_refr, I_att the tent of eq. 13, "
          "F_refl = F_frac + (1 - F_frac)(1 - cos)^F_exp (eq. 14), F_refr = 1 - F_refl (eq. 15)",
          reference=ray_intensity,
          inputs={"t": "float", "t_max": "float", "gamma": "float", "l_dir": "vec3", "n": "vec3", "f_frac": "float",
                  "f_exp": "float", "L": "float"},
          outputs={"i_att": "float", "F_refl": "float", "F_refr": "float", "R": "float"},
          generate=_gen_photon_intensity)
def _eval_photon_intensity(x):
    i_att = intensity_attenuation(x["t"], x["t_max"], x["gamma"])
    F_refl = fresnel_reflect_approx(x["l_dir"], x["n"], x["f_frac"], x["f_exp"])
    F_refr = fresnel_refract_approx(x["l_dir"], x["n"], x["f_frac"], x["f_exp"])
    return {"i_att": i_att, "F_refl": F_refl, "F_refr": F_refr, "R": ray_intensity(x["L"], i_att, F_refr)}


def _gen_sprite(rng, n):
    n_pl, n_rand = split(n)
    cfg = np.asarray(SPRITE_CONFIGS, np.float64)

    def rows(m, l_dir, n_hit, sigma):
        c = cfg[rng.integers(0, len(cfg), m)]
        return {"l_dir": l_dir, "n_hit": n_hit, "x_hit": rng.uniform(-2, 2, (m, 3)) * [1, 1, 0.5], "sigma": sigma,
                "R": rng.uniform(0, 2, m), "r_width": c[:, 0], "r_height": c[:, 1], "ccm0_x": c[:, 2],
                "ccm0_y": c[:, 3], "q0": rng.uniform(0.5, 2.0, m)}

    n_up = unit(rng.normal(size=(n_rand, 3)) * [0.4, 0.4, 0] + [0, 0, 1])
    rand = rows(n_rand, unit(rng.normal(size=(n_rand, 3)) * [1, 1, 0.4] - [0, 0, 1]), n_up, rng.uniform(0.1, 3, n_rand))
    # planted: normal incidence (the patch is square, a = 1 / (1 + eps)); sigma = 1
    n_pl_up = unit(rng.normal(size=(n_pl, 3)) * [0.2, 0.2, 0] + [0, 0, 1])
    planted = rows(n_pl, -n_pl_up, n_pl_up, np.ones(n_pl))
    z = np.array([0, 0, 1.0])
    adv = rows(6, np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 0, -1.0], [0, 0, -1.0], [0, 0.6, -0.8], [0, -1.0, 0]]),
               np.array([z, z, z, [1.0, 0, 0], [0, 0.6, 0.8], [0, 1.0, 0]]), np.array([1.0, 1.0, 0.0, 1.0, 1.0, 1.0]))
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


@register("sprite", equations="seed 004 eq. 16-20: q = sqrt(r.w/(ccm0.x-1) r.h/(ccm0.y-1)) q0 sigma (eq. 16), "
          "a = 1/(max(-l.n', 0) + 1e-3) (eq. 19), basis lp_F, lp_R (Fig. 6), corners (eq. 17-18, patch "
          "(-1,1), (1,1), (-1,-1), (1,-1)), I = R/(a q^2) (eq. 20)", reference=sprite_corners,
          inputs={"l_dir": "vec3", "n_hit": "vec3", "x_hit": "vec3", "sigma": "float", "R": "float",
                  "r_width": "float", "r_height": "float", "ccm0_x": "int", "ccm0_y": "int", "q0": "float"},
          outputs={"q": "float", "a": "float", "lp_F": "vec3", "lp_R": "vec3", "corners": "vec3[4]", "I": "float"},
          generate=_gen_sprite)
def _eval_sprite(x):
    q = jnp.zeros_like(x["sigma"])
    for r_w, r_h, c_x, c_y in SPRITE_CONFIGS:
        this = (x["r_width"] == r_w) & (x["r_height"] == r_h) & (x["ccm0_x"] == c_x) & (x["ccm0_y"] == c_y)
        q = jnp.where(this, sprite_size(r_w, r_h, c_x, c_y, x["q0"], x["sigma"]), q)
    a = sprite_foreshortening(x["l_dir"], x["n_hit"])
    lp_F, lp_R = sprite_basis(x["l_dir"], x["n_hit"])
    return {"q": q, "a": a, "lp_F": lp_F, "lp_R": lp_R, "corners": sprite_corners(x["x_hit"], q, a, lp_F, lp_R),
            "I": sprite_intensity(x["R"], a, q)}
