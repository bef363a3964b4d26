# %% [markdown]
# # The comparison seed 001 makes (§5, Fig. 7-8): irradiance error against time per receiver
#
# Question: per receiver, how close to the total caustic irradiance (the sum over every
# refracted path) does each method get, and at what cost? Against the certified
# all-path reference (`irradiance(..., method="exhaustive", all_paths=True)`, float64):
#
# - **walk, one path** (`method="walk"`, seed 001): the path on the curve through `M0`;
# - **walk, all paths** (`method="walk", all_paths=True`: `solvers/trace.py`, the curve
#   traced through `M0` and from every boundary root);
# - **Newton, one path** from `M0` (`method="newton"`, half-vector, the MNEE baseline);
# - **SMS biased** (`transport.sms_biased`): `k` Newton solves from area-uniform random
#   starts, distinct solutions summed, `k` in 1..64;
# - **SMS unbiased** (`transport.sms_unbiased`, Zeltner et al. 2020's Bernoulli trials),
#   the mean of `m` independent estimates, `m` in 1..64.
#
# Three pools of 2048 triangles, 256 receivers on the floor, a point light 3 m up:
# **gentle** (the default sea, amplitude 0.03 m, floor 1 m down: one path everywhere),
# **steep** (one wave of amplitude 0.1 m and wavelength 0.6 m, the steep wave of
# docs/solvers.md's known limitations, floor 0.5 m down: about a tenth of the receivers
# have 3 paths), **post-focal** (the same wave, floor 2 m down, well past where its crests
# focus, roughly 0.4 m down: about four fifths of the receivers have 3 or more paths).
# (The four-wave pools of amplitude 0.1 m at 0.5 m and 0.3 m at 3 m give 0 and 2 of 256
# receivers with more than one path on the pool floor: no comparison.)
#
# Error: relative L2 over the receivers, `|E - E_ref| / |E_ref|`. Time: wall time of the
# call over all receivers after a first (compiling) call, divided by the receivers; the
# machine's 2 cores are shared with other jobs, so times carry their load (the ratios of
# calls made in this one process are what to read).
#
# Run: `python -m experiments.estimators` (writes `figures/estimators.png` and `.json`,
# prints a table; `--quick` for 64 receivers).

# %%
from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import caustics_jax as cj  # noqa: E402
from caustics_jax import scenes  # noqa: E402
from caustics_jax.transport import irradiance, sms_biased, sms_unbiased  # noqa: E402
from experiments.common import figures_dir, median_time, parse_args, use_agg, write_json  # noqa: E402

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

UP = [0.0, 0.0, 1.0]
STEEP_WAVE = dict(amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6))
POOLS = {
    "gentle": dict(amplitude=0.03, depth=1.0),
    "steep": dict(STEEP_WAVE, depth=0.5),
    "post-focal": dict(STEEP_WAVE, depth=2.0),
}
K_BIASED = (1, 4, 16, 64)
M_UNBIASED = (1, 4, 16, 64)


def pool(name: str, n_side: int):
    with cj.precision("float64"):
        sc = scenes.wavy_pool(2048, n_receivers=n_side, dtype="float64", **POOLS[name])
        P = np.asarray(sc.receivers)
        return sc.surface, P, np.asarray(sc.lights.endpoint(P))


def rel_l2(E, ref):
    return float(np.linalg.norm(np.asarray(E, np.float64) - ref) / np.linalg.norm(ref))


def recall(found_sets, ref):
    """Fraction of the reference's solutions within 1e-6 m of a found one."""
    hit = total = 0
    for i in range(len(ref.count)):
        mine = found_sets[i]
        for q in ref.all_points[i, : ref.count[i]]:
            total += 1
            hit += bool(len(mine)) and np.min(np.linalg.norm(mine - q, axis=-1)) < 1e-6
    return hit / max(total, 1)


def run_pool(name: str, n_side: int, seed: int = 0) -> dict:
    mesh, P, L = pool(name, n_side)
    n = len(P)
    kw = dict(intensity=1.0, receiver_normal=UP)
    with cj.precision("float64"):
        (E_ref, ref_sol), t_ref = median_time(lambda: irradiance(mesh, P, L, method="exhaustive", all_paths=True,
                                                           return_solution=True, **kw))
        ref = cj.solve(mesh, P, L, method="exhaustive", return_all=True)
        E_ref = np.asarray(E_ref, np.float64)
        rows = [dict(method="exhaustive (reference)", param=None, us=1e6 * t_ref / n, err=0.0, recall=1.0)]
        (E, sol), t = median_time(lambda: irradiance(mesh, P, L, method="walk", return_solution=True, **kw))
        pts = [np.asarray(sol.point)[i:i + 1] if bool(sol.found[i]) else np.zeros((0, 3)) for i in range(n)]
        rows.append(dict(method="walk, one path", param=None, us=1e6 * t / n, err=rel_l2(E, E_ref),
                         recall=recall(pts, ref)))
        (E, sol), t = median_time(lambda: irradiance(mesh, P, L, method="newton", return_solution=True, **kw))
        pts = [np.asarray(sol.point)[i:i + 1] if bool(sol.found[i]) else np.zeros((0, 3)) for i in range(n)]
        rows.append(dict(method="Newton, one path", param=None, us=1e6 * t / n, err=rel_l2(E, E_ref),
                         recall=recall(pts, ref)))
        E, t = median_time(lambda: irradiance(mesh, P, L, method="walk", all_paths=True, **kw))
        tr = cj.solve(mesh, P, L, method="walk", solutions="all")
        rows.append(dict(method="walk, all paths", param=None, us=1e6 * t / n, err=rel_l2(E, E_ref),
                         recall=recall([tr.all_points[i, : tr.count[i]] for i in range(n)], ref)))
        for k in K_BIASED:
            est, t = median_time(lambda k=k: sms_biased(mesh, P, L, k=k, seed=seed, **kw))
            rows.append(dict(method="SMS biased", param=k, us=1e6 * t / n, err=rel_l2(est.irradiance, E_ref),
                             recall=float(np.sum(est.paths) / max(ref.count.sum(), 1))))
        for m in M_UNBIASED:
            rep = lambda X, m=m: np.repeat(X, m, 0)  # noqa: E731
            est, t = median_time(lambda m=m, rep=rep: sms_unbiased(mesh, rep(P), rep(L), seed=seed, **kw))
            E = est.irradiance.reshape(n, m).mean(1)
            rows.append(dict(method="SMS unbiased", param=m, us=1e6 * t / n, err=rel_l2(E, E_ref),
                             solves=float(est.solves.mean()), recall=None))
    counts = np.bincount(ref.count)
    return dict(pool=name, receivers=n, paths_per_receiver=counts.tolist(), rows=rows,
                reference_status=ref_sol.summary())


def plot(results, path):
    fig, axes = plt.subplots(1, len(results), figsize=(5.0 * len(results), 4.6), sharey=True)
    floor = 1e-6
    for ax, res in zip(np.atleast_1d(axes), results, strict=True):
        rows = res["rows"]
        for method, style in (("SMS biased", "o-"), ("SMS unbiased", "s-")):
            sel = [r for r in rows if r["method"] == method]
            ax.plot([r["us"] for r in sel], [max(r["err"], floor) for r in sel], style, label=method)
            for r in sel:
                ax.annotate(f"{'k' if method == 'SMS biased' else 'm'}={r['param']}", (r["us"], max(r["err"], floor)),
                            fontsize=7, xytext=(3, 3), textcoords="offset points")
        for method, marker in (("walk, one path", "^"), ("Newton, one path", "v"), ("walk, all paths", "*"),
                               ("exhaustive (reference)", "D")):
            r = next(r for r in rows if r["method"] == method)
            ax.plot([r["us"]], [max(r["err"], floor)], marker, markersize=10 if marker == "*" else 7, label=method)
        counts = res["paths_per_receiver"]
        multi = sum(counts[2:]) / max(sum(counts), 1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("time per receiver (us, 2-core CPU, shared)")
        ax.set_title(f"{res['pool']} pool: {100 * multi:.0f}% of receivers with 2+ paths")
        ax.grid(which="both", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel(f"relative L2 error of irradiance (floored at {floor:g})")
    handles, labels = np.atleast_1d(axes)[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=6, fontsize=8, frameon=False)
    fig.suptitle("Irradiance error against time per receiver, vs the certified all-path reference "
                 "(seed 001 Fig. 7-8 analogue, float64)")
    fig.tight_layout(rect=(0, 0.08, 1, 0.95))
    fig.savefig(path, dpi=130)


def table(results) -> str:
    lines = ["| pool | method | k / m | time per receiver (us) | rel. L2 error | recall of paths |",
             "|---|---|---|---|---|---|"]
    for res in results:
        for r in res["rows"]:
            rec = "" if r.get("recall") is None else f"{r['recall']:.3f}"
            param = "" if r["param"] is None else str(r["param"])
            lines.append(f"| {res['pool']} | {r['method']} | {param} | {r['us']:,.0f} | {r['err']:.2e} | {rec} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="64 receivers per pool")
    args = parse_args(ap, argv)
    n_side = 8 if args.quick else 16
    t0 = time.time()
    results = []
    for name in POOLS:
        results.append(run_pool(name, n_side))
        print(f"{name}: done ({time.time() - t0:.0f} s)", flush=True)
    out = figures_dir() / "estimators.png"
    plot(results, out)
    write_json(out.with_suffix(".json"), dict(results=results, seconds=time.time() - t0, receivers_side=n_side))
    print(table(results))
    print(f"wrote {out} and .json ({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
