# %% [markdown]
# # One adaptive-radius denoiser pass against ten fixed-radius passes (seed 004 Fig. 12-13)
#
# Seed 004 §3.3: a separable cross-bilateral filter whose radius, step and distance scale
# adapt to the pixel's luminance relative to the scene's lights (eq. 21-28, Alg. 4;
# `kernels.bilateral_denoise`). Its claims: "in order to satisfactorily blur the
# individual photons of undersampled regions when using a fixed radius, 10 sequential
# denoise passes" are needed, while "the same quality result can be achieved even by using
# 1 pass" of the adaptive filter, which costs twice a fixed pass: "the performance gain is
# approximately five-fold".
#
# Measured here against the certified reference caustic (`experiments.caustic_reference`:
# the pre-focal Gerstner pool, 96 x 96 floor cells, walk + D cell averages, certified by the
# exhaustive all-path irradiance on 256 points): the noisy input is brute-force photon
# tracing binned on the same cells (`photon_irradiance`, 2^12 to 2^18 photons: about 0.5
# to 30 photons per lit cell, from undersampled to smooth), filtered by
#
# - the fixed-radius filter: the same kernel with every pixel at the third level
#   (`rho = 5`, `lambda = 1`, `delta = 1`: `lum_l_min = 0`), 1-10 passes;
# - the adaptive filter (eq. 25-28 with `lum(L_min)` the irradiance the light gives the
#   floor through flat water, the caustic's mean level), 1-4 passes; and one pass with
#   `lum(L_min)` 10 and 100 times that (a renderer's exposure decides where the light's
#   luminance sits against the caustic's: the thresholds move with it).
#
# A "pass" is the x then y sub-pass. Cost is counted as the shader pays it: the contributing
# samples per pixel (`2 rho / lambda` per sub-pass, 10 for a fixed pass, 6-20 adaptive: the
# loop count of `denoise_subpass.glsl`); the JAX wall time (which gathers all 30 offsets
# for every pixel either way) is reported too. Errors: relative L1 and RMS over the lit
# cells, in the irradiance units (W/m^2 per W/sr) a renderer accumulates.
#
# Run: `python -m experiments.denoiser [--quick]`; writes `figures/denoiser.png` and
# `figures/denoiser.json`.

# %%
from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

from caustics_jax.kernels.bilateral import adaptive_kernel_params, bilateral_denoise
from caustics_jax.testing import flat_interface_irradiance
from caustics_jax.transport import photon_irradiance
from experiments.caustic_reference import ETA, LIGHT, certify, errors, pool, receiver_grid, reference_map
from experiments.common import ROOT, parse_args, use_agg, write_json

use_agg()
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

FIG = ROOT / "figures" / "denoiser.png"
CELLS = 96
FIXED_PASSES = tuple(range(1, 11))
#: Multiples of the flat-water floor irradiance tried as `lum(L_min)` (the adaptive levels'
#: thresholds are 0.0114 and 0.057 times it: where a renderer's exposure puts the light's
#: luminance decides which pixels count as dark).
LUM_SCALES = (1.0, 10.0, 100.0)
ADAPTIVE_PASSES = (1, 2, 3, 4)


def image(E: np.ndarray):
    """The map as the filter's inputs: grey colour, constant depth (a camera looking down
    from 1 m above the water), world positions of the cell centres (m)."""
    receiver = receiver_grid(E.shape[0])
    centres = receiver.subsamples(1).reshape(E.shape[0], E.shape[1], 3)
    C = jnp.asarray(np.repeat(E[..., None], 3, -1))
    return C, jnp.full(E.shape, 2.0), jnp.asarray(centres)


def taps(E: np.ndarray, lum_l_min: float) -> float:
    """Contributing samples per pixel of one adaptive pass (x and y sub-pass), at the input."""
    rho, lam, _ = adaptive_kernel_params(jnp.asarray(E), lum_l_min)
    return float(2 * np.mean(2 * np.asarray(rho) / np.asarray(lam)))


def filtered(E: np.ndarray, passes: int, lum_l_min: float) -> tuple[np.ndarray, float]:
    """`passes` denoiser passes (`lum_l_min = 0`: the fixed radius), and the wall time of
    the call after its compile."""
    C, depth, pos = image(E)
    run = jax.jit(lambda C: bilateral_denoise(C, depth, pos, lum_l_min, passes))
    out = np.asarray(run(C))
    t0 = time.perf_counter()
    jax.block_until_ready(run(C))
    return out[..., 0], time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="48 x 48 cells, 2^10 and 2^12 photons")
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
    args = parse_args(ap, argv)
    cells = 48 if args.quick else CELLS
    mesh = pool()
    receiver = receiver_grid(cells)
    ref = reference_map(mesh, receiver)
    cert = certify(mesh, receiver, lanes=64 if args.quick else 256)
    # lum(L_min): the light's irradiance on the floor through flat water at the pool's centre.
    lum_l_min = float(flat_interface_irradiance(np.array([[0.0, 0.0, -1.0]]), LIGHT, 0.0, ETA)[0])
    rows, maps = [], {}
    for p in ((10, 12) if args.quick else (12, 14, 16, 18)):
        pm = photon_irradiance(mesh, LIGHT, intensity=1.0, eta=ETA, receiver=receiver, n_photons=1 << p, seed=p,
                               chunk=1 << 16)
        noisy = pm.irradiance
        row = {"photons": 1 << p, "photons_per_lit_cell": float((1 << p) / np.sum(ref > 0)),
               "unfiltered": errors(noisy, ref), "fixed": [], "adaptive": [],
               "adaptive_taps_per_pass": taps(noisy, lum_l_min), "fixed_taps_per_pass": 20.0}
        for k in FIXED_PASSES:
            E, dt = filtered(noisy, k, 0.0)
            row["fixed"].append({"passes": k, "taps": 20.0 * k, "seconds": dt, **errors(E, ref)})
        for k in ADAPTIVE_PASSES:
            E, dt = filtered(noisy, k, lum_l_min)
            row["adaptive"].append({"passes": k, "taps": row["adaptive_taps_per_pass"] * k, "seconds": dt,
                                    **errors(E, ref)})
            if k == 1:
                maps[p] = (noisy, E, filtered(noisy, 10, 0.0)[0])
        row["adaptive_lum_scales"] = []
        for scale in LUM_SCALES[1:]:
            E, dt = filtered(noisy, 1, scale * lum_l_min)
            row["adaptive_lum_scales"].append({"lum_scale": scale, "passes": 1, "seconds": dt,
                                               "taps": taps(noisy, scale * lum_l_min), **errors(E, ref)})
        a1 = row["adaptive"][0]["rel_L1"]
        better = [f["passes"] for f in row["fixed"] if f["rel_L1"] <= a1]
        row["fixed_passes_to_match_one_adaptive"] = better[0] if better else None
        rows.append(row)
        print(f"2^{p} photons: unfiltered {row['unfiltered']['rel_L1']:.3f}, adaptive x1 {a1:.3f}, "
              f"fixed x1 {row['fixed'][0]['rel_L1']:.3f} x10 {row['fixed'][-1]['rel_L1']:.3f}; fixed passes to "
              f"match: {row['fixed_passes_to_match_one_adaptive']}", flush=True)
    result = {"cells": cells, "certification": cert, "lum_l_min": lum_l_min, "rows": rows,
              "reference_mean": float(ref[ref > 0].mean())}
    write_json(args.json, result)
    plot(result, ref, maps)
    print(table(result))
    return result


def table(result) -> str:
    lines = ["| photons | per lit cell | unfiltered rel L1 | fixed radius, 1 / 2 / 5 / 10 passes | adaptive, 1 / 2 / 4 "
             "passes | 1 adaptive pass, lum(L_min) x10 / x100 | fixed passes matching 1 adaptive | samples per "
             "pixel: 1 adaptive pass (x1 / x10 / x100) / 1 fixed |",
             "|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        f = {x["passes"]: x["rel_L1"] for x in r["fixed"]}
        a = {x["passes"]: x["rel_L1"] for x in r["adaptive"]}
        lines.append(f"| 2^{int(np.log2(r['photons']))} | {r['photons_per_lit_cell']:.2g} | "
                     f"{r['unfiltered']['rel_L1']:.3f} | {f[1]:.3f} / {f[2]:.3f} / {f[5]:.3f} / {f[10]:.3f} | "
                     f"{a[1]:.3f} / {a[2]:.3f} / {a[4]:.3f} | "
                     + " / ".join(f"{x['rel_L1']:.3f}" for x in r["adaptive_lum_scales"])
                     + f" | {r['fixed_passes_to_match_one_adaptive'] or '> 10'} | {r['adaptive_taps_per_pass']:.1f} / "
                     + " / ".join(f"{x['taps']:.1f}" for x in r["adaptive_lum_scales"])
                     + f" / {r['fixed_taps_per_pass']:.0f} |")
    return "\n".join(lines)


def plot(result, ref, maps) -> None:
    fig = plt.figure(figsize=(12, 6.6))
    ax = fig.add_subplot(1, 2, 1)
    for r, color in zip(result["rows"], ("#d62728", "#ff7f0e", "#1f77b4", "#2ca02c"), strict=False):
        n = int(np.log2(r["photons"]))
        ax.plot([x["taps"] for x in r["fixed"]], [x["rel_L1"] for x in r["fixed"]], "o-", color=color, mfc="none",
                label=f"2^{n} photons, fixed radius (1-10 passes)")
        ax.plot([x["taps"] for x in r["adaptive"]], [x["rel_L1"] for x in r["adaptive"]], "s-", color=color,
                label=f"2^{n} photons, adaptive (1-4 passes)")
        ax.axhline(r["unfiltered"]["rel_L1"], color=color, ls=":", lw=0.8)
    ax.set(xlabel="contributing samples per pixel (all passes)", ylabel="relative L1 error against the reference",
           xscale="log", yscale="log", title="Error against the shader's cost (dotted: unfiltered)")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_xticks([10, 20, 50, 100, 200])
    ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.legend(fontsize=7)
    p = min(maps)
    noisy, adaptive, fixed10 = maps[p]
    vmax = float(np.quantile(ref, 0.995))
    for i, (img, title) in enumerate(((ref, "reference (walk + D, certified)"), (noisy, f"photons 2^{p}, unfiltered"),
                                      (adaptive, "adaptive, 1 pass"), (fixed10, "fixed radius, 10 passes"))):
        a = fig.add_subplot(2, 4, 3 + i + (2 if i >= 2 else 0))
        im = a.imshow(img, origin="lower", vmin=0, vmax=vmax, cmap="inferno", extent=(-1.6, 1.6, -1.6, 1.6))
        a.set(title=title, xlabel="x (m)")
        if i % 2 == 0:
            a.set_ylabel("y (m)")
        a.title.set_fontsize(8)
    fig.subplots_adjust(wspace=0.35)
    fig.colorbar(im, ax=fig.axes[1:], shrink=0.7, label="irradiance (W/m² per W/sr)")
    fig.suptitle(f"Seed 004 Fig. 12-13: adaptive-radius against fixed-radius denoising of a photon-traced caustic, "
                 f"{result['cells']}² floor cells", fontsize=10)
    FIG.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIG, dpi=120)
    plt.close(fig)


# %%
if __name__ == "__main__":
    main()
