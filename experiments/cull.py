# %% [markdown]
# # Energy culling: energy removed and error added against photons and solves saved (seed 003)
#
# Seed 003 discards energy below thresholds: mid-trace ("discard the photon if its energy
# is below this threshold"), final ("at the time it is stored ... darker surfaces have less
# photons stored") and the throughput cull of ray-traced refraction paths ("pruned if its
# contribution is estimated less than the thresholds"). On what the testbed traces
# (`kernels.culling`):
#
# - **mid**: a photon's throughput after the water, `beta = T exp(-sigma_t t)` (exact Fresnel
#   transmittance, Beer-Lambert over its path `t`), below `mid`: discarded, not stored;
# - **final**: `albedo * beta` below `final`, the receiver's albedo applied: not stored;
# - **throughput**: a receiver's refracted path, its throughput *estimated before the
#   solve* at the start point `M0` (where `P -> L` crosses the surface), below
#   `min_throughput`: not solved. A receiver without a start point has no estimate and is
#   never culled.
#
# Thresholds are fractions of the emitted energy. The scene is the certified pre-focal pool
# of `experiments.caustic_reference` (8,192 triangles, 10 cm waves, floor 1 m down) with
# water attenuating at `sigma_t = 0.3 / m` and a tiled floor (0.4 m tiles, each of an albedo
# drawn from 0.05-0.8), lit by a point light overhead (the claims' light) and by a low one
# (18 degrees above the horizon, where the Fresnel transmittance spreads from 0.54 to 0.97;
# past the focal distance there, so its reference sums every path on the traced curve,
# certified like the other against the exhaustive solver).
#
# What a viewer sees is the floor's reflected radiance, `albedo * E / pi`: the error is the
# relative L1 of `albedo * E` over the lit cells against the reference (walk + D cell
# averages, certified against the all-path exhaustive solver), in percent. Cost is counted
# as the seed counts it: photons not stored (and not splatted), paths not solved; the
# photons are traced once, and each threshold culls the same photons (2^22 of them, about
# 1,000 per lit cell, so that the culling's bias stands above their noise).
#
# Run: `python -m experiments.cull [--quick]`; writes `figures/cull.png` and
# `figures/cull.json`.

# %%
from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from caustics_jax import interpolated_normal, irradiance, safe_normalize, start_points  # noqa: E402
from caustics_jax.kernels import CullStatus, photon_cull, throughput, throughput_cull  # noqa: E402
from caustics_jax.math.barycentric import barycentric_point  # noqa: E402
from caustics_jax.transport import EmissionPlane, ReceiverGrid, trace_photons  # noqa: E402
from experiments.caustic_reference import ETA, LIGHT, UP, certify, pool, receiver_grid  # noqa: E402
from experiments.caustic_reference import reference_map as caustic_map  # noqa: E402
from experiments.common import ROOT, parse_args, use_agg, write_json  # noqa: E402

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "cull.png"
SIGMA_T = 0.3
LIGHTS = {"overhead": LIGHT, "low": np.array([-4.0, 0.5, 1.5])}
#: The floor: `TILE` m square tiles, each of an albedo drawn uniformly from `ALBEDO`.
TILE, ALBEDO = 0.4, (0.05, 0.8)
MID = (0.0, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.675, 0.7, 0.71, 0.72, 0.73, 0.74)
FINAL = (0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5)
MIN_THROUGHPUT = MID


def albedo(x, y):
    """The floor's albedo at `(x, y)`: tiles of `TILE` m, each its own albedo in `ALBEDO`
    (drawn once, seed 0, for the 64 x 64 tiles around the origin)."""
    table = np.random.default_rng(0).uniform(*ALBEDO, (64, 64))
    i = np.clip(np.floor(x / TILE).astype(np.int64) + 32, 0, 63)
    j = np.clip(np.floor(y / TILE).astype(np.int64) + 32, 0, 63)
    return table[j, i]


def cell_albedo(receiver: ReceiverGrid) -> np.ndarray:
    c = receiver.centers()
    return albedo(c[..., 0], c[..., 1])


def visible_error(E, ref, rho, lit) -> float:
    """Relative L1 of the reflected `albedo * E` against the reference's, over `lit`."""
    return float(np.sum(np.abs(rho * (E - ref))[lit]) / np.sum((rho * ref)[lit]))


def photon_rows(mesh, light, receiver, n_photons, seed):
    """Trace `n_photons` once; for each mid and final threshold, the map of the stored
    photons, the photons culled and the energy (reflected, `albedo beta flux`) removed."""
    plane = EmissionPlane.covering(mesh, light)
    rng = np.random.default_rng(seed)
    X = np.stack([rng.uniform(plane.x0, plane.x1, n_photons), rng.uniform(plane.y0, plane.y1, n_photons),
                  np.full(n_photons, plane.z)], -1)
    h = trace_photons(mesh, light, X, intensity=1.0, area=plane.area / n_photons, eta=ETA, receiver_z=receiver.z)
    beta = np.asarray(throughput(jnp.asarray(h.cos_i), jnp.asarray(h.t), 1 / ETA, SIGMA_T))
    beta = np.where(h.valid, beta, 0.0)
    cell, inside = receiver.cells(h.Y, h.valid)
    rho = np.where(inside, albedo(h.Y[:, 0], h.Y[:, 1]), 0.0)
    arriving = inside.sum()

    def binned(stored):
        w = np.where(inside, stored * h.flux, 0.0)
        return np.bincount(cell, w, receiver.nx * receiver.ny).reshape(receiver.ny, receiver.nx) / receiver.cell_area

    def cull(mid, final):
        stored, status = photon_cull(jnp.asarray(beta), jnp.asarray(rho), jnp.asarray(mid), jnp.asarray(final))
        stored, status = np.asarray(stored), np.asarray(status)
        culled = inside & (status != CullStatus.STORED)
        removed = np.sum((rho * beta * h.flux)[culled]) / np.sum((rho * beta * h.flux)[inside])
        return binned(stored), float(culled.sum() / arriving), float(removed)

    rows = {"mid": [cull(m, 0.0) for m in MID], "final": [cull(0.0, f) for f in FINAL]}
    beta_in = beta[inside]
    return rows, {"beta_percentiles": dict(zip(("p1", "p10", "p50", "p90", "p99"),
                                               np.percentile(beta_in, [1, 10, 50, 90, 99]).tolist(), strict=True)),
                  "photons_arriving": int(arriving), "photons": n_photons}


def solve_rows(mesh, light, receiver, k):
    """Throughput cull of the receivers' paths: the estimate at `M0` against the solved
    path's own throughput, the lanes culled, the (reflected) energy they carried, and the
    map of the kept lanes."""
    P_np = receiver.subsamples(k).reshape(-1, 3)
    P, L = jnp.asarray(P_np), jnp.asarray(light)
    E = np.asarray(irradiance(mesh, P, L, intensity=1.0, eta=ETA, receiver_normal=UP, sigma_t=SIGMA_T,
                              all_paths=True))
    # the throughput the estimate stands for: the walk's path (one per receiver)
    _, sol = irradiance(mesh, P, L, intensity=1.0, eta=ETA, receiver_normal=UP, sigma_t=SIGMA_T,
                        return_solution=True)

    def cos_and_distance(face, ab, ok):
        V, N = mesh.triangle(jnp.where(ok, face, 0))
        M = barycentric_point(V, ab)
        n = safe_normalize(interpolated_normal(N, ab))
        cos_i = jnp.sum(safe_normalize(L - M) * n, -1)
        return np.where(ok, np.asarray(cos_i), 0.0), np.asarray(jnp.linalg.norm(P - M, axis=-1))

    start = start_points(mesh, P, L)
    cos0, d0 = cos_and_distance(start.face, start.barycentric, start.found)
    cos1, d1 = cos_and_distance(sol.triangle, sol.barycentric, sol.found)
    beta_true = np.asarray(throughput(jnp.asarray(cos1), jnp.asarray(d1), 1 / ETA, SIGMA_T))
    rho = albedo(P_np[:, 0], P_np[:, 1])
    lit = E > 0
    rows = []
    for m in MIN_THROUGHPUT:
        beta_hat, keep = throughput_cull(jnp.asarray(cos0), jnp.asarray(d0), jnp.asarray(m), 1 / ETA, SIGMA_T)
        keep = np.asarray(keep) | ~np.asarray(start.found)  # no start point, no estimate: not culled
        E_kept = np.where(keep, E, 0.0).reshape(receiver.ny, receiver.nx, k * k).mean(-1)
        culled = ~keep & start.found
        rows.append((E_kept, float(np.sum(culled) / np.sum(np.asarray(start.found))),
                     float(np.sum((rho * E)[culled]) / np.sum(rho * E)),
                     int(np.sum(culled & lit & (beta_true >= m))), int(np.sum(keep & lit & (beta_true < m)))))
    err = np.asarray(beta_hat)[lit] - beta_true[lit]
    return rows, {"lanes": int(len(P_np)), "estimate_minus_true_throughput": {
        "median_abs": float(np.median(np.abs(err))), "max_abs": float(np.max(np.abs(err)))}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="32 x 32 cells, 2^18 photons, 2 048 triangles")
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
    args = parse_args(ap, argv)
    cells, photons, triangles = (32, 1 << 18, 2048) if args.quick else (64, 1 << 22, 8192)
    mesh = pool(triangles)
    receiver = receiver_grid(cells)
    rho = cell_albedo(receiver)
    result = {"cells": cells, "photons": photons, "triangles": triangles, "sigma_t": SIGMA_T,
              "albedo": {"tile_m": TILE, "range": ALBEDO}, "lights": {}}
    for name, light in LIGHTS.items():
        ref = caustic_map(mesh, receiver, light=light, sigma_t=SIGMA_T, all_paths=True)
        lit = ref > 0
        cert = certify(mesh, receiver, light=light, all_paths=True)
        prow, pinfo = photon_rows(mesh, light, receiver, photons, seed=11)
        srow, sinfo = solve_rows(mesh, light, receiver, 2)
        out = {"light": light.tolist(), "certify": cert, **pinfo, **sinfo}
        for kind, thresholds in (("mid", MID), ("final", FINAL)):
            out[kind] = [{"threshold": t, "saved": s, "energy_removed": e, "error": visible_error(E, ref, rho, lit)}
                         for t, (E, s, e) in zip(thresholds, prow[kind], strict=True)]
        out["throughput"] = [{"threshold": t, "saved": s, "energy_removed": e,
                              "error": visible_error(E, ref, rho, lit), "culled_but_would_pass": a,
                              "kept_but_would_fail": b}
                             for t, (E, s, e, a, b) in zip(MIN_THROUGHPUT, srow, strict=True)]
        result["lights"][name] = out
        print(f"{name}: certify {cert}; beta {pinfo['beta_percentiles']}", flush=True)
    write_json(args.json, result)
    plot(result)
    print(table(result))
    return result


def table(result) -> str:
    lines = ["| light | cull | threshold | work saved | energy removed | error (visible, rel. L1) |",
             "|---|---|---|---|---|---|"]
    for name, out in result["lights"].items():
        for kind in ("mid", "final", "throughput"):
            for r in out[kind]:
                lines.append(f"| {name} | {kind} | {r['threshold']:g} | {100 * r['saved']:.1f}% | "
                             f"{100 * r['energy_removed']:.2f}% | {100 * r['error']:.2f}% |")
    return "\n".join(lines)


def plot(result) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), sharey=True)
    style = {"mid": ("C0", "o", "mid-trace cull (photons not stored)"),
             "final": ("C1", "s", "final cull (photons not stored)"),
             "throughput": ("C2", "^", "throughput cull (paths not solved)")}
    for ax, (name, out) in zip(axes, result["lights"].items(), strict=True):
        ax.plot([0, 100], [0, 100], color="0.6", ls="--", lw=0.8, label="culling at random (energy = work)")
        for kind, (color, marker, label) in style.items():
            rows = out[kind]
            saved = [100 * r["saved"] for r in rows]
            ax.plot(saved, [100 * r["energy_removed"] for r in rows], color=color, marker=marker, label=label)
            for r, x in zip(rows, saved, strict=True):
                if r["threshold"] > 0 and 1 < x < 97:
                    ax.annotate(f"{r['threshold']:g}", (x, 100 * r["energy_removed"]), fontsize=7, color=color,
                                xytext=(4, -9), textcoords="offset points")
        p = out["beta_percentiles"]
        ax.set_title(f"{name} light {out['light']}: throughput after the water\n"
                     f"p1-p99 {p['p1']:.2f}-{p['p99']:.2f} (sigma_t {result['sigma_t']} / m); photon error "
                     f"uncull {100 * out['mid'][0]['error']:.1f}%", fontsize=9)
        ax.set_xlabel("work saved: photons culled or paths not solved (%)")
        ax.set_xlim(0, 100)
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("energy removed: the floor's reflected light\n(albedo x E) the culled carried (%)")
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Seed 003's energy culling on the pre-focal pool: thresholds (labels) as fractions of the "
                 f"emitted energy;\n{result['photons']:,} photons, {result['cells']}^2 cells, tiled floor "
                 f"(albedo {result['albedo']['range'][0]}-{result['albedo']['range'][1]} per tile)", fontsize=9)
    fig.tight_layout()
    fig.savefig(FIG, dpi=130)
    plt.close(fig)


if __name__ == "__main__":
    main()
