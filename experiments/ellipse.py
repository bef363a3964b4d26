# %% [markdown]
# # How often is the curve an ellipse inside one triangle? (seed 001 §3.4.4, Fig. 6)
#
# Seed 001 §3.4.4: when the coplanarity conic of a lane crosses no edge of the start
# triangle, it is an ellipse entirely inside that triangle, which the edge-crossing walk
# cannot follow; the paper samples it by subdividing the triangle and says the case
# "happens rarely (see Figure 6)". It adds that such ellipses inside *other* triangles are
# not detected at all ("Since there is no curve that intersects its edges, we cannot reach
# that triangle").
#
# Measured here, on the Gerstner pool (`scenes.wavy_pool`, 4 waves, floor 1 m down, the
# default point light) against tessellation (512 to 32,768 triangles) and wave amplitude
# (1 to 15 cm), float64:
#
# - **start-triangle ellipses**: the share of lanes whose conic in the start triangle is an
#   interior ellipse (`arc_roots.interior_ellipse`: a real ellipse, its centre inside the
#   face, no edge root; the conic passes through `M0`, so the ellipse is the curve through
#   `M0`), and what those lanes cost the walk (`Walk(fallback="none")`: iterations, statuses)
#   against the other lanes;
# - **ellipses elsewhere**: on 256 lanes per configuration, the faces of the whole mesh whose
#   conic for that lane is an interior ellipse (closed components the walk from `M0` never
#   reaches), and how many of those ellipses hold a refracted path (a sign change of `f` on
#   them: the exhaustive reference's root finder on that face's arcs), i.e. paths the walk
#   misses for this reason.
#
# Run: `python -m experiments.ellipse [--quick]`; writes `figures/ellipse.png` and
# `figures/ellipse.json`.

# %%
from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from caustics_jax import Status, Walk, prepare, scenes, solve  # noqa: E402
from caustics_jax.curve.arc_roots import interior_ellipse  # noqa: E402
from caustics_jax.math.conic import conic_coefficients  # noqa: E402
from caustics_jax.solvers import Exhaustive  # noqa: E402
from experiments.common import ROOT, parse_args, use_agg, write_json  # noqa: E402

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "ellipse.png"
TRIANGLES = (512, 2048, 8192, 32768)
AMPLITUDES = (0.01, 0.03, 0.08, 0.15)
#: Lanes whose whole mesh is scanned for interior ellipses, per configuration.
SCAN_LANES = 256


@jax.jit
def _ellipse_flags(V, N, P, L):
    """Per row (a lane's face): is the lane's conic an interior ellipse of that face?"""
    coef = conic_coefficients(V, N, P, L)
    return jax.vmap(lambda c: interior_ellipse(c)[3])(coef)


def ellipse_faces(mesh, P, L, chunk=1 << 16):
    """`(lanes, F)` bool: the faces whose conic for each lane is an interior ellipse."""
    V_all, N_all = mesh.triangle(jnp.arange(mesh.faces.shape[0]))
    F = V_all.shape[0]
    out = np.zeros((P.shape[0], F), bool)
    for i in range(P.shape[0]):
        for lo in range(0, F, chunk):
            hi = min(lo + chunk, F)
            pad = chunk - (hi - lo)
            V = jnp.pad(V_all[lo:hi], ((0, pad), (0, 0), (0, 0)), mode="edge")
            N = jnp.pad(N_all[lo:hi], ((0, pad), (0, 0), (0, 0)), mode="edge")
            rep = lambda x: jnp.broadcast_to(x, (chunk, 3))  # noqa: E731
            out[i, lo:hi] = np.asarray(_ellipse_flags(V, N, rep(P[i]), rep(L[i])))[: hi - lo]
    return out


def one(n, amplitude, receivers):
    try:
        scene = scenes.wavy_pool(n, amplitude=amplitude, n_receivers=receivers, dtype=jnp.float64)
    except ValueError as exc:  # waves the mesh cannot resolve
        return {"triangles": n, "amplitude": amplitude, "skipped": str(exc)[:160]}
    mesh = scene.surface
    P = scene.receivers
    L = jnp.broadcast_to(jnp.asarray(scene.lights.position[0], jnp.float64), P.shape)
    prep = prepare(mesh)
    start = prep.start_points(P, L)
    V0, N0 = mesh.triangle(jnp.maximum(start.face, 0))
    flags = np.asarray(_ellipse_flags(V0, N0, P, L))
    flags = flags & np.asarray(start.found)
    t0 = time.perf_counter()
    sol = solve(prep, P, L, method=Walk(fallback="none"), features=None, start=start)
    it, status = np.asarray(sol.iterations), np.asarray(sol.status)
    walk_s = time.perf_counter() - t0
    others = np.asarray(start.found) & ~flags
    row = {"triangles": int(mesh.faces.shape[0]), "amplitude": amplitude, "lanes": int(P.shape[0]),
           "started": int(np.sum(np.asarray(start.found))), "start_ellipse": int(flags.sum()),
           "start_ellipse_share": float(flags.sum() / max(np.sum(np.asarray(start.found)), 1)),
           "iterations_ellipse_lanes": float(it[flags].mean()) if flags.any() else None,
           "iterations_other_lanes": float(it[others].mean()),
           "found_share_ellipse_lanes": float(np.mean(status[flags] == Status.FOUND)) if flags.any() else None,
           "found_share_other_lanes": float(np.mean(status[others] == Status.FOUND)),
           "statuses_ellipse_lanes": {Status(int(s)).name: int(c) for s, c in
                                      zip(*np.unique(status[flags], return_counts=True), strict=True)},
           "walk_seconds": walk_s}
    # Ellipses elsewhere on the mesh, on a subsample of lanes.
    rng = np.random.default_rng(0)
    lanes = rng.choice(np.flatnonzero(np.asarray(start.found)), size=min(SCAN_LANES, int(row["started"])),
                       replace=False)
    faces = ellipse_faces(mesh, np.asarray(P)[lanes], np.asarray(L)[lanes])
    faces[np.arange(lanes.size), np.asarray(start.face)[lanes]] = False  # the start triangle's own: above
    row["scan_lanes"] = int(lanes.size)
    row["other_face_ellipses_per_lane"] = float(faces.sum() / lanes.size)
    row["lanes_with_other_face_ellipse"] = int(np.any(faces, axis=1).sum())
    # Which of them hold a path: the exhaustive reference's paths on those faces, not on the walk's.
    ref = solve(prep, P[lanes], L[lanes], method=Exhaustive(), solutions="all")
    ref_faces = np.asarray(ref.all_triangles)
    ref_ok = ref_faces >= 0
    missed = 0
    for k in range(lanes.size):
        missed += int(np.sum(ref_ok[k] & faces[k][np.maximum(ref_faces[k], 0)]))
    row["paths_on_other_face_ellipses"] = missed
    row["paths_reference"] = int(np.asarray(ref.count).sum())
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="two tessellations, 32 x 32 receivers")
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
    args = parse_args(ap, argv)
    tris = TRIANGLES[:2] if args.quick else TRIANGLES
    receivers = 32 if args.quick else 64
    rows = []
    for n in tris:
        for a in AMPLITUDES:
            row = one(n, a, receivers)
            rows.append(row)
            if "skipped" in row:
                print(f"n={n} a={a}: skipped ({row['skipped'][:60]}...)", flush=True)
                continue
            print(f"n={row['triangles']} a={a}: start ellipse {row['start_ellipse']}/{row['started']} "
                  f"({100 * row['start_ellipse_share']:.3f}%), other-face ellipses per lane "
                  f"{row['other_face_ellipses_per_lane']:.3f}, paths on them {row['paths_on_other_face_ellipses']}"
                  f"/{row['paths_reference']}", flush=True)
    result = {"rows": rows, "receivers_per_scene": receivers * receivers, "scan_lanes": SCAN_LANES,
              "dtype": "float64"}
    write_json(args.json, result)
    plot(result)
    print(table(result))
    return result


def table(result) -> str:
    lines = ["| triangles | amplitude (m) | start-triangle ellipse lanes | share | walk iterations: ellipse lanes / "
             "others | FOUND: ellipse lanes / others | other faces with an interior ellipse, per lane | "
             "paths on them / reference paths |", "|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        if "skipped" in r:
            lines.append(f"| {r['triangles']} | {r['amplitude']} | (waves not resolved by the mesh) | | | | | |")
            continue
        it_e = "-" if r["iterations_ellipse_lanes"] is None else f"{r['iterations_ellipse_lanes']:.1f}"
        f_e = "-" if r["found_share_ellipse_lanes"] is None else f"{r['found_share_ellipse_lanes']:.3f}"
        lines.append(f"| {r['triangles']} | {r['amplitude']} | {r['start_ellipse']} / {r['started']} | "
                     f"{100 * r['start_ellipse_share']:.3f}% | {it_e} / {r['iterations_other_lanes']:.1f} | "
                     f"{f_e} / {r['found_share_other_lanes']:.3f} | {r['other_face_ellipses_per_lane']:.3f} | "
                     f"{r['paths_on_other_face_ellipses']} / {r['paths_reference']} |")
    return "\n".join(lines)


def plot(result) -> None:
    rows = [r for r in result["rows"] if "skipped" not in r]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for a in AMPLITUDES:
        sel = sorted((r for r in rows if r["amplitude"] == a), key=lambda r: r["triangles"])
        if not sel:
            continue
        x = [r["triangles"] for r in sel]
        # None seen in n lanes: the 95% upper bound 3 / n of the share, drawn as a downward marker.
        y = [100 * (r["start_ellipse_share"] if r["start_ellipse"] else 3 / r["started"]) for r in sel]
        line, = ax[0].plot(x, y, "-", label=f"amplitude {a * 100:g} cm")
        for xi, yi, r in zip(x, y, sel, strict=True):
            ax[0].plot(xi, yi, "o" if r["start_ellipse"] else "v", color=line.get_color())
        ax[1].plot(x, [r["other_face_ellipses_per_lane"] for r in sel], "o-", color=line.get_color(),
                   label=f"amplitude {a * 100:g} cm")
    ax[0].set(xscale="log", yscale="log", xlabel="triangles", ylabel="lanes with the curve an ellipse\n"
              "inside the start triangle (%)", title="Start triangle (the walk's special case)\n"
              "v: none seen, the 95% upper bound 3 / lanes")
    ax[1].set(xscale="log", xlabel="triangles", ylabel="faces per lane with an interior ellipse",
              title=f"Elsewhere on the mesh, {result['scan_lanes']} lanes per point\n"
                    "(closed components the walk never reaches; 8 and 15 cm overlap)")
    for a in ax:
        a.title.set_fontsize(10)
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"Seed 001 Fig. 6: the coplanarity curve as an ellipse inside one triangle, Gerstner pool, "
                 f"{result['receivers_per_scene']} receivers per point, float64", fontsize=10)
    fig.tight_layout()
    FIG.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIG, dpi=130)
    plt.close(fig)


# %%
if __name__ == "__main__":
    main()
