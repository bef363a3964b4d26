"""Reference cases of the path and transport kernels: `signed_sine` (seed 001 eq. 19-21,
orientation "plane"), `d_factor` (eq. 26-33, signs of docs/transport.md) and
`photon_compression` (seed 004 eq. 10-11, Alg. 2, refraction variant of math.md §7);
DESIGN.md "Reference data for shader tests"."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..math.geometry import refract, refraction_k, safe_normalize
from ..math.objectives import path_vectors, signed_sine_and_status
from ..transport.differentials import ray_differential_D
from ..transport.photon_differentials import compression_ratio
from .cases import adversarial_paths, f64, path_inputs, planted, random_paths, split, stack_cases, unit
from .records import CASES
from .registry import register

_PATH_INPUTS = {"V": "vec3[3]", "N": "vec3[3]", "P": "vec3", "L": "vec3", "ab": "vec2", "eta": "float"}


def _gen_signed_sine(rng, n):
    n_pl, n_rand = split(n)
    V, N, P, L, ab = random_paths(rng, 4 * n_rand)
    pl = planted(rng, n_pl)
    return stack_cases([(path_inputs(V, N, P, L, ab, 1.333), CASES["random"]),
                        (path_inputs(pl.V, pl.N, pl.P, pl.L, pl.ab, pl.eta), CASES["planted"]),
                        (adversarial_paths(), CASES["adversarial"])])


def _path(x):
    """`n_s, w_P, w_L` (objectives.path_vectors), refract's `k` at `M` (geometry.refraction_k
    with `cos = dot(-n_s, -w_P)`) and `r = refract(-w_P, -n_s, eta)`, all float64."""
    _, n_s, w_P, w_L, _ = f64(path_vectors, x["V"], x["N"], x["P"], x["L"], x["ab"])
    k = f64(refraction_k, np.sum(n_s * w_P, -1), x["eta"])  # negative under TIR
    r = f64(refract, -w_P, -n_s, x["eta"])
    return n_s, w_P, w_L, k, r


def _keep_signed_sine(x, ref):
    n_s, w_P, w_L, k, r = _path(x)
    c = np.cross(r, w_L)
    o = np.cross(x["L"] - x["P"], n_s)  # the 'plane' orientation reference of signed_sine_and_status
    sign_margin = np.abs(np.sum(c * o, -1)) / (np.linalg.norm(c, axis=-1) * np.linalg.norm(o, axis=-1) + 1e-300)
    return (np.abs(k) > 1e-2) & (sign_margin > 1e-2)


@register("signed_sine", equations="seed 001 eq. 19-21, orientation 'plane' (objectives.signed_sine_and_status)",
          reference=signed_sine_and_status, inputs=_PATH_INPUTS, outputs={"f": "float", "status": "uint"},
          generate=_gen_signed_sine, keep=_keep_signed_sine, audit={"f": ("signed sine at planted M (abs)", "abs")})
def _eval_signed_sine(x):
    f, status = signed_sine_and_status(x["V"], x["N"], x["P"], x["L"], x["ab"], x["eta"], orientation="plane")
    return {"f": f, "status": status.astype(jnp.uint32)}


def _gen_D(rng, n):
    n_pl, n_rand = split(n)
    # random: planted geometry with the refraction point moved off the solution (D is still
    # defined there, it just describes a different ray map)
    r = planted(rng, 4 * n_rand)
    ab = r.ab + rng.uniform(-0.1, 0.1, r.ab.shape)
    pl = planted(rng, n_pl)
    return stack_cases([(path_inputs(r.V, r.N, r.P, r.L, ab, r.eta), CASES["random"]),
                        (path_inputs(pl.V, pl.N, pl.P, pl.L, pl.ab, pl.eta), CASES["planted"]),
                        (adversarial_paths(), CASES["adversarial"])])


def _keep_D(x, ref):
    n_s, w_P, w_L, k, _ = _path(x)
    n_g = f64(safe_normalize, np.cross(x["V"][:, 1] - x["V"][:, 0], x["V"][:, 2] - x["V"][:, 0]))
    # every validity threshold of ray_differential_D (sqrt(eps) of the dtype) far away
    return ((np.abs(k) > 1e-2) & (np.abs(np.sum(w_P * n_g, -1)) > 5e-2) & (np.sum(w_L * n_s, -1) > 5e-2)
            & (np.sum(w_P * n_s, -1) < -5e-2))


@register("d_factor", equations="seed 001 eq. 26-33, signs as in transport/differentials.py",
          reference=ray_differential_D, inputs=_PATH_INPUTS, outputs={"D": "float", "valid": "uint"},
          generate=_gen_D, keep=_keep_D)
def _eval_D(x):
    D, valid = ray_differential_D(x["V"], x["N"], x["P"], x["L"], x["ab"], x["eta"])
    return {"D": D, "valid": valid.astype(jnp.uint32)}


def _gen_photon(rng, n):
    n_pl, n_rand = split(n)
    m = n_rand

    def patch(m, spread):
        x00 = rng.uniform(-1, 1, (m, 3)) * [1, 1, 0.05]
        h = rng.uniform(0.005, 0.05, (m, 1))
        x10 = x00 + h * [1, 0, 0] + rng.normal(0, 0.2, (m, 3)) * h * [0, 0, 1]
        x01 = x00 + h * [0, 1, 0] + rng.normal(0, 0.2, (m, 3)) * h * [0, 0, 1]
        ns = [unit([0, 0, 1.0] + spread * rng.normal(size=(m, 3)) * [1, 1, 0]) for _ in range(3)]
        return x00, x10, x01, ns

    x00, x10, x01, (n00, n10, n01) = patch(m, 0.05)
    theta = np.radians(rng.uniform(0, 60, m))
    phi = rng.uniform(0, 2 * np.pi, m)
    l_dir = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)], -1)
    rand = {"x00": x00, "x10": x10, "x01": x01, "n00": n00, "n10": n10, "n01": n01, "l_dir": l_dir,
            "eta": np.full(m, 1.333), "t_hit": rng.uniform(0.5, 5, m), "s": rng.uniform(1, 2, m),
            "c": rng.integers(0, 4, m).astype(np.float64)}
    # planted: a flat patch with one normal refracts every ray the same way, so the caustic
    # triangle is a translate of the surface triangle and sigma = s^c exactly
    p00, p10, p01, _ = patch(n_pl, 0)
    p10[:, 2] = p01[:, 2] = p00[:, 2]
    up = np.broadcast_to([0, 0, 1.0], (n_pl, 3))
    th = np.radians(rng.uniform(0, 60, n_pl))
    ldir_pl = np.stack([np.sin(th), np.zeros(n_pl), -np.cos(th)], -1)
    planted_ = {"x00": p00, "x10": p10, "x01": p01, "n00": up, "n10": up, "n01": up, "l_dir": ldir_pl,
                "eta": np.full(n_pl, 1.333), "t_hit": rng.uniform(0.5, 5, n_pl),
                "s": rng.uniform(1, 2, n_pl), "c": rng.integers(0, 4, n_pl).astype(np.float64)}
    z = np.array([0, 0, 1.0])
    adv = {  # collinear surface points (A = 0), light straight down, grazing light, c = 0
        "x00": np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0.0]]),
        "x10": np.array([[1, 0, 0], [0.01, 0, 0], [0.01, 0, 0.0]]),
        "x01": np.array([[2, 0, 0], [0, 0.01, 0], [0, 0.01, 0.0]]),
        "n00": np.stack([z] * 3), "n10": np.stack([z, unit([0.1, 0, 1.0]), z]),
        "n01": np.stack([z, unit([0, 0.1, 1.0]), z]),
        "l_dir": np.stack([-z, -z, unit([1, 0, -0.05])]),
        "eta": np.full(3, 1.333), "t_hit": np.array([1.0, 2.0, 3.0]), "s": np.array([2.0, 1.5, 2.0]),
        "c": np.array([1.0, 0.0, 2.0]),
    }
    # the kernel's invalid lanes (sigma 0), one per condition on a valid texel triangle: a zero
    # normal, a normal of length 2, light from below, t' = 0, eta = 0, s < 1, c fractional,
    # c < 0 (each had given a finite sigma in the port, up to 57)
    k = 8
    tilt = unit([0.1, 0, 1.0])
    bad = {"x00": np.zeros((k, 3)), "x10": np.tile([0.01, 0, 0.001], (k, 1)), "x01": np.tile([0, 0.01, 0.0], (k, 1)),
           "n00": np.stack([z] * k), "n10": np.stack([np.zeros(3), 2 * tilt] + [tilt] * (k - 2)),
           "n01": np.stack([z] * k), "l_dir": np.stack([-z, -z, z] + [-z] * (k - 3)),
           "eta": np.array([1.333] * 4 + [0.0] + [1.333] * 3), "t_hit": np.array([1.0] * 3 + [0.0] + [1.0] * 4),
           "s": np.array([2.0] * 5 + [0.5, 2.0, 2.0]), "c": np.array([1.0] * 6 + [1.5, -1.0])}
    adv = {key: np.concatenate([adv[key], bad[key]]) for key in adv}
    return stack_cases([(rand, CASES["random"]), (planted_, CASES["planted"]), (adv, CASES["adversarial"])])


@register("photon_compression", equations="seed 004 eq. 10-11, Alg. 2 (refraction variant, math.md §7)",
          reference=compression_ratio,
          inputs={"x00": "vec3", "x10": "vec3", "x01": "vec3", "n00": "vec3", "n10": "vec3", "n01": "vec3",
                  "l_dir": "vec3", "eta": "float", "t_hit": "float", "s": "float", "c": "float"},
          outputs={"sigma": "float"}, generate=_gen_photon)
def _eval_photon(x):
    sigma, _ = compression_ratio(x["x00"], x["x10"], x["x01"], x["n00"], x["n10"], x["n01"], x["l_dir"],
                                 x["t_hit"], eta=x["eta"], scale=x["s"], level=x["c"], mode="refract")
    return {"sigma": sigma}
