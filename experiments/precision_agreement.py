# %% [markdown]
# # float32 against float64: do they find the same lanes?
#
# Issue 14's target: the float32 walk ends a lane with the same status as the float64 walk,
# except on fewer than 1e-4 of the lanes of a gentle pool. Two scenes of `caustics-jax
# compare`: the default wavy pool (a heightfield grid) and the jittered pool (Gerstner
# waves with horizontal displacement: an irregular general mesh), each with the
# comparison's 100k receivers on the floor (`compare.CompareConfig()` lanes,
# `compare.scene_arrays`). Both precisions solve the same lanes on the same surface (the
# float64 scene cast to float32). The table counts lanes per (float64 status, float32
# status) pair; the disagreement rate is the fraction of lanes whose FOUND-ness differs.
#
# Run: `python -m experiments.precision_agreement [--n 100000]`; writes
# `figures/precision_agreement.json` and prints the tables.

# %%
from __future__ import annotations

import argparse
import time

import numpy as np

import caustics_jax as cj
from caustics_jax.app import compare
from experiments.common import figures_dir, log, parse_args, write_json

SCENES = ("wavy", "wavy_jittered")
TARGET = 1e-4


def agreement(scene: str, n: int, method: str = "walk") -> dict:
    """Statuses of `n` lanes of `scene` in float32 and float64, and their pairs."""
    cfg = compare.CompareConfig(scene=scene, n=n)
    with cj.precision("float64"):
        sc, _, P, L = compare.scene_arrays(cfg)
        t = time.perf_counter()
        s64 = cj.solve(sc.surface, P, L, method=method)
        st64 = np.asarray(s64.status)
        t64 = time.perf_counter() - t
    mesh32 = sc.surface.astype("float32")
    t = time.perf_counter()
    s32 = cj.solve(mesh32, P.astype(np.float32), L.astype(np.float32), method=method)
    st32 = np.asarray(s32.status)
    t32 = time.perf_counter() - t
    pairs: dict[str, int] = {}
    for a, b in zip(*np.unique(np.stack([st64, st32]), axis=1, return_counts=False), strict=True):
        key = f"{cj.Status(int(a)).name} -> {cj.Status(int(b)).name}"
        pairs[key] = int(np.sum((st64 == a) & (st32 == b)))
    found64, found32 = st64 == cj.Status.FOUND, st32 == cj.Status.FOUND
    differ = np.flatnonzero(found64 != found32)
    return {
        "scene": sc.name, "method": method, "lanes": n,
        "found_float64": int(found64.sum()), "found_float32": int(found32.sum()),
        "status_pairs": pairs,
        "found_disagreement": int(differ.size), "found_disagreement_rate": differ.size / n,
        "status_disagreement": int(np.sum(st64 != st32)), "status_disagreement_rate": float(np.mean(st64 != st32)),
        "disagreeing_lanes": [{"lane": int(i), "P": P[i].tolist(), "L": L[i].tolist(),
                               "float64": cj.Status(int(st64[i])).name, "float32": cj.Status(int(st32[i])).name}
                              for i in differ[:50]],
        "seconds": {"float64": t64, "float32": t32},
        "target_rate": TARGET, "meets_target": differ.size / n < TARGET,
    }


def table(result: dict) -> str:
    lines = [f"{result['scene']}: {result['lanes']} lanes, {result['method']}; found float64 "
             f"{result['found_float64']}, float32 {result['found_float32']}; FOUND disagreement "
             f"{result['found_disagreement']} ({result['found_disagreement_rate']:.2e}, target < {TARGET:.0e}), "
             f"any status {result['status_disagreement']}",
             f"  {'float64 -> float32':<52}{'lanes':>8}"]
    for key, count in sorted(result["status_pairs"].items(), key=lambda kv: -kv[1]):
        lines.append(f"  {key:<52}{count:>8}")
    return "\n".join(lines)


# %%
def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--n", type=int, default=100_000, help="lanes per scene")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=sorted(compare.SCENES))
    args = parse_args(parser, argv)
    results = []
    for scene in args.scenes:
        log(f"{scene}: {args.n} lanes in float64 and float32 ...")
        results.append(agreement(scene, args.n))
        print(table(results[-1]))
    out = write_json(figures_dir() / "precision_agreement.json",
                     {"results": results, "note": "machine shared with other jobs; times are indicative only"})
    log(f"wrote {out}")
    return {"results": results}


if __name__ == "__main__":
    main()
