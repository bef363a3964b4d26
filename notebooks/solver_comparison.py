# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Solver comparison: the walk, every Newton variant and the exhaustive reference
#
# Every solver configuration that `caustics_jax.app.compare.CONFIGS` offers when this notebook
# runs (the curve walk of seed 001, the optimistix Newton/MNEE/SMS variants, and whatever
# later solvers register there) on five scenes:
#
# | scene | what it stresses |
# |---|---|
# | gentle pool (`wavy`) | the default Gerstner sea, one path per receiver |
# | steep pool (`wavy_steep`) | amplitude 0.08 m: long walks, Newton basins shrink |
# | post-focal pool (`postfocal`) | amplitude 0.3 m over a floor 3 m down: several paths per receiver |
# | lagoon (`lagoon`) | irregular Delaunay water over an uneven floor |
# | a mesh from an OBJ file | written here with trimesh, read back with `SurfaceMesh.from_trimesh(trimesh.load(path))` |
#
# For each: success against the exhaustive float64 reference (`method="exhaustive"`),
# error against time (the Pareto sweep over acceptance tolerances), iterations, the
# failure statuses, and where on the floor each solver fails. The numbers come from
# `caustics_jax.app.compare.run`, the job behind `caustics-jax compare` (docs/solvers.md).
#
# Timings are wall-clock on whatever machine runs the notebook (batched, CPU unless a GPU
# is present); compare them within one run only. `CAUSTICS_JAX_QUICK=1` (what CI runs)
# uses 1,024 lanes and float32 only; the default uses 4,096 lanes in float32 and float64.

# %%
import contextlib
import io
import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import trimesh
from matplotlib.patches import Patch
from matplotlib.ticker import NullFormatter

import caustics_jax as cj
from caustics_jax.app import compare

QUICK = os.environ.get("CAUSTICS_JAX_QUICK", "") not in ("", "0")
N = 1024 if QUICK else 4096          # receiver lanes per scene
REF_N = 64 if QUICK else 512         # lanes checked against the exhaustive reference
TRIANGLES = 2048                     # one mesh size class: every scene reuses the same compiles
DTYPES = ("float32",) if QUICK else ("float32", "float64")
CONFIGS = tuple(compare.CONFIGS)     # every configuration the package offers at run time
plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": 100, "font.size": 9})
print(f"quick={QUICK}: {N} lanes, {REF_N} reference lanes, dtypes {DTYPES}")
print("solver configurations:", ", ".join(CONFIGS))

# %% [markdown]
# ## The OBJ scene
#
# A rippled surface (a decaying radial wave around an off-centre drop) on a 32 x 32 grid
# rotated by 30 degrees, so its vertices are off any axis-aligned grid and the solvers
# take the general (BVH) start-point path, written as OBJ by trimesh into a temporary
# folder and read back the way a user loads their own mesh. `compare.scene_from_mesh`
# puts the floor `W / 4` below it (`W` its larger xy side) and the light `0.75 W` above
# (the proportions of the built-in pools).

# %%
def ripple_obj(path: Path, n: int = 32, size: float = 4.0) -> Path:
    u = np.linspace(-size / 2, size / 2, n + 1)
    X, Y = np.meshgrid(u, u, indexing="xy")
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    x, y = c * X - s * Y, s * X + c * Y
    r = np.hypot(x - 0.4, y + 0.2)
    z = 0.05 * np.cos(2 * np.pi * r / 0.9) * np.exp(-r / 1.5)
    V = np.stack([x.ravel(), y.ravel(), z.ravel()], -1)
    i = np.arange(n)[None, :] + (n + 1) * np.arange(n)[:, None]
    a, b, d, e = i, i + 1, i + n + 1, i + n + 2
    F = np.concatenate([np.stack([a, b, e], -1).reshape(-1, 3), np.stack([a, e, d], -1).reshape(-1, 3)])
    trimesh.Trimesh(V, F, process=False).export(path)
    return path


tmp = Path(tempfile.mkdtemp(prefix="caustics_jax_"))
obj_path = ripple_obj(tmp / "ripple.obj")
surface = cj.SurfaceMesh.from_trimesh(trimesh.load(obj_path))
print(f"{obj_path.name}: {surface.faces.shape[0]} triangles, {surface.vertices.shape[0]} vertices, "
      f"{obj_path.stat().st_size / 1024:.0f} KiB")

SCENES = {"gentle pool": "wavy", "steep pool": "wavy_steep", "post-focal pool": "postfocal",
          "lagoon": "lagoon", "OBJ ripple": str(obj_path)}

# %% [markdown]
# ## Run every configuration on every scene
#
# `compare.run`'s progress lines (on stderr) are kept out of the notebook; the first scene
# pays the compiles, the others reuse them (same mesh size class and lane count).

# %%
reports = {}
for label, scene in SCENES.items():
    cfg = compare.CompareConfig(scene=scene, n_triangles=TRIANGLES, n=N, dtypes=DTYPES, configs=CONFIGS,
                                ref_n=REF_N, sweep_n=N, repeats=1 if QUICK else 2, keep_lanes=True)
    with contextlib.redirect_stderr(io.StringIO()):
        reports[label] = compare.run(cfg)
    ref = reports[label]["reference"]
    print(f"{label}: {reports[label]['scene']}; {reports[label]['lanes_crossing_surface']} of {N} lanes cross "
          f"the surface; reference solutions per lane {ref['solutions_per_lane'] if ref else '-'}")

# %% [markdown]
# ## Success, accuracy, iterations and speed
#
# `success`: of the reference lanes that have a solution, the fraction where the solver
# returned one (`@M0`: the one nearest the start point). `found`: all lanes. Angle error:
# the refraction-angle error of every found lane, evaluated in float64 on the float64
# mesh. The exhaustive reference's cost is its row (`ref`): seconds for its lanes,
# compile included where the scene is the first of its size class.

# %%
def fmt(x, spec):
    return "-" if x is None or x != x else format(x, spec)


for label, rep in reports.items():
    print(f"\n{label}: {rep['scene']}")
    print(f"{'config':<16}{'dtype':<9}{'success':>8}{'@M0':>7}{'found':>7}{'ang p99':>10}"
          f"{'it med':>7}{'it p99':>7}{'µs/solve':>10}")
    for r in rep["rows"]:
        print(f"{r['config']:<16}{r['dtype']:<9}{fmt(r['success'], '.3f'):>8}{fmt(r['nearest_M0'], '.3f'):>7}"
              f"{r['found']:>7.3f}{fmt(r['angle_error_rad']['p99'], '.1e'):>10}"
              f"{r['iterations']['median']:>7.0f}{r['iterations']['p99']:>7.0f}{1e6 / r['solves_per_s']:>10.2f}")
    if rep["reference"]:
        ref = rep["reference"]
        print(f"{'ref':<16}{'float64':<9}{'1.000':>8}  exhaustive reference: {ref['lanes']} lanes in "
              f"{ref['seconds']:.1f} s, solutions per lane {ref['solutions_per_lane']}")

# %% [markdown]
# ## Error against time (Pareto) and success against time
#
# Each line is one configuration and dtype swept over the acceptance tolerance `|f|`
# (a traced argument, so a sweep compiles once). Lower-left is better on the left panel,
# upper-left on the right one.

# %%
colors = {name: plt.cm.tab20(i % 20) for i, name in enumerate(CONFIGS)}
marks = {"float32": ("o", "-"), "float64": ("s", "--")}
fig, axes = plt.subplots(2, len(reports), figsize=(3.6 * len(reports), 6.4), squeeze=False)
for j, (label, rep) in enumerate(reports.items()):
    for name in CONFIGS:
        for dtype, (m, ls) in marks.items():
            rows = [s for s in rep["sweep"] if s["config"] == name and s["dtype"] == dtype]
            if not rows:
                continue
            t = [s["us_per_solve"] for s in rows]
            axes[0, j].plot(t, [max(s["angle_error_rad"]["p99"], 1e-17) for s in rows], ls, marker=m, ms=3,
                            color=colors[name], label=f"{name} {dtype}")
            axes[1, j].plot(t, [100 * s["found"] for s in rows], ls, marker=m, ms=3, color=colors[name])
    axes[0, j].set(xscale="log", yscale="log", title=label, xlabel="time per solve (µs)",
                   ylabel="p99 angle error (rad)" if j == 0 else None)
    axes[1, j].set(xscale="log", xlabel="time per solve (µs)", ylabel="lanes found (%)" if j == 0 else None)
    for ax in axes[:, j]:
        ax.grid(True, which="both", alpha=0.3)
        ax.xaxis.set_minor_formatter(NullFormatter())  # log minor tick labels collide
axes[0, -1].legend(fontsize=6, loc="upper right")
fig.suptitle(f"Error and success against run time over the acceptance tolerance ({N} lanes per point)")
fig.tight_layout()
plt.show()

# %% [markdown]
# ## Iterations and failure statuses
#
# Iterations of the found lanes (walk: triangle crossings plus refinement steps; Newton:
# optimistix steps over all patches and starts), and every lane's final `Status`
# (`cj.Status.explain(code)` says what each means).

# %%
statuses = [s.name for s in cj.Status]
dtype0 = DTYPES[0]
fig, axes = plt.subplots(2, len(reports), figsize=(3.6 * len(reports), 6.6), squeeze=False)
for j, (label, rep) in enumerate(reports.items()):
    rows = [r for r in rep["rows"] if r["dtype"] == dtype0]
    names = [r["config"] for r in rows]
    y = np.arange(len(rows))
    axes[0, j].barh(y - 0.2, [r["iterations"]["median"] for r in rows], 0.4, label="median")
    axes[0, j].barh(y + 0.2, [r["iterations"]["p99"] for r in rows], 0.4, label="p99")
    axes[0, j].set(yticks=y, yticklabels=names if j == 0 else [], xscale="log", xlabel="iterations",
                   title=f"{label} ({dtype0})")
    left = np.zeros(len(rows))
    for k, st in enumerate(statuses):
        frac = np.array([100 * r["status"].get(st, 0) / r["n"] for r in rows])
        if frac.any():
            axes[1, j].barh(y, frac, left=left, color=plt.cm.tab10(k), label=st)
            left += frac
    axes[1, j].set(yticks=y, yticklabels=names if j == 0 else [], xlabel="lanes (%)", xlim=(0, 100))
axes[0, 0].legend(fontsize=7)
seen = sorted({st for rep in reports.values() for r in rep["rows"] for st in r["status"]}, key=lambda n: cj.Status[n])
fig.legend([Patch(color=plt.cm.tab10(cj.Status[st].value)) for st in seen], seen, loc="lower center",
           ncol=min(len(seen), 5), fontsize=8)
fig.suptitle("Iterations of found lanes (top) and final status of every lane (bottom)")
fig.tight_layout(rect=(0, 0.07, 1, 1))
plt.show()
for st in statuses:
    print(cj.Status.explain(cj.Status[st].value))

# %% [markdown]
# ## Where on the floor each solver fails
#
# Receivers on the floor, coloured by their status where the solver did not return a
# path (grey: found). `NO_CROSSING` lanes (the segment to the light misses the surface)
# fail for every solver alike: they are where the light does not reach through the water.

# %%
cmap = plt.cm.tab10
for label, rep in reports.items():
    xy = np.asarray(rep["receivers"])[:, :2]
    rows = [r for r in rep["rows"] if r["dtype"] == dtype0]
    cols = min(len(rows), 5)
    nrow = -(-len(rows) // cols)
    fig, axes = plt.subplots(nrow, cols, figsize=(2.5 * cols, 2.8 * nrow + 0.5), squeeze=False)
    for ax, r in zip(axes.ravel(), rows, strict=False):
        st = np.asarray(r["lane_status"])
        ok = st == cj.Status.FOUND
        ax.scatter(*xy[ok].T, s=1, c="0.85", rasterized=True)
        for code in np.unique(st[~ok]):
            sel = st == code
            ax.scatter(*xy[sel].T, s=2, color=cmap(int(code)), label=cj.Status(int(code)).name, rasterized=True)
        ax.set_title(f"{r['config']}: {100 * (1 - ok.mean()):.1f}% fail", fontsize=8)
        ax.set_aspect("equal")
        ax.set(xticks=[], yticks=[])
        if (~ok).any():
            ax.legend(fontsize=5, markerscale=3, loc="lower left")
    for ax in axes.ravel()[len(rows):]:
        ax.axis("off")
    lo, hi = xy.min(0), xy.max(0)
    fig.suptitle(f"{label}: failing receivers on the floor ({dtype0}; x {lo[0]:.1f}..{hi[0]:.1f} m, "
                 f"y {lo[1]:.1f}..{hi[1]:.1f} m)", fontsize=9)
    fig.tight_layout(h_pad=1.5)
    plt.show()

# %% [markdown]
# ## Walk against the best Newton, per scene
#
# The throughput ratio of the walk over the best optimistix configuration (best success,
# then speed), as `caustics-jax compare` prints it.

# %%
for label, rep in reports.items():
    for q in compare.ratios(rep):
        print(f"{label:<16}[{q['dtype']}] walk / {q['best_newton']}: {q['speed_ratio']:.2f}x "
              f"(success {fmt(q['walk_success'], '.3f')} vs {fmt(q['newton_success'], '.3f')})")

# %% [markdown]
# ## The same race in GLSL: the walk and the one-step Newton as shaders
#
# The comparison above runs the solvers in JAX, whose cost model (vmapped selects, XLA:CPU
# fusion) is not a shader's. `python -m experiments.glsl_throughput` runs the GLSL walk and
# the GLSL one-step Newton (`newton-hv-step`, `caustics_jax/shaders/newton.glsl`) on
# lavapipe, beside the same two solvers in JAX, on the same lanes of the exported scenes
# (start point through the face cells, the solver, D and E; float32), alternating, CPU time
# per lane. This cell reads its committed result, `figures/glsl_throughput.json`; rerun the
# experiment (`make figures-vulkan`) to measure this machine. Lavapipe is a CPU standing in
# for a GPU: the ratios are provisional until `tools/gpu_recipe.py` runs on one
# (docs/export.md "The race in GLSL").

# %%
import json  # noqa: E402

glsl = json.loads((Path(cj.__file__).resolve().parents[1] / "figures" / "glsl_throughput.json").read_text())
rows = {(r["scene"], r["solver"]): r for r in glsl["rows"]}
names = list(glsl["ratios"])
print(f"{'scene':<14}{'solver':<8}{'JAX us/lane':>12}{'GLSL us/lane':>14}{'iterations':>12}"
      f"{'in subgroups of ' + str(glsl['subgroup_size']):>22}")
for name in names:
    for solver in glsl["solvers"]:
        r = rows[name, solver]
        print(f"{name:<14}{solver:<8}{r['jax_cpu_us_per_lane']:>12.1f}{r['glsl_cpu_us_per_lane']:>14.2f}"
              f"{r['iterations_per_lane']:>12.2f}{r['iterations_per_subgroup_lane']:>22.2f}")
fig, ax = plt.subplots(1, 2, figsize=(10, 3.4))
x = np.arange(len(names))
for k, solver in enumerate(glsl["solvers"]):
    ax[0].bar(x + (k - 0.5) * 0.4, [rows[n, solver]["jax_cpu_us_per_lane"] for n in names], 0.4, label=solver)
    ax[1].bar(x + (k - 0.5) * 0.4, [rows[n, solver]["glsl_cpu_us_per_lane"] for n in names], 0.4, label=solver)
for a, title in zip(ax, ("JAX on XLA:CPU", f"GLSL on {glsl['rows'][0]['device']}"), strict=True):
    a.set_xticks(x, names, fontsize=8)
    a.set(title=title, ylabel="CPU time per lane (us)")
    a.legend(fontsize=8)
fig.suptitle(f"Walk against one-step Newton, float32, {glsl['lanes']} lanes per scene (same CPU, one process)")
fig.tight_layout()
plt.show()
for name, q in glsl["ratios"].items():
    print(f"{name:<14} walk / Newton: GLSL {q['glsl_walk_over_newton_cpu']:.2f}, "
          f"JAX {q['jax_walk_over_newton_cpu']:.2f}")
