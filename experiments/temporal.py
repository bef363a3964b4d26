# %% [markdown]
# # Temporal consistency on an animated pool (seed 001 §5.4)
#
# Seed 001 §5.4 calls its images "noise-free and temporally consistent". On an animated pool
# (`scenes.wavy_pool(..., time=t)`: the Gerstner waves advance with their deep-water
# dispersion; `time=0`, the default, is today's mesh), frame by frame at 30 frames/s, the
# floor irradiance of 32 x 32 receivers (cell centres) is computed by
#
# - the walk alone (`Walk(fallback="none")`, seed 001's method: one path per receiver),
# - the one-step Newton (`newton-hv-step`: one path per receiver, from the same `M0`),
# - the all-path reference (`irradiance(..., method="exhaustive", all_paths=True)`: every
#   refracted path on the mesh, float64, certified),
# - brute-force photons binned on the same cells (2^20 per frame, a new seed per frame).
#
# The pool is past its focal distance (amplitude 0.3 m, floor 3 m down): several paths
# reach many receivers, so a single-path solver must pick one. Flicker metrics, per frame
# pair: the excess change, `sum |dE - dE_ref| / sum E_ref` (`dE` the frame-to-frame change of a
# method's map, `dE_ref` the reference's own); the error against the reference,
# `sum |E - E_ref| / sum E_ref`; and for the two solvers the lanes whose solution **jumps**
# to another path: FOUND in both frames with the point moving by more than `JUMP = 10` times
# the surface's own largest vertex displacement between the frames (a path followed
# continuously moves with the surface, by about its displacement divided by the slope of
# the light's path through it), plus the lanes that gain or lose their path.
#
# Run: `python -m experiments.temporal [--quick]`; writes `figures/temporal.png` and
# `figures/temporal.json`.

# %%
from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from caustics_jax import Newton, Status, Walk, scenes, solve  # noqa: E402
from caustics_jax.transport import ReceiverGrid, irradiance, photon_irradiance  # noqa: E402
from experiments.caustic_reference import ETA, LIGHT, UP  # noqa: E402  (the same light and water)
from experiments.common import ROOT, parse_args, use_agg, write_json  # noqa: E402

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "temporal.png"
DEPTH, AMPLITUDE, TRIANGLES = 3.0, 0.3, 2048
FPS = 30.0
#: A solution jumps when its point moves by more than this many surface displacements.
JUMP = 10.0
SOLVERS = {"walk": Walk(fallback="none"), "newton": Newton(stepping="one_step", constraint="half_vector")}


def frame(t: float, P, receiver, photons: int, seed: int) -> dict:
    mesh = scenes.wavy_pool(TRIANGLES, amplitude=AMPLITUDE, depth=DEPTH, time=t, dtype=jnp.float64).surface
    L = jnp.asarray(LIGHT)
    out = {"vertices": np.asarray(mesh.vertices)}
    for name, method in SOLVERS.items():
        E, sol = irradiance(mesh, P, L, intensity=1.0, eta=ETA, receiver_normal=UP, method=method, features=None,
                            return_solution=True)
        out[name] = {"E": np.asarray(E), "M": np.asarray(sol.point), "found": np.asarray(sol.status) == Status.FOUND}
    out["reference"] = {"E": np.asarray(irradiance(mesh, P, L, intensity=1.0, eta=ETA, receiver_normal=UP,
                                                   method="exhaustive", all_paths=True))}
    out["paths"] = np.asarray(solve(mesh, P, jnp.broadcast_to(L, P.shape), eta=ETA, method="exhaustive",
                                    return_all=True).count)
    pm = photon_irradiance(mesh, LIGHT, intensity=1.0, eta=ETA, receiver=receiver, n_photons=photons, seed=seed,
                           chunk=1 << 16)
    out["photons"] = {"E": pm.irradiance.reshape(-1)}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="16 x 16 receivers, 6 frames, 2^16 photons")
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
    args = parse_args(ap, argv)
    n, frames, photons = (16, 6, 1 << 16) if args.quick else (32, 16, 1 << 20)
    receiver = ReceiverGrid(-DEPTH, -1.6, 1.6, -1.6, 1.6, n, n)
    P = jnp.asarray(receiver.subsamples(1).reshape(-1, 3))
    runs = [frame(k / FPS, P, receiver, photons, seed=k) for k in range(frames)]
    methods = list(SOLVERS) + ["photons"]
    pairs = []
    for k in range(frames - 1):
        a, b = runs[k], runs[k + 1]
        ref_a, ref_b = a["reference"]["E"], b["reference"]["E"]
        total = float(np.sum(ref_a))
        d_ref = ref_b - ref_a
        surf = float(np.max(np.linalg.norm(b["vertices"] - a["vertices"], axis=-1)))
        row = {"frame": k, "surface_displacement_m": surf, "reference_change": float(np.sum(np.abs(d_ref)) / total),
               "reference_path_count_changes": int(np.sum(a["paths"] != b["paths"]))}
        for m in methods:
            d = b[m]["E"] - a[m]["E"]
            row[m] = {"change": float(np.sum(np.abs(d)) / total),
                      "excess_change": float(np.sum(np.abs(d - d_ref)) / total),
                      "error": float(np.sum(np.abs(a[m]["E"] - ref_a)) / total)}
            if m in SOLVERS:
                both = a[m]["found"] & b[m]["found"]
                moved = np.linalg.norm(b[m]["M"] - a[m]["M"], axis=-1)
                row[m]["jumps"] = int(np.sum(both & (moved > JUMP * surf)))
                row[m]["found_changes"] = int(np.sum(a[m]["found"] != b[m]["found"]))
        pairs.append(row)
        print(f"frames {k}-{k + 1}: ref change {row['reference_change']:.3f}; "
              + "; ".join(f"{m} excess {row[m]['excess_change']:.3f}" for m in methods)
              + f"; jumps walk {row['walk']['jumps']} newton {row['newton']['jumps']}", flush=True)
    multi = np.mean([np.mean(r["paths"] > 1) for r in runs])
    summary = {m: {k: float(np.mean([p[m][k] for p in pairs])) for k in pairs[0][m]} for m in methods}
    result = {"receivers": int(P.shape[0]), "frames": frames, "fps": FPS, "photons_per_frame": photons,
              "triangles": TRIANGLES, "amplitude": AMPLITUDE, "depth": DEPTH, "jump_factor": JUMP,
              "share_of_receivers_with_several_paths": float(multi),
              "mean_paths_per_receiver": float(np.mean([r["paths"].mean() for r in runs])),
              "pairs": pairs, "summary": summary,
              "reference_change_mean": float(np.mean([p["reference_change"] for p in pairs]))}
    write_json(args.json, result)
    plot(result, runs, n)
    print(table(result))
    return result


def table(result) -> str:
    lines = ["| method | error against the reference | frame-to-frame change | excess change (vs the reference's "
             "own) | path jumps per frame pair | lanes gaining or losing a path per pair |",
             "|---|---|---|---|---|---|"]
    for m, s in result["summary"].items():
        jumps = f"{s['jumps']:.1f}" if "jumps" in s else "-"
        changes = f"{s['found_changes']:.1f}" if "found_changes" in s else "-"
        lines.append(f"| {m} | {s['error']:.3f} | {s['change']:.3f} | {s['excess_change']:.3f} | {jumps} | "
                     f"{changes} |")
    lines.append(f"| reference (all paths) | 0 | {result['reference_change_mean']:.3f} | 0 | - | - |")
    return "\n".join(lines)


def plot(result, runs, n) -> None:
    fig = plt.figure(figsize=(12, 6.4))
    ax = fig.add_subplot(1, 2, 1)
    x = [p["frame"] + 0.5 for p in result["pairs"]]
    ax.plot(x, [p["reference_change"] for p in result["pairs"]], "k-", lw=2, label="reference: its own change")
    colors = {"walk": "#1f77b4", "newton": "#d62728", "photons": "#7f7f7f"}
    labels = {"walk": "walk alone (one path)", "newton": "one-step Newton (one path)",
              "photons": f"photons, 2^{int(np.log2(result['photons_per_frame']))} per frame"}
    for m, c in colors.items():
        ax.plot(x, [p[m]["excess_change"] for p in result["pairs"]], "o-", color=c, label=f"{labels[m]}: excess change")
        ax.plot(x, [p[m]["error"] for p in result["pairs"]], ":", color=c, label=f"{labels[m]}: error")
    ax.set(xlabel=f"frame pair (frame {1 / result['fps'] * 1000:.0f} ms)", yscale="log",
           ylabel="sum |dE - dE_ref| / sum E_ref  (solid)\nsum |E - E_ref| / sum E_ref  (dotted)",
           title="Flicker and error per frame pair")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    k = max(range(len(result["pairs"])), key=lambda i: result["pairs"][i]["walk"]["excess_change"])
    ref_d = (runs[k + 1]["reference"]["E"] - runs[k]["reference"]["E"]).reshape(n, n)
    walk_d = (runs[k + 1]["walk"]["E"] - runs[k]["walk"]["E"]).reshape(n, n)
    newton_d = (runs[k + 1]["newton"]["E"] - runs[k]["newton"]["E"]).reshape(n, n)
    vmax = float(np.quantile(np.abs(ref_d), 0.99)) or 1.0
    for i, (img, title) in enumerate(((runs[k]["reference"]["E"].reshape(n, n), f"reference E, frame {k}"),
                                      (ref_d, "reference change"), (walk_d, "walk's change"),
                                      (newton_d, "Newton's change"))):
        a = fig.add_subplot(2, 4, (3, 4, 7, 8)[i])
        if i == 0:  # (the folds' peaks would set the scale: clipped at the 98th percentile)
            im0 = a.imshow(img, origin="lower", cmap="inferno", vmin=0, vmax=float(np.quantile(img, 0.98)),
                           extent=(-1.6, 1.6, -1.6, 1.6))
            cb = fig.colorbar(im0, ax=a, orientation="horizontal", shrink=0.9, pad=0.28)
            cb.set_label("E (W/m² per W/sr)", fontsize=7)
            cb.ax.tick_params(labelsize=6)
        else:
            im = a.imshow(img, origin="lower", cmap="RdBu_r", vmin=-vmax, vmax=vmax, extent=(-1.6, 1.6, -1.6, 1.6))
        a.set(title=f"{title} (frames {k}-{k + 1})" if i else title, xlabel="x (m)")
        if i % 2 == 0:
            a.set_ylabel("y (m)")
        a.title.set_fontsize(8)
    fig.subplots_adjust(wspace=0.6)
    fig.colorbar(im, ax=fig.axes[-3:], shrink=0.6, label="change of E (W/m² per W/sr)")
    fig.suptitle(f"Seed 001 §5.4: temporal consistency on an animated pool ({result['triangles']} triangles, "
                 f"{result['amplitude'] * 100:g} cm waves, floor {result['depth']:g} m down, {result['fps']:g} fps; "
                 f"{100 * result['share_of_receivers_with_several_paths']:.1f}% of receivers reached by several paths)",
                 fontsize=10)
    FIG.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIG, dpi=120)
    plt.close(fig)


# %%
if __name__ == "__main__":
    main()
