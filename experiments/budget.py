# %% [markdown]
# # The adaptive photon budget in light space, against uniform allocation (seed 003)
#
# Seed 003 allocates each frame's photons from feedback buffers in light-view space: every
# stored photon adds its footprint to the texel it left through, and the next frame gives
# "high density and closeup regions ... more photons with smaller size", the previous
# frame's buffer mixed in for temporal stability. The testbed has no camera, so the
# footprint is measured on the receiver (`kernels.photon_budget`): a photon landing in a
# cell holding `h` photons covers `cell_area / h`, a texel's footprint is the sum over its
# photons, and the budget gives a texel `total (floor / T + (1 - floor) w / sum w)` photons
# with `w = footprint^gamma` (`floor = 0.25`, `T` texels). `gamma = 1` equalises the
# photon density over the receiver (the seed's target); each texel's photons stand for its
# area over their count, so every allocation is unbiased and only the noise differs.
#
# Measured on the animated pre-focal pool of `experiments.reuse` (8,192 triangles, 10 cm
# waves, floor 1 m down, 30 frames/s) with 48 x 48 floor cells, a 64 x 64 feedback buffer on
# the emission plane and 2^18 photons per frame for every method (equal photon count): the
# uniform baseline emits the same count uniformly (stratified per texel, as the adaptive
# ones are); the feedback is smoothed over frames by seed 000 eq. 2's EMA (`alpha = 0.5`).
# Per frame, against the certified reference (`experiments.caustic_reference`):
#
# - relative L1 over the lit cells (the energy-weighted error),
# - relative RMS of the per-cell *relative* error, `sqrt(mean((E / E_ref - 1)^2))` over the
#   lit cells (what a viewer's contrast sensitivity weighs: dim cells count as much);
#
# and for temporal stability the excess flicker of `experiments.temporal`,
# `sum |dE - dE_ref| / sum E_ref` between frames. Density estimation predicts the optimum:
# with `h` photons in a cell of irradiance `E` the L1 error sums `E / sqrt(h)`, minimal for
# `h ~ E^(2/3)`, that is `gamma = 1/3`; the per-cell relative error is minimal for equal
# `h`, `gamma = 1`. `gamma = 0` (uniform over the texels whose photons reached the receiver
# last frame) separates the gain of not emitting where nothing is seen from that of the
# density target.
#
# Run: `python -m experiments.budget [--quick]`; writes `figures/budget.png` and
# `figures/budget.json`.

# %%
from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from caustics_jax import scenes  # noqa: E402
from caustics_jax.kernels import BUDGET_FLOOR, photon_budget, temporal_ema  # noqa: E402
from caustics_jax.transport import EmissionPlane, trace_photons  # noqa: E402
from experiments.caustic_reference import ETA, LIGHT, errors, receiver_grid, reference_map  # noqa: E402
from experiments.common import ROOT, parse_args, use_agg, write_json  # noqa: E402

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "budget.png"
FPS = 30.0
GAMMAS = (0.0, 1 / 3, 2 / 3, 1.0)
#: EMA weight of the previous feedback (seed 000 eq. 2's alpha).
HISTORY = 0.5


def rounded(budget: np.ndarray) -> np.ndarray:
    """Whole photons per texel summing to `round(sum(budget))`, each within 1 of its budget."""
    c = np.round(np.cumsum(budget.reshape(-1)))
    return np.diff(np.concatenate([[0.0], c])).astype(np.int64)


def emit(plane: EmissionPlane, counts: np.ndarray, g: int, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`counts[t]` photons uniform in each of the `g x g` texels of `plane`: points, the
    emission-plane area each stands for, and its texel."""
    texel = np.repeat(np.arange(g * g), counts)
    u = rng.uniform(0, 1, (len(texel), 2))
    dx, dy = (plane.x1 - plane.x0) / g, (plane.y1 - plane.y0) / g
    X = np.stack([plane.x0 + (texel % g + u[:, 0]) * dx, plane.y0 + (texel // g + u[:, 1]) * dy,
                  np.full(len(texel), plane.z)], -1)
    return X, dx * dy / counts[texel], texel


def frame_map(mesh, plane, counts, g, receiver, rng):
    """The photon map of one frame and each texel's receiver footprint (seed 003 feedback)."""
    X, area, texel = emit(plane, counts, g, rng)
    h = trace_photons(mesh, LIGHT, X, intensity=1.0, area=area, eta=ETA, receiver_z=receiver.z)
    cell, inside = receiver.cells(h.Y, h.valid)
    n_cells = receiver.nx * receiver.ny
    w = np.where(inside, h.flux * h.T, 0.0)
    E = np.bincount(cell, w, n_cells).reshape(receiver.ny, receiver.nx) / receiver.cell_area
    hits = np.bincount(cell[inside], minlength=n_cells)
    share = np.where(inside, receiver.cell_area / np.maximum(hits[cell], 1), 0.0)
    footprint = np.bincount(texel, share, g * g).reshape(g, g)
    return E, footprint, float(inside.mean())


def rel_cell_rms(E, ref, lit) -> float:
    return float(np.sqrt(np.mean((E[lit] / ref[lit] - 1) ** 2)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="24 x 24 cells, 32^2 texels, 2^15 photons, 3 + 6 frames")
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
    args = parse_args(ap, argv)
    cells, g, photons, warm, measured, triangles = (24, 32, 1 << 15, 3, 6, 2048) if args.quick else \
        (48, 64, 1 << 18, 4, 16, 8192)
    receiver = receiver_grid(cells)
    methods = ["uniform", *(f"gamma={gm:.2f}" for gm in GAMMAS)]
    feedback = {m: None for m in methods[1:]}
    maps: dict[str, list] = {m: [] for m in methods}
    on_receiver: dict[str, list] = {m: [] for m in methods}
    refs, spread = [], {}
    rng = np.random.default_rng(2026)
    for k in range(warm + measured):
        mesh = scenes.wavy_pool(triangles, amplitude=0.1, depth=1.0, time=(k - warm) / FPS,
                                dtype=jnp.float64).surface
        plane = EmissionPlane.covering(mesh, LIGHT)
        uniform = rounded(np.full(g * g, photons / (g * g)))
        E, _, landed = frame_map(mesh, plane, uniform, g, receiver, rng)
        maps["uniform"].append(E)
        on_receiver["uniform"].append(landed)
        for m, gamma in zip(methods[1:], GAMMAS, strict=True):
            fb = feedback[m]
            counts = uniform if fb is None else rounded(np.asarray(photon_budget(jnp.asarray(fb), photons, gamma)))
            E, footprint, landed = frame_map(mesh, plane, np.maximum(counts, 1), g, receiver, rng)
            maps[m].append(E)
            on_receiver[m].append(landed)
            feedback[m] = footprint if fb is None else np.asarray(temporal_ema(jnp.asarray(fb), jnp.asarray(footprint),
                                                                               HISTORY))
            spread[m] = counts
        refs.append(reference_map(mesh, receiver) if k >= warm - 1 else None)
        print(f"frame {k - warm}", flush=True)
    ks = range(warm, warm + measured)
    rows = []
    for m in methods:
        l1 = [errors(maps[m][k], refs[k])["rel_L1"] for k in ks]
        rel = [rel_cell_rms(maps[m][k], refs[k], refs[k] > 0) for k in ks]
        flick = [float(np.sum(np.abs((maps[m][k] - maps[m][k - 1]) - (refs[k] - refs[k - 1])))
                       / np.sum(refs[k])) for k in ks]
        counts = spread.get(m, rounded(np.full(g * g, photons / (g * g))))
        rows.append({"method": m, "rel_L1": float(np.mean(l1)), "rel_L1_frames": l1,
                     "rel_cell_rms": float(np.mean(rel)), "excess_flicker": float(np.mean(flick)),
                     "photons_per_frame": int(counts.sum()),
                     "share_on_receiver": float(np.mean([on_receiver[m][k] for k in ks])),
                     "texel_photons_min_max": [int(counts.min()), int(counts.max())]})
        print(rows[-1]["method"], {k: v for k, v in rows[-1].items() if k not in ("method", "rel_L1_frames")},
              flush=True)
    reference_change = float(np.mean([np.sum(np.abs(refs[k] - refs[k - 1])) / np.sum(refs[k]) for k in ks]))
    result = {"cells": cells, "texels": g, "photons_per_frame": photons, "frames": measured, "warmup_frames": warm,
              "fps": FPS, "floor": BUDGET_FLOOR, "history_alpha": HISTORY, "triangles": triangles,
              "reference_frame_change": reference_change, "rows": rows,
              "last_allocation": {m: spread[m].reshape(g, g).tolist() for m in methods[1:]}}
    write_json(args.json, result)
    plot(result)
    print(table(result))
    return result


def table(result) -> str:
    lines = ["| allocation | rel. L1 | rel. per-cell RMS | excess flicker | photons on the receiver | "
             "photons per texel (min-max) |", "|---|---|---|---|---|---|"]
    for r in result["rows"]:
        lo, hi = r["texel_photons_min_max"]
        lines.append(f"| {r['method']} | {r['rel_L1']:.4f} | {r['rel_cell_rms']:.4f} | {r['excess_flicker']:.4f} | "
                     f"{100 * r['share_on_receiver']:.0f}% | {lo}-{hi} |")
    return "\n".join(lines)


def plot(result) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    rows = result["rows"]
    names = [r["method"].replace("gamma=", "adaptive\ngamma ") for r in rows]
    x = np.arange(len(rows))
    for off, key, label in ((-0.27, "rel_L1", "rel. L1 (energy-weighted)"),
                            (0.0, "rel_cell_rms", "rel. per-cell RMS (every lit cell alike)"),
                            (0.27, "excess_flicker", "excess flicker between frames")):
        axes[0].bar(x + off, [r[key] for r in rows], width=0.26, label=label)
    axes[0].set_xticks(x, names, fontsize=8)
    axes[0].set_ylabel("error against the certified reference (fraction)")
    axes[0].set_title(f"equal photons: {result['photons_per_frame']:,} per frame, mean of {result['frames']} frames",
                      fontsize=9)
    axes[0].legend(fontsize=7)
    axes[0].grid(alpha=0.3, axis="y")
    for r in rows:
        axes[1].plot(np.arange(len(r["rel_L1_frames"])), r["rel_L1_frames"], marker=".", label=r["method"])
    axes[1].set_xlabel(f"frame (at {result['fps']:g} frames/s)")
    axes[1].set_ylabel("rel. L1 against the frame's reference")
    axes[1].set_title("per frame: the feedback follows the moving caustic", fontsize=9)
    axes[1].legend(fontsize=7)
    axes[1].grid(alpha=0.3)
    alloc = np.asarray(result["last_allocation"]["gamma=1.00"], float)
    im = axes[2].imshow(alloc, origin="lower", cmap="magma")
    fig.colorbar(im, ax=axes[2], label="photons per texel")
    axes[2].set_title(f"light-space budget, gamma 1 (last frame, {result['texels']}^2 texels\n"
                      "on the emission plane; seed 003 Fig. 6's debug view)", fontsize=9)
    axes[2].set_xlabel("emission-plane texel x")
    axes[2].set_ylabel("emission-plane texel y")
    fig.suptitle("Seed 003's adaptive photon budget (feedback from the previous frame's receiver footprint) "
                 "against uniform emission, animated pre-focal pool", fontsize=10)
    fig.tight_layout()
    fig.savefig(FIG, dpi=130)
    plt.close(fig)


if __name__ == "__main__":
    main()
