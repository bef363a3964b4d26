# %% [markdown]
# # Start points on any mesh: grid cells, binned cells and the BVH
#
# Questions (issue 15 item 4):
#
# 1. How fast is `start_points` (first crossing of `P -> L` with the water, seed 001
#    §3.4.2) on each acceleration structure, against the triangle count? Meshes: the
#    generator's wavy pool (`GridInfo`), the same arrays loaded with
#    `SurfaceMesh.from_arrays` (no `GridInfo`: the grid is recognised by
#    `grid.detect_grid`), the pool with its vertices jittered by 20% of a cell (binned
#    cells) and the Delaunay lagoon (binned cells); each against the BVH reference.
# 2. On 100k lanes of 32k-triangle meshes, what do start points cost against the walk
#    itself (target: at most a tenth)?
# 3. How much does `features="auto"` gain on a flat mesh a user loads from arrays (a
#    regular grid without `grid=`, and a jittered irregular one), start points included
#    (target: at least 5x), against the same gain with the BVH start points of before?
#
# Also: agreement with the BVH (found, face, point), build times, and the time and memory
# of building the 1M-triangle wavy scene in a fresh process. Calls of the variants are
# interleaved round by round (the machine is shared; ratios of interleaved medians follow
# its drifting load far less than back-to-back blocks).
#
# Run: `python -m experiments.start_point_throughput` (writes
# `figures/start_point_throughput.png` and `.json`, prints tables; `--quick` for a short
# run at 4k and 16k triangles only).

# %%
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from functools import partial

import jax
import numpy as np

import caustics_jax as cj
from caustics_jax.accel.bvh import build_bvh
from caustics_jax.accel.prepared import prepare
from caustics_jax.accel.start_points import build_accel, start_points
from caustics_jax.math.barycentric import barycentric_point
from caustics_jax.surface.mesh import SurfaceMesh
from caustics_jax.surface.scenes import flat_pool, lagoon, wavy_pool
from caustics_jax.testing.meshes import jittered_grid
from experiments.common import ROOT, parse_args, use_agg, write_json

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "start_point_throughput.png"
SIZES = [4_000, 16_000, 62_000, 250_000, 1_000_000]
N_SEGMENTS = 128 * 128  # receivers on the pool floor, per call of the size sweep
N_LANES = int(os.environ.get("SPT_LANES", 100_000))  # questions 2 and 3
MID = 32_000  # triangles for questions 2 and 3
REPEATS = 3
DTYPE = "float32"  # what shaders run
LIGHT = (0.4, -0.3, 3.0)  # the scenes' point light, 3 m above the water
OBLIQUE = (5.0, 0.0, 3.0)  # a low (31 degree) light: oblique segments cross more cells


def interleaved(fns: dict, repeats: int = REPEATS):
    """Per variant `(first call s, median s, result)`; rounds call every variant once, in an
    order rotated per round."""
    first, times, out = {}, {k: [] for k in fns}, {}
    for k, fn in fns.items():
        t = time.perf_counter()
        out[k] = jax.block_until_ready(fn())
        first[k] = time.perf_counter() - t
    keys = list(fns)
    for r in range(repeats):
        for k in keys[r % len(keys):] + keys[: r % len(keys)]:
            t = time.perf_counter()
            jax.block_until_ready(fns[k]())
            times[k].append(time.perf_counter() - t)
    return {k: (first[k], float(np.median(times[k])), out[k]) for k in fns}


def meshes(n: int) -> dict:
    """The four meshes of question 1 at about `n` triangles, float32."""
    pool = wavy_pool(n, seed=0, dtype=DTYPE).surface
    return {
        "pool (GridInfo)": pool,
        "pool from arrays": SurfaceMesh.from_arrays(np.asarray(pool.vertices), np.asarray(pool.faces)),
        "jittered pool": jittered_grid(n, 0.2, seed=0, dtype=DTYPE),
        "lagoon": lagoon(n, seed=0, dtype=DTYPE).surface,
    }


def floor_lanes(n: int, light, seed: int = 0):
    """`n` receivers uniform on the pool floor (z = -1 m, |x|, |y| <= 2 m) and the light."""
    rng = np.random.default_rng(seed)
    P = np.concatenate([rng.uniform(-2, 2, (n, 2)), np.full((n, 1), -1.0)], -1).astype(DTYPE)
    return P, np.broadcast_to(np.asarray(light, DTYPE), P.shape)


def point_of(mesh, sp):
    return np.asarray(barycentric_point(mesh.triangle(sp.face)[0], sp.barycentric), np.float64)


def agreement(mesh, fast, ref) -> dict:
    found = np.asarray(ref.found)
    both = found & np.asarray(fast.found)
    return dict(found_equal=float(np.mean(np.asarray(fast.found) == found)),
                face_equal=float(np.mean(np.asarray(fast.face)[found] == np.asarray(ref.face)[found])),
                max_point_diff_m=float(np.max(np.abs(point_of(mesh, fast) - point_of(mesh, ref))[both],
                                              initial=0)))  # fmt: skip


# %% [markdown]
# ## 1. Throughput against the triangle count

# %%
def sweep(sizes) -> list:
    rows = []
    for n in sizes:
        for name, mesh in meshes(n).items():
            t = time.perf_counter()
            accel = build_accel(mesh)
            accel_s = time.perf_counter() - t
            t = time.perf_counter()
            bvh = build_bvh(mesh)
            bvh_s = time.perf_counter() - t
            lights = {"overhead": LIGHT, "oblique": OBLIQUE} if name != "lagoon" else {"overhead": LIGHT}
            for light, pos in lights.items():
                P, L = floor_lanes(N_SEGMENTS, pos)
                res = interleaved({"accel": partial(start_points, mesh, P, L, accel=accel),
                                   "bvh": partial(start_points, mesh, P, L, method="general", bvh=bvh)})  # fmt: skip
                row = dict(mesh=name, light=light, triangles=int(mesh.faces.shape[0]),
                           accel=type(accel).__name__ + f"/{getattr(accel, 'kind', 'bvh')}",
                           cell_faces=int(accel.faces.shape[1]) if hasattr(accel, "faces") else None,
                           accel_build_s=accel_s, bvh_build_s=bvh_s,
                           accel_per_s=N_SEGMENTS / res["accel"][1], bvh_per_s=N_SEGMENTS / res["bvh"][1],
                           accel_compile_s=max(res["accel"][0] - res["accel"][1], 0.0),
                           found=float(np.mean(np.asarray(res["accel"][2].found))),
                           agreement=agreement(mesh, res["accel"][2], res["bvh"][2]))  # fmt: skip
                rows.append(row)
                print(f"{name:18s} {light:8s} F={row['triangles']:>9,d} {row['accel']:15s} K={row['cell_faces']}"
                      f"  accel {row['accel_per_s']:>10,.0f}/s  bvh {row['bvh_per_s']:>8,.0f}/s"
                      f"  x{row['accel_per_s'] / row['bvh_per_s']:6.1f}  build {accel_s:5.2f}s / bvh {bvh_s:5.2f}s"
                      f"  found {row['found']:.3f} agree {row['agreement']}", flush=True)  # fmt: skip
    return rows


# %% [markdown]
# ## 2. Start points against the walk (100k lanes, 32k triangles)

# %%
def against_walk() -> list:
    rows = []
    P, L = floor_lanes(N_LANES, LIGHT, seed=1)
    for name, mesh in meshes(MID).items():
        if name == "pool (GridInfo)":
            continue  # same structure and speed as "pool from arrays" (question 1)
        prep = prepare(mesh)
        bvh = build_bvh(mesh)
        sp = prep.start_points(P, L)
        res = interleaved({"start points": partial(prep.start_points, P, L),
                           "start points (BVH)": partial(start_points, mesh, P, L, method="general", bvh=bvh),
                           "walk": partial(cj.solve, prep, P, L, start=sp, features=None)}, repeats=2)  # fmt: skip
        row = dict(mesh=name, triangles=int(mesh.faces.shape[0]), lanes=N_LANES,
                   accel=type(prep.accel).__name__ + f"/{getattr(prep.accel, 'kind', 'bvh')}",
                   seconds={k: v[1] for k, v in res.items()},
                   compile_s={k: max(v[0] - v[1], 0) for k, v in res.items()})  # fmt: skip
        row["start_over_walk"] = row["seconds"]["start points"] / row["seconds"]["walk"]
        row["bvh_over_walk"] = row["seconds"]["start points (BVH)"] / row["seconds"]["walk"]
        rows.append(row)
        print(f"{name:18s} F={row['triangles']:,d} {row['accel']}: " + ", ".join(
            f"{k} {v:.3f}s" for k, v in row["seconds"].items())
            + f"; start/walk {row['start_over_walk']:.3f} (BVH {row['bvh_over_walk']:.2f})", flush=True)  # fmt: skip
    return rows


# %% [markdown]
# ## 3. `features="auto"` on flat user meshes (100k lanes, 32k triangles)
#
# "auto (BVH start points)" is the same call with the prepared surface's structure
# replaced by the BVH: what the features path cost before the cells. `None` and `auto`:
# median of 5 interleaved calls after the compiling one (a single call moved the gain on
# the jittered mesh between 4.7x and 7.9x over four runs); the BVH variant: one timed
# call (it takes seconds per call).

# %%
def flat_gain() -> list:
    rows = []
    P, L = floor_lanes(N_LANES, LIGHT, seed=2)
    pool = flat_pool(MID, dtype=DTYPE).surface
    flats = {"flat pool (GridInfo)": pool,
             "flat grid from arrays": SurfaceMesh.from_arrays(np.asarray(pool.vertices), np.asarray(pool.faces)),
             "jittered flat mesh": jittered_grid(MID, 0.2, seed=0, flat=True, dtype=DTYPE)}  # fmt: skip
    for name, mesh in flats.items():
        prep = prepare(mesh)
        before = prep.with_accel(build_bvh(mesh))
        res = interleaved({"None": partial(cj.solve, prep, P, L, features=None),
                           "auto": partial(cj.solve, prep, P, L, features="auto")}, repeats=5)  # fmt: skip
        res.update(interleaved({"auto (BVH start points)": partial(cj.solve, before, P, L, features="auto")},
                               repeats=1))  # fmt: skip
        a, b = (cj.solve(prep, P, L, features=f) for f in (None, "auto"))
        found = np.asarray(a.found) & np.asarray(b.found)
        row = dict(mesh=name, triangles=int(mesh.faces.shape[0]), lanes=N_LANES, flat=bool(prep.features.flat),
                   accel=type(prep.accel).__name__ + f"/{getattr(prep.accel, 'kind', 'bvh')}",
                   solves_per_s={k: N_LANES / v[1] for k, v in res.items()},
                   status_equal=float(np.mean(np.asarray(a.status) == np.asarray(b.status))),
                   max_point_diff_m=float(np.max(np.abs(np.asarray(a.point) - np.asarray(b.point))[found],
                                                 initial=0)))  # fmt: skip
        s = row["solves_per_s"]
        row["gain"] = s["auto"] / s["None"]
        row["gain_bvh_start_points"] = s["auto (BVH start points)"] / s["None"]
        rows.append(row)
        print(f"{name:22s} flat={row['flat']} {row['accel']}: " + ", ".join(f"{k} {v:,.0f}/s" for k, v in s.items())
              + f"; gain {row['gain']:.1f}x (BVH start points {row['gain_bvh_start_points']:.1f}x), status equal "
              f"{row['status_equal']:.4f}, max |dM| {row['max_point_diff_m']:.1e} m", flush=True)  # fmt: skip
    return rows


# %% [markdown]
# Build time and peak memory of the 1M-triangle wavy scene, in a fresh process (peak RSS
# is per process; the baseline is the interpreter with jax and the package imported).

# %%
_BUILD_1M = """
import time, json, jax
import caustics_jax.surface.scenes as S

def vm(key):  # this process's own high-water mark (ru_maxrss survives exec from the parent)
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) / 1024

base = vm("VmHWM")
t = time.perf_counter()
scene = S.wavy_pool(1_000_000, seed=0, dtype="float32")
jax.block_until_ready(scene.surface.vertices)
dt = time.perf_counter() - t
print(json.dumps(dict(triangles=int(scene.surface.faces.shape[0]), build_s=dt,
                      baseline_rss_mib=base, peak_rss_mib=vm("VmHWM"), final_rss_mib=vm("VmRSS"))))
"""


def build_1m():
    out = subprocess.run([sys.executable, "-c", _BUILD_1M], capture_output=True, text=True,
                         check=True, cwd=ROOT)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


# %%
COLORS = {"pool (GridInfo)": "C0", "pool from arrays": "C9", "jittered pool": "C1", "lagoon": "C2"}


def plot(sweep_rows, walk_rows, flat_rows, path=FIG):
    fig, (ax, ax_w, ax_f) = plt.subplots(1, 3, figsize=(17, 5.5), width_ratios=[5, 3, 3])
    for name, color in COLORS.items():
        for light, style in (("overhead", "-"), ("oblique", ":")):
            r = [x for x in sweep_rows if x["mesh"] == name and x["light"] == light]
            if not r:
                continue
            F = [x["triangles"] for x in r]
            kind = r[0]["accel"].split("/")[1]
            ax.plot(F, [x["accel_per_s"] for x in r], "o" + style, color=color, label=f"{name}: {kind} cells, {light}")
            if light == "overhead":
                ax.plot(F, [x["bvh_per_s"] for x in r], "x--", color=color, alpha=0.6, label=f"{name}: BVH, overhead")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("water surface triangles")
    ax.set_ylabel("start points per second (segments/s)")
    ax.set_title(f"start_points throughput: cells vs BVH\n({N_SEGMENTS:,} floor receivers per call, {DTYPE}, "
                 f"{jax.devices()[0].platform.upper()}, median of {REPEATS}, shared 2-core machine)",
                 fontsize=10)  # fmt: skip
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)

    names = [r["mesh"] for r in walk_rows]
    x = np.arange(len(names))
    for k, (key, color) in enumerate((("start points", "C0"), ("start points (BVH)", "C3"), ("walk", "C7"))):
        ax_w.bar(x + (k - 1) * 0.27, [r["seconds"][key] for r in walk_rows], 0.27, color=color, label=key)
    for i, r in enumerate(walk_rows):
        ax_w.annotate(f"{r['start_over_walk']:.3f}x walk", (i - 0.27, r["seconds"]["start points"]),
                      ha="center", va="bottom", fontsize=7)  # fmt: skip
    ax_w.set_xticks(x, [n.replace(" ", "\n", 1) for n in names], fontsize=8)
    ax_w.set_yscale("log")
    ax_w.set_ylabel(f"seconds per call ({N_LANES:,} lanes)")
    ax_w.set_title(f"start points vs the walk\n({walk_rows[0]['triangles']:,}-ish triangles, {DTYPE})", fontsize=10)
    ax_w.set_ylim(top=ax_w.get_ylim()[1] * 6)  # room for the legend above the bars
    ax_w.legend(fontsize=7, loc="upper left")
    ax_w.grid(True, axis="y", which="both", alpha=0.3)

    names = [r["mesh"] for r in flat_rows]
    x = np.arange(len(names))
    for k, (key, color) in enumerate((("None", "C7"), ("auto (BVH start points)", "C3"), ("auto", "C0"))):
        ax_f.bar(x + (k - 1) * 0.27, [r["solves_per_s"][key] for r in flat_rows], 0.27, color=color,
                 label=f'features="{key}"' if key != "auto (BVH start points)" else 'features="auto", BVH start points')
    for i, r in enumerate(flat_rows):
        ax_f.annotate(f"{r['gain']:.1f}x", (i + 0.27, r["solves_per_s"]["auto"]), ha="center", va="bottom", fontsize=8)
    ax_f.set_xticks(x, [n.replace(" ", "\n", 1) for n in names], fontsize=8)
    ax_f.set_yscale("log")
    ax_f.set_ylabel("solves per second (walk, start points included)")
    ax_f.set_title(f'features="auto" on flat meshes\n({N_LANES:,} lanes, {DTYPE})', fontsize=10)
    ax_f.set_ylim(top=ax_f.get_ylim()[1] * 8)  # room for the legend above the bars
    ax_f.legend(fontsize=7, loc="upper left")
    ax_f.grid(True, axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# %%
if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="4k and 16k triangles only, no 1M build")
    args = parse_args(parser)
    load_start = os.getloadavg()  # the machine is shared: record how busy it was
    t0 = time.perf_counter()
    sweep_rows = sweep(SIZES[:2] if args.quick else SIZES)
    walk_rows = against_walk()
    flat_rows = flat_gain()
    mem = None if args.quick else build_1m()
    if mem:
        print(f"1M wavy scene: {mem['triangles']:,d} triangles built in {mem['build_s']:.2f} s, peak RSS "
              f"{mem['peak_rss_mib']:.0f} MiB (baseline {mem['baseline_rss_mib']:.0f} MiB)")  # fmt: skip
    plot(sweep_rows, walk_rows, flat_rows)
    meta = dict(segments=N_SEGMENTS, lanes=N_LANES, dtype=DTYPE, repeats=REPEATS, device=str(jax.devices()[0]),
                jax=jax.__version__, light=LIGHT, oblique=OBLIQUE, load_avg_start=load_start,
                load_avg_end=os.getloadavg(), run_s=time.perf_counter() - t0)  # fmt: skip
    write_json(FIG.with_suffix(".json"), dict(meta=meta, sweep=sweep_rows, against_walk=walk_rows,
                                              flat_gain=flat_rows, build_1m=mem))  # fmt: skip
    print(f"wrote {FIG} and {FIG.with_suffix('.json')}")
