"""Reference cases of the optics kernels: `refract` (GLSL refract, math.md §1, seed 002
eq. 3.1-3.2) and `fresnel` (exact dielectric Fresnel reflectance, the F of seed 001 eq. 25);
DESIGN.md "Reference data for shader tests"."""

from __future__ import annotations

import numpy as np

from ..math.geometry import fresnel_reflectance, refract, refraction_k
from ..math.objectives import path_vectors
from .cases import f64, planted, split, stack_cases, unit
from .records import CASES
from .registry import register

#: Conditioning margin of both filters: `|k| = |cos_t^2|` below it is too close to the
#: critical angle for float32 to decide refraction vs total internal reflection.
CRITICAL_MARGIN = 1e-2


def _gen_refract(rng, n):
    n_pl, n_rand = split(n)
    N = unit(rng.normal(size=(4 * n_rand, 3)))
    I = unit(rng.normal(size=(4 * n_rand, 3)))
    I = np.where(np.sum(I * N, -1, keepdims=True) > 0, -I, I)  # GLSL: dot(N, I) <= 0
    eta = rng.uniform(0.6, 1.5, 4 * n_rand)
    pl = planted(rng, n_pl)
    _, n_s, w_P, _, _ = f64(path_vectors, pl.V, pl.N, pl.P, pl.L, pl.ab)
    z, x = np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
    g = unit(np.array([0.6, 0, -0.8]))
    # normal incidence, grazing, eta = 1, deep total internal reflection, exact zeros; eta =
    # 1e30, beyond every physical ratio: total internal reflection (k had been inf - inf)
    adv = {
        "I": np.stack([-z, -z, x, x, g, g, -z, unit(np.array([0.9, 0, -0.1])), g]),
        "N": np.stack([z, z, z, z, z, z, z, z, z]),
        "eta": np.array([1.333, 1 / 1.333, 1 / 1.333, 1.333, 1.0, 1.333, 1.0, 1.333, 1e30]),
    }
    return stack_cases([
        ({"I": I, "N": N, "eta": eta}, CASES["random"]),
        ({"I": -w_P, "N": -n_s, "eta": np.full(n_pl, pl.eta)}, CASES["planted"]),
        (adv, CASES["adversarial"]),
    ])


def _keep_refract(x, ref):
    k = f64(refraction_k, np.sum(x["N"] * x["I"], -1), x["eta"])
    return np.abs(k) > CRITICAL_MARGIN  # sqrt(k) is ill-conditioned at the critical angle


@register("refract", equations="GLSL refract (math.md §1; seed 002 eq. 3.1-3.2)", reference=refract,
          inputs={"I": "vec3", "N": "vec3", "eta": "float"}, outputs={"T": "vec3"},
          generate=_gen_refract, keep=_keep_refract, audit={"T": ("refract (abs, unit vector)", "abs")})
def _eval_refract(x):
    return {"T": refract(x["I"], x["N"], x["eta"])}


def _gen_fresnel(rng, n):
    n_pl, n_rand = split(n)
    m = 4 * n_rand
    rand = {"cos_i": rng.uniform(0, 1, m), "eta": rng.choice([1 / 1.333, 1.333, 1 / 1.5, 1.5], m)
            * rng.uniform(0.9, 1.1, m)}
    # planted: water -> air at normal incidence, R = ((eta - 1)/(eta + 1))^2 in closed form
    planted_ = {"cos_i": np.ones(n_pl), "eta": rng.uniform(0.5, 2.0, n_pl)}
    adv = {"cos_i": np.array([0.0, 0.0, 1.0, 1.0, 0.5, 0.2, 1.0, 0.0, 0.6]),  # last: eta 1e30, TIR (R = 1)
           "eta": np.array([1 / 1.333, 1.333, 1.0, 1.333, 1.0, 1.333, 2.0, 1.0, 1e30])}
    return stack_cases([(rand, CASES["random"]), (planted_, CASES["planted"]), (adv, CASES["adversarial"])])


def _keep_fresnel(x, ref):
    cos_t2 = f64(refraction_k, x["cos_i"], x["eta"])
    return (np.abs(cos_t2) > CRITICAL_MARGIN) & (x["cos_i"] > 1e-2)  # not at the critical angle, not grazing


@register("fresnel", equations="exact unpolarised dielectric Fresnel reflectance (the F of seed 001 eq. 25)",
          reference=fresnel_reflectance, inputs={"cos_i": "float", "eta": "float"}, outputs={"R": "float"},
          generate=_gen_fresnel, keep=_keep_fresnel, audit={"R": ("Fresnel R air->water (abs)", "abs")})
def _eval_fresnel(x):
    return {"R": fresnel_reflectance(x["cos_i"], x["eta"])}
