# %% [markdown]
# # Scaling with tessellation (seed 001 Fig. 10-12 analogue)
#
# How do the curve walk and the optimistix Newton baselines of `caustics_jax/app/compare.py`
# scale with the triangle count of the water surface? Newton converging inside every
# triangle (`newton-hv`: Newton, half-vector constraint) and Newton stepping as Cycles'
# MNEE and Mitsuba's SMS do (`newton-hv-step`: one step, then re-project onto the
# surface; the strongest baseline, docs/solvers.md "Throughput"). The wavy pool (same waves, same light, same 4096
# floor receivers) is tessellated from about 4k to 1M triangles; per size and dtype we
# measure the time per solve (start points given, median of `REPEATS` calls after a
# compile call), the start points' own time, the mean number of triangles crossed, and
# the found fraction, and the solver's steps per found path (the walk: crossings plus
# refinement cuts; Newton: its iterations). Newton runs with its default cap of 64 patches (one triangle per
# patch) and with 4096, to separate its cost growth from the cap. A least-squares line in
# log-log space gives the growth law `time ~ F^slope`.
#
# Run: `python -m experiments.scaling` (writes `figures/scaling.json` and
# `figures/scaling.png`; about 5 minutes on 2 cores, 296 s measured; the 1M pool builds in a few seconds).

# %%
from __future__ import annotations

import argparse
import inspect
import pathlib
import time

import jax
import numpy as np

import caustics_jax as cj
from caustics_jax.app.compare import CONFIGS
from caustics_jax.runtime.progress import progress
from experiments.common import ROOT, log, median_time, parse_args, use_agg, write_json

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

# 4,050 / 16,020 / 64,082 / 250,632 / 1,001,112 faces: each just under a power of two (the
# solvers pad meshes to power-of-two buckets)
SIZES = (4_000, 16_000, 64_000, 250_000, 1_000_000)
N_RECEIVERS = 64  # per side: 4096 lanes
REPEATS = 3
SOLVERS = {
    "walk": ("walk", {}),
    "newton-hv": CONFIGS["newton-hv"],
    "newton-hv, 4096 patches": (CONFIGS["newton-hv"][0], {**CONFIGS["newton-hv"][1], "max_patches": 4096}),
    "newton-hv-step": CONFIGS["newton-hv-step"],
}
COLORS = {"walk": "C0", "newton-hv": "C1", "newton-hv, 4096 patches": "C3", "newton-hv-step": "C2"}
DTYPES = ("float32", "float64")
# The general solver path, not a scene-feature specialisation (issue 7 part 2, where present).
GENERAL = {"features": None} if "features" in inspect.signature(cj.solve).parameters else {}


def run(sizes=SIZES, dtypes=DTYPES, repeats=REPEATS) -> dict:
    rows = []
    steps = progress(total=len(sizes) * len(dtypes), desc="scaling", unit="mesh")
    for n_tri in sizes:
        for dtype in dtypes:
            steps.update(1)  # a bar over (tessellation, dtype) pairs, on a terminal only
            with cj.precision(dtype):
                t = time.perf_counter()
                sc = cj.scenes.wavy_pool(n_tri, n_receivers=N_RECEIVERS, dtype=dtype)
                build = time.perf_counter() - t
                F = int(sc.surface.faces.shape[0])
                P = sc.receivers
                L = sc.lights.endpoint(P)
                start, t_start = median_time(lambda sc=sc, P=P, L=L: cj.start_points(sc.surface, P, L), repeats)
                n = int(P.shape[0])
                for name, (method, opts) in SOLVERS.items():
                    t = time.perf_counter()
                    sol, t_solve = median_time(
                        lambda m=method, o=opts, mesh=sc.surface, P=P, L=L, start=start: cj.solve(
                            mesh, P, L, method=m, start=start, **o, **GENERAL), repeats)
                    found = np.asarray(sol.found)
                    crossed = np.asarray(sol.crossed)
                    row = {"triangles": F, "dtype": dtype, "solver": name, "lanes": n,
                           "us_per_solve": 1e6 * t_solve / n, "start_us_per_lane": 1e6 * t_start / n,
                           "found": float(found.mean()), "status": sol.summary(),
                           "crossed_mean_found": float(crossed[found].mean()) if found.any() else None,
                           "crossed_mean_all": float(crossed.mean()),
                           "crossed_p99_found": float(np.quantile(crossed[found], 0.99)) if found.any() else None,
                           "iterations_mean_found": float(np.asarray(sol.iterations)[found].mean()),
                           "build_s": build, "wall_incl_compile_s": time.perf_counter() - t}
                    rows.append(row)
                    log(f"{F:>9,} {dtype} {name:24s} {row['us_per_solve']:8.2f} us/solve  found {row['found']:.4f}  "
                        f"crossed {row['crossed_mean_found']:.1f}  ({row['wall_incl_compile_s']:.0f} s)")
    steps.close()
    return {"rows": rows, "fits": fits(rows), "lanes": N_RECEIVERS**2, "repeats": repeats,
            "platform": jax.default_backend(), "devices": [str(d) for d in jax.devices()]}


def _slope(x, y):
    x, y = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
    slope, intercept = np.polyfit(x, y, 1)
    return float(slope), float(np.exp(intercept))


def fits(rows) -> list[dict]:
    """Log-log least-squares slopes of time per solve and crossings against triangles."""
    out = []
    for dtype in {r["dtype"] for r in rows}:
        for name in SOLVERS:
            rs = sorted((r for r in rows if r["dtype"] == dtype and r["solver"] == name), key=lambda r: r["triangles"])
            if len(rs) < 2:
                continue
            F = [r["triangles"] for r in rs]
            s_t, c_t = _slope(F, [r["us_per_solve"] for r in rs])
            s_c, c_c = _slope(F, [max(r["crossed_mean_found"] or 0, 1e-3) for r in rs])
            s_i, _ = _slope(F, [r["iterations_mean_found"] for r in rs])
            # time per solve affine in the crossings: t = fixed + per_crossing x crossed
            per_crossing, fixed = np.polyfit([r["crossed_mean_found"] or 0 for r in rs],
                                             [r["us_per_solve"] for r in rs], 1)
            out.append({"dtype": dtype, "solver": name, "time_slope": s_t, "time_coef_us": c_t,
                        "crossed_slope": s_c, "crossed_coef": c_c, "iterations_slope": s_i,
                        "fixed_us": float(fixed), "us_per_crossing": float(per_crossing)})
        rs = sorted((r for r in rows if r["dtype"] == dtype and r["solver"] == "walk"), key=lambda r: r["triangles"])
        if len(rs) >= 2:
            s, c = _slope([r["triangles"] for r in rs], [r["start_us_per_lane"] for r in rs])
            out.append({"dtype": dtype, "solver": "start points (grid DDA)", "time_slope": s, "time_coef_us": c})
    return sorted(out, key=lambda r: (r["dtype"], r["solver"]))


def plot(result, path):
    rows = result["rows"]
    fig, axes = plt.subplots(1, 3, figsize=(19, 5.5))
    colors = COLORS
    slopes = {(f["dtype"], f["solver"]): f for f in result["fits"]}
    for dtype, ls, marker in (("float32", "-", "o"), ("float64", "--", "s")):
        for name, color in colors.items():
            rs = sorted((r for r in rows if r["dtype"] == dtype and r["solver"] == name), key=lambda r: r["triangles"])
            if not rs:
                continue
            F = [r["triangles"] for r in rs]
            fit = slopes.get((dtype, name), {})
            axes[0].plot(F, [r["us_per_solve"] for r in rs], ls=ls, marker=marker, color=color,
                         label=f"{name} {dtype} (slope {fit.get('time_slope', float('nan')):.2f})")
            # walk drawn with large open markers: where Newton crosses as many triangles
            # the curves coincide
            big = dict(markersize=10, markerfacecolor="none") if name == "walk" else {}
            axes[1].plot(F, [r["crossed_mean_found"] for r in rs], ls=ls, marker=marker, color=color,
                         label=f"{name} {dtype} (slope {fit.get('crossed_slope', float('nan')):.2f})", **big)
            axes[2].plot(F, [r["iterations_mean_found"] for r in rs], ls=ls, marker=marker, color=color,
                         label=f"{name} {dtype} (slope {fit.get('iterations_slope', float('nan')):.2f})")
        rs = sorted((r for r in rows if r["dtype"] == dtype and r["solver"] == "walk"), key=lambda r: r["triangles"])
        if rs:
            fit = slopes.get((dtype, "start points (grid DDA)"), {})
            axes[0].plot([r["triangles"] for r in rs], [r["start_us_per_lane"] for r in rs], ls=ls, marker=marker,
                         color="gray", label=f"start points {dtype} (slope {fit.get('time_slope', float('nan')):.2f})")
    F = np.array([min(r["triangles"] for r in rows), max(r["triangles"] for r in rows)], float)
    ref = [r["crossed_mean_found"] for r in rows if r["solver"] == "walk" and r["triangles"] == F[0]][0]
    axes[1].plot(F, ref * np.sqrt(F / F[0]), color="k", lw=0.8, ls=":", label="sqrt(F) reference")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("triangles F of the wavy pool")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    # room under the curves for the legend (it had covered the start points' curves)
    lo = min(r["start_us_per_lane"] for r in rows)
    axes[0].set_ylim(bottom=lo / 20)
    axes[0].legend(fontsize=7, loc="lower right")
    axes[0].set_ylabel("time per solve (microseconds, 2-core CPU, start points given)")
    axes[0].set_title("Per-solve time against tessellation")
    axes[1].set_ylabel("mean triangles crossed per found path")
    axes[1].set_title("Triangles crossed from M0 to the solution")
    axes[2].set_ylabel("mean solver steps per found path (walk: crossings + cuts)")
    axes[2].set_title("Steps from M0 to the solution")
    fig.suptitle(f"Walk vs optimistix Newton (half-vector; converging per triangle, and one step + re-projection) "
                 f"on the wavy pool, same {result['lanes']} receivers and light at every tessellation "
                 "(log-log; slope = fitted growth exponent)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# %%
def main(argv=None):
    ap = argparse.ArgumentParser(description="walk vs Newton against tessellation")
    ap.add_argument("--quick", action="store_true", help="4k-262k triangles, float32 only")
    ap.add_argument("--out", default=str(ROOT / "figures"))
    args = parse_args(ap, argv)
    t0 = time.perf_counter()
    result = run(SIZES[:4], ("float32",)) if args.quick else run()
    result["seconds"] = time.perf_counter() - t0
    out = pathlib.Path(args.out)
    write_json(out / "scaling.json", result)
    plot(result, out / "scaling.png")
    print(f"{'triangles':>10s} {'dtype':8s} {'solver':24s} {'us/solve':>9s} {'start us':>9s} {'found':>7s} "
          f"{'crossed':>8s} {'steps':>6s}")
    for r in result["rows"]:
        print(f"{r['triangles']:>10,} {r['dtype']:8s} {r['solver']:24s} {r['us_per_solve']:9.2f} "
              f"{r['start_us_per_lane']:9.2f} {r['found']:7.4f} {r['crossed_mean_found'] or 0:8.2f} "
              f"{r['iterations_mean_found']:6.2f}")
    for f in result["fits"]:
        extra = ""
        if "crossed_slope" in f:
            extra = (f", crossed ~ F^{f['crossed_slope']:.2f}, steps ~ F^{f['iterations_slope']:.2f}, "
                     f"t = {f['fixed_us']:.1f} us + {f['us_per_crossing']:.2f} us x crossed")
        print(f"{f['dtype']} {f['solver']}: time ~ F^{f['time_slope']:.2f}{extra}")
    print(f"{result['seconds']:.0f} s")


if __name__ == "__main__":
    main()
