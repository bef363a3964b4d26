# %% [markdown]
# # Temporal reuse on an animated pool: noise against lag (seed 000 eq. 2-4)
#
# Seed 000 reuses last frame's radiance: previous points whose collection cylinder contains a
# current point and that pass the acceptance test (eq. 4: within the current radius `r`,
# normals within `acos 0.9`, same material) contribute with the Gaussian weight of eq. 3
# (`sigma = 0.75 r`), and the gathered `L_hat` is blended with this frame's resolve by the
# EMA of eq. 2, `alpha L_hat + (1 - alpha) L` (`alpha = 0.8` in the paper): less noise, at
# the price of lag (and blur) when the caustic moves. Kernels: `kernels.gather_previous`,
# `kernels.temporal_ema`.
#
# Measured on the animated pre-focal pool (`scenes.wavy_pool(8192, amplitude=0.1,
# time=k / 30)`, floor 1 m down, 48 x 48 floor cells, 24 frames at 30 frames/s): each
# frame's estimate is brute-force photons binned on the cells (2^16 per frame, a new seed
# each frame: about 28 per lit cell, the noisy input of a real-time pipeline); the exact
# frame is the certified reference map of that frame (walk + D cell averages,
# `experiments.caustic_reference`). The same reuse (a given `alpha` and reuse radius `r` in
# cells) runs on the noisy sequence and on the exact one:
#
# - **error**: the reused noisy map against the exact frame (what the viewer sees);
# - **lag**: the reused *exact* sequence against the exact frame (the bias that history
#   alone adds: trailing, blur);
# - **noise**: the reused noisy map against the reused exact one (what is left of the noise).
#
# All as relative RMS over the lit cells, averaged over the 24 measured frames; 48 frames
# run before them (the animation continuing), so that no trace of the history's first frame
# is left (its weight after them is alpha^48, 0.085 at alpha = 0.95).
#
# Run: `python -m experiments.reuse [--quick]`; writes `figures/reuse.png` and
# `figures/reuse.json`.

# %%
from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from caustics_jax import scenes  # noqa: E402
from caustics_jax.kernels import gather_previous, temporal_ema  # noqa: E402
from caustics_jax.transport import photon_irradiance  # noqa: E402
from experiments.caustic_reference import ETA, LIGHT, errors, receiver_grid, reference_map  # noqa: E402
from experiments.common import ROOT, parse_args, use_agg, write_json  # noqa: E402

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "reuse.png"
FPS = 30.0
ALPHAS = (0.0, 0.5, 0.8, 0.9, 0.95)
RADII = (0.5, 1.0, 2.0)  # reuse radius, in cells
#: Frames run before the measured ones, so that the history holds no trace of its first frame
#: (its weight after them: alpha^WARMUP, 0.085 for alpha = 0.95).
WARMUP = 48


def reuse_sequence(frames: list[np.ndarray], alpha: float, radius: float, centres: np.ndarray) -> list[np.ndarray]:
    """Seed 000's reuse over a sequence of maps on fixed points (a static floor and camera):
    each frame gathers the previous output (eq. 3-4, `gather_previous`) and blends it with
    its own map (eq. 2, `temporal_ema`); where nothing is accepted the frame's map stands."""
    n = centres.shape[0]
    up = jnp.broadcast_to(jnp.asarray([0.0, 0.0, 1.0]), (n, 3))
    m = jnp.zeros(n, jnp.int32)
    r = jnp.full(n, radius)
    p = jnp.asarray(centres)
    step = jax.jit(lambda L_prev, L: _step(p, up, m, r, L_prev, L, alpha))
    out = [frames[0]]
    for L in frames[1:]:
        out.append(np.asarray(step(jnp.asarray(out[-1].reshape(-1)), jnp.asarray(L.reshape(-1)))).reshape(L.shape))
    return out


def _step(p, up, m, r, L_prev, L, alpha):
    L_hat, w = gather_previous(p, up, m, r, p, up, m, r, L_prev)
    return jnp.where(w > 0, temporal_ema(L_hat, L, alpha), L)


def rel_rms(E, ref, lit) -> float:
    """Relative RMS of `E` against `ref` over the cells `lit` (`caustic_reference.errors`)."""
    return errors(E, ref, lit)["rel_rms"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="24 x 24 cells, 12 + 24 frames, 2^14 photons")
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
    args = parse_args(ap, argv)
    cells, measured, photons, warm = (24, 12, 1 << 14, 24) if args.quick else (48, 24, 1 << 16, WARMUP)
    n_frames = warm + measured
    receiver = receiver_grid(cells)
    centres = receiver.subsamples(1).reshape(-1, 3)
    exact, noisy = [], []
    for k in range(n_frames):
        mesh = scenes.wavy_pool(8192, amplitude=0.1, depth=1.0, time=(k - warm) / FPS, dtype=jnp.float64).surface
        exact.append(reference_map(mesh, receiver))
        noisy.append(photon_irradiance(mesh, LIGHT, intensity=1.0, eta=ETA, receiver=receiver, n_photons=photons,
                                       seed=1000 + k, chunk=1 << 16).irradiance)
        if k % 8 == 0:
            print(f"frame {k - warm}", flush=True)
    lit = [e > 0 for e in exact]
    frame_change = float(np.mean([rel_rms(exact[k + 1], exact[k], lit[k]) for k in range(n_frames - 1)]))
    rows = []
    for radius in RADII:
        for alpha in ALPHAS:
            ru_noisy = reuse_sequence(noisy, alpha, radius * receiver.dx, centres)
            ru_exact = reuse_sequence(exact, alpha, radius * receiver.dx, centres)
            ks = range(warm, n_frames)
            row = {"alpha": alpha, "radius_cells": radius,
                   "error": float(np.mean([rel_rms(ru_noisy[k], exact[k], lit[k]) for k in ks])),
                   "lag": float(np.mean([rel_rms(ru_exact[k], exact[k], lit[k]) for k in ks])),
                   "noise": float(np.mean([rel_rms(ru_noisy[k], ru_exact[k], lit[k]) for k in ks]))}
            rows.append(row)
            print(f"r {radius} cells, alpha {alpha}: error {row['error']:.4f} = lag {row['lag']:.4f} (+) noise "
                  f"{row['noise']:.4f}", flush=True)
    no_reuse = next(r for r in rows if r["alpha"] == 0.0 and r["radius_cells"] == RADII[0])
    best = min(rows, key=lambda r: r["error"])
    result = {"cells": cells, "frames": measured, "fps": FPS, "photons_per_frame": photons, "warmup_frames": warm,
              "rows": rows, "no_reuse": no_reuse, "best": best,
              "exact_frame_to_frame_change": frame_change,
              "paper_alpha": next(r for r in rows if r["alpha"] == 0.8 and r["radius_cells"] == 1.0)}
    write_json(args.json, result)
    plot(result)
    print(table(result))
    return result


def table(result) -> str:
    lines = ["| reuse radius (cells) | alpha | error | lag | noise |", "|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['radius_cells']:g} | {r['alpha']:g} | {r['error']:.4f} | {r['lag']:.4f} | "
                     f"{r['noise']:.4f} |")
    return "\n".join(lines)


def plot(result) -> None:
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for radius, color in zip(RADII, ("#1f77b4", "#ff7f0e", "#2ca02c"), strict=True):
        sel = [r for r in result["rows"] if r["radius_cells"] == radius]
        ax[0].plot([r["lag"] for r in sel], [r["noise"] for r in sel], "o-", color=color,
                   label=f"reuse radius {radius:g} cells")
        for r in sel:
            ax[0].annotate(f"{r['alpha']:g}", (r["lag"], r["noise"]), fontsize=7, textcoords="offset points",
                           xytext=(4, 3))
        ax[1].plot([r["alpha"] for r in sel], [r["error"] for r in sel], "o-", color=color,
                   label=f"reuse radius {radius:g} cells")
    ax[0].set(xlabel="lag: reused exact frames against the exact frame (rel. RMS)",
              ylabel="noise: reused photons against reused exact (rel. RMS)",
              title="Noise against lag (labels: EMA weight alpha)")
    ax[1].set(xlabel="EMA weight alpha (eq. 2; the paper: 0.8)", ylabel="error against the exact frame (rel. RMS)",
              yscale="log", title="What the viewer sees")
    ax[1].axhline(result["exact_frame_to_frame_change"], color="k", ls=":", lw=0.8)
    ax[1].annotate("the caustic's own change per frame", (0.0, result["exact_frame_to_frame_change"]), fontsize=7,
                   textcoords="offset points", xytext=(2, 3))
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8)
    photons = int(np.log2(result["photons_per_frame"]))
    fig.suptitle(f"Seed 000 eq. 2-4: temporal reuse on an animated pool, {result['cells']}² floor cells, "
                 f"2^{photons} photons per frame at {result['fps']:g} fps", fontsize=10)
    fig.tight_layout()
    FIG.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIG, dpi=130)
    plt.close(fig)


# %%
if __name__ == "__main__":
    main()
