"""Reference cases of seed 003's energy culling (kernels/culling.py): `photon_cull` (the
photon's throughput after the water, then the mid-trace and final cull) and
`throughput_cull` (a refracted path's throughput estimated at its start point);
DESIGN.md "Reference data for shader tests"."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..kernels.culling import photon_cull, throughput, throughput_cull
from ..math.geometry import refraction_k
from .cases import f64, split, stack_cases
from .cases_optics import CRITICAL_MARGIN
from .records import CASES
from .registry import register

#: Relative distance from a cull threshold below which float32 rounding (of `T` and the
#: exponential, a few ulps) could decide the outcome: such candidates are not exported.
THRESHOLD_MARGIN = 1e-4


def _eta(rng, m):
    """Mostly air to water (the photons' refraction), some other ratios both ways."""
    return np.where(rng.uniform(0, 1, m) < 0.75, 1 / 1.333, rng.uniform(0.6, 1.5, m))


def _gen_photon_cull(rng, n):
    n_pl, n_rand = split(n)
    m = 4 * n_rand
    rand = {"cos_i": rng.uniform(0, 1, m), "t": rng.uniform(-0.2, 5, m), "eta": _eta(rng, m),
            "sigma_t": rng.choice([0.0, 0.1, 0.5, 2.0], m), "albedo": rng.uniform(0, 1, m),
            "mid": rng.uniform(0, 0.9, m), "final": rng.uniform(0, 0.6, m)}
    # planted: normal incidence in clear water, beta = 1 - ((1 - eta)/(1 + eta))^2, no thresholds
    planted = {"cos_i": np.ones(n_pl), "t": rng.uniform(0, 3, n_pl), "eta": np.full(n_pl, 1 / 1.333),
               "sigma_t": np.zeros(n_pl), "albedo": rng.uniform(0, 1, n_pl), "mid": np.zeros(n_pl),
               "final": np.zeros(n_pl)}
    # grazing (T = 0) with zero thresholds (0 >= 0: stored with energy 0) and with mid > 0;
    # black receiver (albedo 0) with final = 0 and > 0; negative t (clipped to 0); an
    # exponential that underflows float32 (beta = 0); total internal reflection (eta 1.333)
    adv = {"cos_i": np.array([0.0, 0.0, 0.8, 0.8, 0.9, 1.0, 0.2]),
           "t": np.array([1.0, 1.0, 1.0, 1.0, -3.0, 1e3, 1.0]),
           "eta": np.array([1 / 1.333] * 6 + [1.333]),
           "sigma_t": np.array([0.1, 0.1, 0.1, 0.1, 0.5, 1.0, 0.0]),
           "albedo": np.array([0.5, 0.5, 0.0, 0.0, 0.5, 0.5, 0.5]),
           "mid": np.array([0.0, 0.1, 0.1, 0.1, 0.1, 0.1, 0.0]),
           "final": np.array([0.0, 0.0, 0.0, 0.05, 0.05, 0.0, 0.0])}
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


def _clear_of(value, threshold):
    return np.abs(value - threshold) > THRESHOLD_MARGIN * np.maximum(np.abs(threshold), 1e-30)


def _keep_photon_cull(x, ref):
    beta = ref["beta"]
    cos_t2 = f64(refraction_k, x["cos_i"], x["eta"])
    return (np.abs(cos_t2) > CRITICAL_MARGIN) & (x["cos_i"] > 1e-2) & _clear_of(beta, x["mid"]) \
        & _clear_of(x["albedo"] * beta, x["final"])


@register("photon_cull", equations="seed 003 Fig. 9: beta = T(cos_i, eta) exp(-sigma_t max(t, 0)) (seed 001 "
          "eq. 25's T A), mid-trace cull beta < mid, final cull albedo beta < final (status 0 stored, 1 mid, "
          "2 final)",
          reference=photon_cull,
          inputs={"cos_i": "float", "t": "float", "eta": "float", "sigma_t": "float", "albedo": "float",
                  "mid": "float", "final": "float"},
          outputs={"beta": "float", "stored": "float", "status": "uint"},
          generate=_gen_photon_cull, keep=_keep_photon_cull)
def _eval_photon_cull(x):
    beta = throughput(x["cos_i"], x["t"], x["eta"], x["sigma_t"])
    stored, status = photon_cull(beta, x["albedo"], x["mid"], x["final"])
    return {"beta": beta, "stored": stored, "status": status.astype(jnp.uint32)}


def _gen_throughput_cull(rng, n):
    n_pl, n_rand = split(n)
    m = 4 * n_rand
    rand = {"cos_i": rng.uniform(0, 1, m), "d": rng.uniform(0, 8, m), "eta": _eta(rng, m),
            "sigma_t": rng.choice([0.0, 0.1, 0.5, 2.0], m), "min_throughput": rng.uniform(0, 0.9, m)}
    # planted: normal incidence, min_throughput 0 (every lane solved)
    planted = {"cos_i": np.ones(n_pl), "d": rng.uniform(0, 5, n_pl), "eta": np.full(n_pl, 1 / 1.333),
               "sigma_t": rng.uniform(0, 1, n_pl), "min_throughput": np.zeros(n_pl)}
    # grazing with threshold 0 (kept) and > 0 (culled); d = 0; an underflowing exponential
    adv = {"cos_i": np.array([0.0, 0.0, 0.7, 1.0]), "d": np.array([1.0, 1.0, 0.0, 1e3]),
           "eta": np.full(4, 1 / 1.333), "sigma_t": np.array([0.5, 0.5, 0.5, 1.0]),
           "min_throughput": np.array([0.0, 0.01, 0.5, 0.01])}
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


def _keep_throughput_cull(x, ref):
    cos_t2 = f64(refraction_k, x["cos_i"], x["eta"])
    return (np.abs(cos_t2) > CRITICAL_MARGIN) & (x["cos_i"] > 1e-2) & _clear_of(ref["beta_hat"], x["min_throughput"])


@register("throughput_cull", equations="seed 003 Fig. 14: beta_hat = T(cos_i, eta) exp(-sigma_t max(d, 0)) at "
          "the start point M0 (d = |P - M0|), the path solved where beta_hat >= min_throughput",
          reference=throughput_cull,
          inputs={"cos_i": "float", "d": "float", "eta": "float", "sigma_t": "float", "min_throughput": "float"},
          outputs={"beta_hat": "float", "keep": "uint"},
          generate=_gen_throughput_cull, keep=_keep_throughput_cull)
def _eval_throughput_cull(x):
    beta_hat, keep = throughput_cull(x["cos_i"], x["d"], x["min_throughput"], x["eta"], x["sigma_t"])
    return {"beta_hat": beta_hat, "keep": keep.astype(jnp.uint32)}
