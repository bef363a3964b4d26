# %% [markdown]
# # Scene-feature specialisation against the general path
#
# Question: how much do `features="auto"` (closed form on a flat surface, lanes without a
# start point kept out of the solver, D only for found paths) save over `features=None`
# (the general path), and are the outputs the same? Three scenes, float32 and float64:
#
# - **flat pool**: still water, every lane solved in closed form (`solvers/flat.py`);
# - **partly covered floor**: a wavy pool over a floor that reaches past the water on
#   every side, a quarter of the receivers above the water (many segments miss it);
# - **wavy pool**: Gerstner waves over the whole floor, nearly every lane needs the walk.
#
# Throughput: median of `REPEATS` calls after a first (compiling) call, all paths in the
# same process, interleaved call by call (the machine is shared: its load drifts).
# Compile time (first call minus the median) and the host-side analysis
# `features(mesh)` are reported separately. The specialised path is timed with the
# `SceneFeatures` computed once (what a renderer does per mesh) and with `"auto"`
# (which analyses on every call).
#
# Run: `python -m experiments.features_benchmark` (writes `figures/features_benchmark.png`
# and `.json`, prints a table).

# %%
from __future__ import annotations

import time

import jax

jax.config.update("jax_enable_x64", True)  # float32 arrays stay float32 (built explicitly)

import numpy as np  # noqa: E402

from caustics_jax.solvers import Status, solve  # noqa: E402
from caustics_jax.surface import features, scenes  # noqa: E402
from caustics_jax.testing import partly_covered_floor  # noqa: E402
from caustics_jax.transport import irradiance  # noqa: E402
from experiments.common import ROOT, use_agg, write_json  # noqa: E402

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "features_benchmark.png"
N_TRIANGLES = 8192  # seed 001 Fig. 10's range, the `make demo` pool
N_SIDE = 128  # 16,384 receivers
REPEATS = 7
DTYPES = ("float32", "float64")
UP = np.array([0.0, 0.0, 1.0])


def make_scene(name, dtype):
    if name == "partly covered floor":
        return partly_covered_floor(dtype, n_triangles=N_TRIANGLES, n=N_SIDE, half=4.0)
    make = scenes.flat_pool if name == "flat pool" else scenes.wavy_pool
    scene = make(N_TRIANGLES, n_receivers=N_SIDE, dtype=dtype)
    return scene.surface, scene.receivers, scene.lights.endpoint(scene.receivers)


def timed_interleaved(fns: dict):
    """Per variant: (first-call seconds, median of REPEATS further calls, last result).

    After the first (compiling) calls, each round calls every variant once, the order
    rotated per round: the load of the shared machine changes over seconds, and ratios of
    interleaved medians follow it far less than back-to-back blocks of calls."""
    first, times, out = {}, {k: [] for k in fns}, {}
    for k, fn in fns.items():
        t = time.perf_counter()
        out[k] = jax.block_until_ready(fn())
        first[k] = time.perf_counter() - t
    keys = list(fns)
    for r in range(REPEATS):
        for k in keys[r % len(keys):] + keys[:r % len(keys)]:
            t = time.perf_counter()
            out[k] = jax.block_until_ready(fns[k]())
            times[k].append(time.perf_counter() - t)
    return {k: (first[k], float(np.median(times[k])), out[k]) for k in fns}


SCENES = ("flat pool", "partly covered floor", "wavy pool")

# %%
rows = []
for dtype in DTYPES:
    for name in SCENES:
        mesh, P, L = make_scene(name, dtype)
        n = P.shape[0]
        t = time.perf_counter()
        feats = features(mesh)
        t_analyse = time.perf_counter() - t
        row = dict(scene=name, dtype=dtype, lanes=n, triangles=int(mesh.faces.shape[0]),
                   features=feats._asdict(), analyse_s=t_analyse)
        variants = {"general": None, "specialised": feats, "auto": "auto"}
        solves = timed_interleaved({key: (lambda f=f, m=mesh, P=P, L=L: solve(m, P, L, features=f))
                                    for key, f in variants.items()})
        irrs = timed_interleaved({key: (lambda f=f, m=mesh, P=P, L=L: irradiance(
            m, P, L, intensity=1.0, receiver_normal=UP, features=f)) for key, f in variants.items()})
        sols, Es = {}, {}
        for key in variants:
            for what, res in (("solve", solves), ("irradiance", irrs)):
                first, med, _ = res[key]
                row[f"{what}_{key}"] = dict(first_s=first, median_s=med, compile_s=first - med, per_s=n / med)
            sols[key] = solves[key][2]
            Es[key] = np.asarray(irrs[key][2], np.float64)
        g, s = sols["general"], sols["specialised"]
        found = np.asarray(g.found)
        E_g, E_s = Es["general"], Es["specialised"]
        rel = np.abs(E_s - E_g) / np.where(E_g > 0, E_g, 1)
        row.update(
            status_mismatches=int(np.sum(np.asarray(g.status) != np.asarray(s.status))),
            statuses=g.summary(),
            max_point_diff_m=float(np.max(np.abs(np.asarray(g.point, np.float64)
                                                 - np.asarray(s.point, np.float64)))),
            max_E_rel_diff=float(np.max(rel)),
            E_bit_identical=bool(np.array_equal(E_g, E_s)),
            solve_speedup=row["solve_general"]["median_s"] / row["solve_specialised"]["median_s"],
            irradiance_speedup=(row["irradiance_general"]["median_s"]
                                / row["irradiance_specialised"]["median_s"]),
            found=int(found.sum()),
            no_crossing=int(np.sum(np.asarray(g.status) == Status.NO_CROSSING)),
        )
        rows.append(row)
        print(f"{dtype} {name:22s} solve {row['solve_general']['per_s']:9.0f} -> "
              f"{row['solve_specialised']['per_s']:9.0f}/s (x{row['solve_speedup']:.2f}), "
              f"irradiance {row['irradiance_general']['per_s']:9.0f} -> "
              f"{row['irradiance_specialised']['per_s']:9.0f}/s (x{row['irradiance_speedup']:.2f}); "
              f"status mismatches {row['status_mismatches']}, max |dM| {row['max_point_diff_m']:.2e} m, "
              f"max rel dE {row['max_E_rel_diff']:.2e}", flush=True)

# %%
out = dict(
    question="features='auto' (specialised) vs features=None (general): throughput and identical outputs",
    machine="2-core CPU shared with other jobs",
    repeats=REPEATS, lanes=N_SIDE**2, triangles=N_TRIANGLES,
    rows=rows,
)
write_json(FIG.with_suffix(".json"), out)

print()
print("| scene | dtype | found / no crossing | solves/s general | specialised | x | \"auto\" | irradiance/s general "
      "| specialised | x | compile s (gen / spec) | analyse ms |")
print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|")
for r in rows:
    print(f"| {r['scene']} | {r['dtype']} | {r['found']} / {r['no_crossing']} "
          f"| {r['solve_general']['per_s']:,.0f} | {r['solve_specialised']['per_s']:,.0f} "
          f"| {r['solve_speedup']:.2f} | {r['solve_auto']['per_s']:,.0f} | {r['irradiance_general']['per_s']:,.0f} "
          f"| {r['irradiance_specialised']['per_s']:,.0f} | {r['irradiance_speedup']:.2f} "
          f"| {r['solve_general']['compile_s']:.1f} / {r['solve_specialised']['compile_s']:.1f} "
          f"| {1e3 * r['analyse_s']:.1f} |")

# %%
fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), sharey=True)
x = np.arange(len(SCENES))
width = 0.2
colors = {("general", "float32"): "#9ecae1", ("specialised", "float32"): "#08519c",
          ("general", "float64"): "#fdae6b", ("specialised", "float64"): "#a63603"}
for ax, what, label in ((axes[0], "solve", "solve (walk)"), (axes[1], "irradiance", "irradiance (walk + D)")):
    k = 0
    for dtype in DTYPES:
        for path in ("general", "specialised"):
            vals = [next(r for r in rows if r["scene"] == s and r["dtype"] == dtype)[f"{what}_{path}"]["per_s"]
                    for s in SCENES]
            bars = ax.bar(x + (k - 1.5) * width, vals, width, color=colors[(path, dtype)],
                          label=f"{'features=None' if path == 'general' else 'features=auto'}, {dtype}")
            if path == "specialised":
                for b, s in zip(bars, SCENES, strict=True):
                    r = next(r for r in rows if r["scene"] == s and r["dtype"] == dtype)
                    ax.annotate(f"x{r[f'{what}_speedup']:.1f}", (b.get_x() + b.get_width() / 2, b.get_height()),
                                ha="center", va="bottom", fontsize=7)
            k += 1
    ax.set_xticks(x, SCENES)
    ax.set_yscale("log")
    ax.set_title(label)
    ax.grid(axis="y", which="both", alpha=0.3)
axes[0].set_ylabel("receivers per second (log scale)")
handles, labels = axes[0].get_legend_handles_labels()
fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
fig.suptitle(f"Specialised (features='auto') vs general (features=None): {N_SIDE**2:,} receivers, "
             f"{N_TRIANGLES:,}-triangle surface, 2-core CPU, median of {REPEATS}")
fig.tight_layout(rect=(0, 0.07, 1, 1))
fig.savefig(FIG, dpi=130)
print(f"wrote {FIG} and {FIG.with_suffix('.json')}")
