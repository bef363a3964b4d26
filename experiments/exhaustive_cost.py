# %% [markdown]
# # The certified reference and the all-paths walk: what do they cost, and does the walk find every path?
#
# Two questions of issue 16, measured in one process:
#
# 1. **Cost of the reference, culling on and off.** `method="exhaustive"` (float64) with
#    conservative cone culling (`Exhaustive(cull=True)`, the default: `cones.py`) against
#    `cull=False` (every face whose conic meets it is scanned), on the default wavy pool
#    (8192 triangles) and on a wavy pool of about 100k triangles
#    (`scenes.wavy_pool(100_000)`), the same receivers for both. Per lane: wall time
#    (after a first, compiling call on the same lanes), (lane, face) pairs scanned, and
#    whether both give the same solutions. The issue asks for >= 10x cheaper per lane
#    with culling, so that the reference serves 100k-lane comparisons on 100k-triangle
#    meshes; the table extrapolates the time of 100k lanes linearly from the per-lane time.
# 2. **Recall and time of `solve(..., method="walk", solutions="all")`** (`solvers/trace.py`)
#    against the certified reference, in float64 and float32, on the three pools of
#    `experiments/estimators.py` (gentle, steep, post-focal; 2048 triangles, 256 receivers).
#    Recall: the fraction of the reference's solutions with a found solution within
#    `MATCH` metres (1e-6 m in float64, 1e-4 m in float32, whose positions carry the
#    float32 walk tolerance); extra: found solutions with no reference solution that near.
#
# Times are wall time on whatever machine runs it (this project's: a 2-core CPU shared
# with other jobs), so they are indicative; the ratios come from calls in this one process.
#
# Run: `python -m experiments.exhaustive_cost` (writes `figures/exhaustive_cost.json`,
# prints both tables; `--quick`: 64 lanes and 64 receivers).

# %%
from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import caustics_jax as cj  # noqa: E402
from caustics_jax import scenes  # noqa: E402
from caustics_jax.accel.prepared import padded_mesh  # noqa: E402
from caustics_jax.solvers import exhaustive  # noqa: E402
from experiments.common import figures_dir, median_time, parse_args, write_json  # noqa: E402
from experiments.estimators import POOLS, pool  # noqa: E402

ETA = 1.333
COST_MESHES = {"default wavy pool, 8192 triangles": 8192, "wavy pool, 100k triangles": 100_000}
MATCH = {"float64": 1e-6, "float32": 1e-4}
EXTRAPOLATE_LANES = 100_000


def same_solutions(a, b, tol: float = 1e-9) -> bool:
    """Whether two `ExhaustiveSolution`s hold the same solutions on every lane."""
    if not np.array_equal(a.count, b.count):
        return False
    for i in np.flatnonzero(a.count):
        pa, pb = a.all_points[i, : a.count[i]], b.all_points[i, : b.count[i]]
        if np.max(np.min(np.linalg.norm(pa[:, None] - pb[None], axis=-1), axis=1)) > tol:
            return False
    return True


def reference_cost(name: str, n_triangles: int, n_side: int, repeats: int) -> dict:
    """Per-lane time and scanned pairs of the reference with culling on and off."""
    with cj.precision("float64"):
        sc = scenes.wavy_pool(n_triangles, n_receivers=n_side, dtype="float64")
        mesh, P = sc.surface, np.asarray(sc.receivers)
        L = np.asarray(sc.lights.endpoint(P))
        mesh_b = padded_mesh(mesh)
        row = {"scene": name, "triangles": int(mesh.faces.shape[0]), "lanes": len(P)}
        out = {}
        for cull in (True, False):
            key = "cull" if cull else "no_cull"
            # The (lane, face) pairs the reference scans (its own private helper, so the
            # count is exactly what the timed call works through).
            lanes, _ = exhaustive.candidate_pairs(mesh, mesh_b, P, L, ETA, cull, exhaustive.Exhaustive().chunk)
            out[key], t = median_time(lambda cull=cull: cj.solve(mesh, P, L, eta=ETA,
                                                           method=cj.Exhaustive(cull=cull, return_all=True)), repeats)
            row[f"{key}_ms_per_lane"] = 1e3 * t / len(P)
            row[f"{key}_pairs_per_lane"] = len(lanes) / len(P)
            print(f"  {name}, cull={cull}: {row[f'{key}_ms_per_lane']:.2f} ms per lane", flush=True)
        row["speedup"] = row["no_cull_ms_per_lane"] / row["cull_ms_per_lane"]
        row["solutions"] = int(out["cull"].count.sum())
        row["same_solutions"] = same_solutions(out["cull"], out["no_cull"])
        row["cull_seconds_for_100k_lanes"] = row["cull_ms_per_lane"] * EXTRAPOLATE_LANES / 1e3
        row["no_cull_seconds_for_100k_lanes"] = row["no_cull_ms_per_lane"] * EXTRAPOLATE_LANES / 1e3
    return row


def match(ref, found, tol: float):
    """`(matched reference solutions, reference solutions, extra found, found)` within `tol` m."""
    hit = extra = 0
    for i in range(len(ref.count)):
        r = ref.all_points[i, : ref.count[i]]
        f = np.asarray(found.all_points[i, : found.count[i]], np.float64)
        if len(r) and len(f):
            d = np.linalg.norm(r[:, None] - f[None], axis=-1)
            hit += int(np.sum(d.min(axis=1) <= tol))
            extra += int(np.sum(d.min(axis=0) > tol))
        else:
            extra += len(f)
    return hit, int(ref.count.sum()), extra, int(np.sum(found.count))


def trace_recall(name: str, n_side: int, repeats: int) -> list[dict]:
    """Recall and time of the all-paths walk in float64 and float32 against the reference."""
    with cj.precision("float64"):
        mesh, P, L = pool(name, n_side)
        ref, t_ref = median_time(lambda: cj.solve(mesh, P, L, eta=ETA, method="exhaustive", return_all=True), repeats)
    counts = np.bincount(ref.count).tolist()
    rows = [{"pool": name, "method": "exhaustive (reference)", "dtype": "float64", "receivers": len(P),
             "paths_per_receiver": counts, "us_per_lane": 1e6 * t_ref / len(P), "recall": 1.0, "extra": 0,
             "lanes_all_found": len(P)}]
    for dtype in ("float64", "float32"):
        with cj.precision(dtype):
            m = mesh.astype(dtype)
            Pd, Ld = P.astype(dtype), L.astype(dtype)
            tr, t = median_time(lambda m=m, Pd=Pd, Ld=Ld: cj.solve(m, Pd, Ld, eta=ETA, method="walk", solutions="all"),
                          repeats)
        hit, total, extra, n_found = match(ref, tr, MATCH[dtype])
        per_lane = [match(_lane(ref, i), _lane(tr, i), MATCH[dtype]) for i in range(len(P))]
        rows.append({
            "pool": name, "method": "walk, solutions='all'", "dtype": dtype, "receivers": len(P),
            "paths_per_receiver": counts, "us_per_lane": 1e6 * t / len(P),
            "recall": hit / max(total, 1), "matched": hit, "reference_solutions": total, "found": n_found,
            "extra": extra, "lanes_all_found": int(sum(h == r for h, r, _, _ in per_lane)),
            "status": tr.solution.summary(),
        })
        print(f"  {name}, trace {dtype}: recall {hit}/{total}, extra {extra}, "
              f"{rows[-1]['us_per_lane']:.0f} us per lane", flush=True)
    return rows


def _lane(sol, i: int):
    """Lane `i` of an `ExhaustiveSolution` as a one-lane one (for `match`)."""
    return sol._replace(all_points=sol.all_points[i:i + 1], count=sol.count[i:i + 1])


def cost_table(rows) -> str:
    lines = ["| mesh | lanes | pairs scanned per lane: cull / no cull | ms per lane: cull / no cull "
             "| cheaper with culling | same solutions | 100k lanes, extrapolated: cull / no cull |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['scene']} ({r['triangles']:,}) | {r['lanes']} | {r['cull_pairs_per_lane']:.1f} / "
            f"{r['no_cull_pairs_per_lane']:.1f} | {r['cull_ms_per_lane']:.2f} / {r['no_cull_ms_per_lane']:.1f} "
            f"| {r['speedup']:.1f}x | {'yes' if r['same_solutions'] else 'NO'} "
            f"| {_duration(r['cull_seconds_for_100k_lanes'])} / {_duration(r['no_cull_seconds_for_100k_lanes'])} |")
    return "\n".join(lines)


def _duration(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else (f"{s / 60:.0f} min" if s < 7200 else f"{s / 3600:.1f} h")


def trace_table(rows) -> str:
    lines = ["| pool | receivers with 0 / 1 / 2 / 3+ paths | method | dtype | recall | lanes with every path "
             "| extra | us per lane |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        c = r["paths_per_receiver"] + [0, 0, 0]
        hist = f"{c[0]} / {c[1]} / {c[2]} / {sum(r['paths_per_receiver'][3:])}"
        rec = f"{r['recall']:.4f}" + (f" ({r['matched']}/{r['reference_solutions']})" if "matched" in r else "")
        lines.append(f"| {r['pool']} | {hist} | {r['method']} | {r['dtype']} | {rec} "
                     f"| {r['lanes_all_found']}/{r['receivers']} | {r['extra']} | {r['us_per_lane']:,.0f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="64 lanes per mesh and 64 receivers per pool")
    ap.add_argument("--repeats", type=int, default=2, help="timed calls after the compiling one (median)")
    args = parse_args(ap, argv)
    n_side = 8 if args.quick else 16
    t0 = time.time()
    cost = []
    for name, n_tri in COST_MESHES.items():
        cost.append(reference_cost(name, n_tri, n_side, args.repeats))
    trace = []
    for name in POOLS:
        trace.extend(trace_recall(name, n_side, args.repeats))
    write_json(figures_dir() / "exhaustive_cost.json",
               dict(cost=cost, trace=trace, match_m=MATCH, seconds=time.time() - t0, quick=args.quick))
    print(cost_table(cost))
    print()
    print(trace_table(trace))
    print(f"wrote figures/exhaustive_cost.json ({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
