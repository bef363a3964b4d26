# %% [markdown]
# # Photon differentials against plain photons (seed 004 Fig. 10-11)
#
# Seed 004 §3.2 and Fig. 10-11: photons carrying differentials (their footprints) give the
# same or better caustic quality with a smaller caustic map (fewer photons) than photons
# splatted as points. Measured here against the certified reference caustic
# (`experiments.caustic_reference`: the pre-focal Gerstner pool, 96 x 96 floor cells,
# walk + D cell averages, certified by the exhaustive all-path irradiance) with three
# estimators of the same floor map:
#
# - **random photons, binned** (`photon_irradiance`: emission uniform over the light-view
#   plane, each photon's flux into the cell it lands in; the unbiased Monte-Carlo estimate);
# - **caustic-map photons, binned**: one photon per texel of a `res x res` light-view map
#   (`light_view_texels`, the caustic map of seed 004 §3.1), landing points binned as points
#   (no differential);
# - **caustic-map photons with differentials**: the same texels, each splatted as a
#   flux-conserving anisotropic Gaussian of its exact footprint (`texel_jacobian`,
#   `splat_footprints`: seed 003's elliptical footprints).
#
# Map resolutions 32 to 512 (1k to 262k photons). Errors: relative L1 and RMS over the lit
# cells (W/m^2 per W/sr); the photon ratio at equal error is read off the random photons'
# error curve (log-log interpolation, or its fitted power law beyond the largest count,
# marked extrapolated) at the differentials' error.
#
# Run: `python -m experiments.differential [--quick]`; writes `figures/differential.png` and
# `figures/differential.json`.

# %%
from __future__ import annotations

import argparse
import time

import numpy as np

from caustics_jax.transport import photon_irradiance
from experiments.caustic_reference import ETA, LIGHT, certify, errors, pool, receiver_grid, reference_map
from experiments.common import ROOT, parse_args, use_agg, write_json
from experiments.irradiance_agreement import pd_map, texel_photons

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "differential.png"
CELLS = 96
RESOLUTIONS = (32, 64, 128, 256, 512)
RANDOM_PHOTONS = tuple(1 << p for p in range(10, 23, 2))


def binned(ph, receiver) -> np.ndarray:
    """Caustic-map photons as points: each texel's flux into the cell it lands in, per area."""
    ok = ph["ok"].reshape(-1)
    Y = ph["Y"].reshape(-1, 3)[ok]
    flux = ph["flux"].reshape(-1)[ok]
    H, _, _ = np.histogram2d(Y[:, 1], Y[:, 0], bins=(receiver.ny, receiver.nx),
                             range=((receiver.y0, receiver.y1), (receiver.x0, receiver.x1)), weights=flux)
    return H / (receiver.dx * receiver.dy)


def photons_at(curve_n, curve_err, err) -> tuple[float, bool]:
    """The photon count of the random photons' error curve at error `err`: log-log
    interpolation inside the measured range, else extrapolated along the power law fitted to
    its three largest counts (Monte Carlo: slope about -1/2). Returns `(count, extrapolated)`."""
    n, e = np.log(np.asarray(curve_n, float)), np.log(np.asarray(curve_err, float))
    order = np.argsort(e)
    if e.min() <= np.log(err) <= e.max():
        return float(np.exp(np.interp(np.log(err), e[order], n[order]))), False
    slope, icpt = np.polyfit(n[-3:], e[-3:], 1)
    return float(np.exp((np.log(err) - icpt) / slope)), True


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="48 x 48 cells, map resolutions up to 128")
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
    args = parse_args(ap, argv)
    cells = 48 if args.quick else CELLS
    resolutions = RESOLUTIONS[:3] if args.quick else RESOLUTIONS
    mesh = pool()
    receiver = receiver_grid(cells)
    ref = reference_map(mesh, receiver)
    cert = certify(mesh, receiver, lanes=64 if args.quick else 256)
    random_rows = []
    for n in (RANDOM_PHOTONS[:4] if args.quick else RANDOM_PHOTONS):
        t0 = time.perf_counter()
        pm = photon_irradiance(mesh, LIGHT, intensity=1.0, eta=ETA, receiver=receiver, n_photons=n, seed=n,
                               chunk=1 << 16)
        random_rows.append({"photons": n, "seconds": time.perf_counter() - t0, **errors(pm.irradiance, ref)})
        print(f"random photons {n}: rel L1 {random_rows[-1]['rel_L1']:.4f}", flush=True)
    map_rows, maps = [], {}
    for res in resolutions:
        t0 = time.perf_counter()
        ph = texel_photons(mesh, res, 1.0)
        t_trace = time.perf_counter() - t0
        E_bin = binned(ph, receiver)
        t0 = time.perf_counter()
        E_pd = np.asarray(pd_map(ph, receiver))
        t_splat = time.perf_counter() - t0
        row = {"resolution": res, "photons": res * res, "lit_photons": int(ph["ok"].sum()), "trace_seconds": t_trace,
               "splat_seconds": t_splat, "binned": errors(E_bin, ref), "differentials": errors(E_pd, ref)}
        eq, extrapolated = photons_at([r["photons"] for r in random_rows], [r["rel_L1"] for r in random_rows],
                                      row["differentials"]["rel_L1"])
        row["random_photons_at_equal_error"], row["extrapolated"] = eq, extrapolated
        row["photon_ratio"] = eq / row["photons"]
        map_rows.append(row)
        maps[res] = (E_bin, E_pd)
        print(f"map {res}^2: binned {row['binned']['rel_L1']:.4f}, differentials {row['differentials']['rel_L1']:.4f}"
              f", random photons at equal error {row['random_photons_at_equal_error']}", flush=True)
    result = {"cells": cells, "certification": cert, "random": random_rows, "caustic_map": map_rows}
    write_json(args.json, result)
    plot(result, ref, maps)
    print(table(result))
    return result


def table(result) -> str:
    lines = ["| caustic map | photons | binned as points: rel L1 (RMS) | with differentials: rel L1 (RMS) | "
             "random photons at the differentials' error | photon ratio |", "|---|---|---|---|---|---|"]
    for r in result["caustic_map"]:
        eq = r["random_photons_at_equal_error"]
        eq_s = f"{eq:.3g}" + (" (extrapolated)" if r["extrapolated"] else "")
        ratio = f"{r['photon_ratio']:.3g}"
        lines.append(f"| {r['resolution']}² | {r['photons']} | {r['binned']['rel_L1']:.4f} "
                     f"({r['binned']['rel_rms']:.4f}) | {r['differentials']['rel_L1']:.4f} "
                     f"({r['differentials']['rel_rms']:.4f}) | "
                     f"{eq_s} | {ratio} |")
    lines += ["", "| random photons | rel L1 (RMS) |", "|---|---|"]
    lines += [f"| {r['photons']} | {r['rel_L1']:.4f} ({r['rel_rms']:.4f}) |" for r in result["random"]]
    return "\n".join(lines)


def plot(result, ref, maps) -> None:
    fig = plt.figure(figsize=(12, 5.6))
    ax = fig.add_subplot(1, 2, 1)
    ax.plot([r["photons"] for r in result["random"]], [r["rel_L1"] for r in result["random"]], "o-", color="0.4",
            label="random photons, binned (Monte Carlo)")
    m = result["caustic_map"]
    ax.plot([r["photons"] for r in m], [r["binned"]["rel_L1"] for r in m], "s--", color="#1f77b4",
            label="caustic-map photons, binned as points")
    ax.plot([r["photons"] for r in m], [r["differentials"]["rel_L1"] for r in m], "D-", color="#d62728",
            label="caustic-map photons with differentials (footprints)")
    for r in m:
        ax.annotate(f"{r['resolution']}²", (r["photons"], r["differentials"]["rel_L1"]), fontsize=7,
                    textcoords="offset points", xytext=(4, -10))
    ax.set(xscale="log", yscale="log", xlabel="photons (caustic map: resolution²)",
           ylabel="relative L1 error against the reference", title="Error against photon count")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    res = sorted(maps)[len(maps) // 2]
    E_bin, E_pd = maps[res]
    vmax = float(np.quantile(ref, 0.995))
    for i, (img, title) in enumerate(((ref, "reference (walk + D, certified)"), (E_bin, f"map {res}², binned"),
                                      (E_pd, f"map {res}², differentials"))):
        a = fig.add_subplot(2, 4, (3, 4, 7)[i])
        im = a.imshow(img, origin="lower", vmin=0, vmax=vmax, cmap="inferno", extent=(-1.6, 1.6, -1.6, 1.6))
        a.set(title=title, xlabel="x (m)", ylabel="y (m)")
        a.title.set_fontsize(8)
    fig.colorbar(im, ax=fig.axes[1:], shrink=0.7, label="irradiance (W/m² per W/sr)")
    fig.suptitle(f"Seed 004 Fig. 10-11: photon differentials against plain photons, {result['cells']}² floor cells "
                 f"of the pre-focal pool", fontsize=10)
    FIG.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIG, dpi=120)
    plt.close(fig)


# %%
if __name__ == "__main__":
    main()
