# %% [markdown]
# # Start-point throughput against triangle count (grid DDA vs BVH)
#
# Question: how does the cost of `start_points` (first crossing of `P -> L` with the water,
# seed 001 §3.4.2) grow with the tessellation, for the heightfield-grid fast path and the
# general BVH path? Tessellations sweep seed 001 Fig. 10's range (4k-117k) up to 1M.
# Also measured here, not in tests: the time and peak memory of building the 1M-triangle
# wavy scene (validation, adjacency, normals) in a fresh process.
#
# Run: `python -m experiments.start_point_throughput` (writes
# `figures/start_point_throughput.png` and `.json`, prints a table).

# %%
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import jax
import numpy as np

from caustics_jax.barycentric import barycentric_point
from caustics_jax.scenes import lagoon, wavy_pool
from caustics_jax.start_points import build_bvh, start_points
from experiments.common import ROOT, use_agg, write_json

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "start_point_throughput.png"
SIZES = [100, 1_000, 4_000, 16_000, 62_000, 117_000, 250_000, 1_000_000]
N_SEGMENTS = 128 * 128  # receivers on the pool floor
REPEATS = 5
DTYPE = "float32"  # what shaders run

# Light placements: the seed's overhead point light, and a low (30 degree) light whose
# oblique segments cross many grid cells inside the wave slab (the grid path's worst case).
LIGHTS = {"overhead": (0.4, -0.3, 3.0), "oblique": (5.0, 0.0, 3.0)}


def _median_time(fn, repeats=REPEATS):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def measure(scene, method, bvh=None):
    mesh = scene.surface
    P = scene.receivers
    L = scene.lights.endpoint(P, 0)
    t = time.perf_counter()
    out = jax.block_until_ready(start_points(mesh, P, L, method=method, bvh=bvh))
    first_call = time.perf_counter() - t
    run = _median_time(lambda: start_points(mesh, P, L, method=method, bvh=bvh))
    return out, dict(seconds=run, segments_per_s=P.shape[0] / run,
                     compile_s=max(first_call - run, 0.0),
                     found=float(np.mean(out.found)))  # fmt: skip


def slab_cells(scene):
    """Cells each segment's xy projection crosses inside the wave slab: the grid path's
    per-segment work bound `k` (the DDA stops earlier, at the first crossing)."""
    g = scene.surface.grid
    P = np.asarray(scene.receivers, np.float64)
    L = np.asarray(scene.lights.endpoint(scene.receivers, 0), np.float64)
    z = np.asarray(scene.surface.vertices[:, 2], np.float64)
    d = L - P
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.array([g.x0, g.y0, z.min()])
        hi = np.array([g.x0 + g.nx * g.dx, g.y0 + g.ny * g.dy, z.max()])
        t0, t1 = (lo - P) / d, (hi - P) / d
    s_in = np.clip(np.max(np.minimum(t0, t1), -1), 0, 1)
    s_out = np.clip(np.min(np.maximum(t0, t1), -1), 0, 1)
    cell = np.array([g.dx, g.dy])
    ij_in = np.floor(((P + s_in[:, None] * d)[:, :2] - lo[:2]) / cell)
    ij_out = np.floor(((P + s_out[:, None] * d)[:, :2] - lo[:2]) / cell)
    k = np.where(s_in <= s_out, np.abs(ij_out - ij_in).sum(-1) + 1, 0)
    return dict(mean=float(k.mean()), max=int(k.max()))


# %%
def sweep():
    rows = []
    for n in SIZES:
        for light, pos in LIGHTS.items():
            kw = dict(n_receivers=128, light_position=pos, dtype=DTYPE)
            t = time.perf_counter()
            scene = wavy_pool(n, seed=0, **kw)
            build_s = time.perf_counter() - t
            t = time.perf_counter()
            bvh = build_bvh(scene.surface)
            bvh_s = time.perf_counter() - t
            F = int(scene.surface.faces.shape[0])
            grid_out, grid = measure(scene, "grid")
            grid["slab_cells"] = slab_cells(scene)
            gen_out, gen = measure(scene, "general", bvh)
            mesh = scene.surface
            both = np.asarray(grid_out.found & gen_out.found)
            gap = np.abs(np.asarray(
                barycentric_point(mesh.triangle(grid_out.face)[0], grid_out.barycentric)
                - barycentric_point(mesh.triangle(gen_out.face)[0], gen_out.barycentric)))
            agree = dict(found_equal=float(np.mean(np.asarray(grid_out.found == gen_out.found))),
                         max_point_diff_m=float(gap[both].max(initial=0)))  # fmt: skip
            rows.append(dict(scene="wavy_pool", light=light, triangles=F, build_s=build_s,
                             bvh_build_s=bvh_s, grid=grid, general=gen,
                             agreement=agree))  # fmt: skip
            print(f"wavy {light:8s} F={F:>9,d}  grid {grid['segments_per_s']:>12,.0f}/s  "
                  f"general {gen['segments_per_s']:>12,.0f}/s  found {grid['found']:.3f}  "
                  f"agree {agree['found_equal']:.4f} ({agree['max_point_diff_m']:.1e} m)  "
                  f"build {build_s:.2f}s bvh {bvh_s:.2f}s  slab cells mean "
                  f"{grid['slab_cells']['mean']:.1f} max {grid['slab_cells']['max']}",
                  flush=True)  # fmt: skip
        scene = lagoon(n, seed=0, n_receivers=128, dtype=DTYPE)
        t = time.perf_counter()
        bvh = build_bvh(scene.surface)
        bvh_s = time.perf_counter() - t
        _, gen = measure(scene, "general", bvh)
        F = int(scene.surface.faces.shape[0])
        rows.append(dict(scene="lagoon", light="overhead", triangles=F, bvh_build_s=bvh_s,
                         general=gen))  # fmt: skip
        print(f"lagoon overhead F={F:>9,d}  general {gen['segments_per_s']:>12,.0f}/s", flush=True)
    return rows


# %% [markdown]
# Build time and peak memory of the 1M-triangle wavy scene, in a fresh process (peak RSS
# is per process; the baseline is the interpreter with jax and the package imported).

# %%
_BUILD_1M = """
import time, json, jax
import caustics_jax.scenes as S

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
def plot(rows, path=FIG):
    fig, (ax, ax_k) = plt.subplots(1, 2, figsize=(12, 5), width_ratios=[3, 2])
    style = {"overhead": "-", "oblique": "--"}
    for light in LIGHTS:
        r = [x for x in rows if x["scene"] == "wavy_pool" and x["light"] == light]
        F = [x["triangles"] for x in r]
        ax.plot(F, [x["grid"]["segments_per_s"] for x in r], "o" + style[light], color="C0",
                label=f"grid DDA, wavy pool, {light} light")
        ax.plot(F, [x["general"]["segments_per_s"] for x in r], "s" + style[light], color="C1",
                label=f"general BVH, wavy pool, {light} light")
        for stat, marker in (("mean", "o"), ("max", "v")):
            ax_k.plot(F, [x["grid"]["slab_cells"][stat] for x in r], marker + style[light],
                      color="C0" if stat == "mean" else "C3", label=f"{stat}, {light} light")
    r = [x for x in rows if x["scene"] == "lagoon"]
    ax.plot([x["triangles"] for x in r], [x["general"]["segments_per_s"] for x in r], "^-",
            color="C2", label="general BVH, lagoon (irregular), overhead light")
    for a in (ax, ax_k):
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_xlabel("water surface triangles")
        a.grid(True, which="both", alpha=0.3)
    ax.set_ylabel("start points per second (segments/s)")
    ax.set_title(f"start_points throughput vs tessellation: grid DDA vs BVH\n"
                 f"({N_SEGMENTS} segments per call, float32, {jax.devices()[0].platform.upper()}, "
                 f"median of {REPEATS}, shared 2-core machine)")  # fmt: skip
    ax.legend(fontsize=8)
    ax_k.set_ylabel("grid cells crossed inside the wave slab (per segment)")
    ax_k.set_title("grid path work bound k vs tessellation\n(fixed wave height: k ~ 1 / cell size)")
    ax_k.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# %%
if __name__ == "__main__":
    load_start = os.getloadavg()  # the machine is shared: record how busy it was
    rows = sweep()
    mem = build_1m()
    print(f"1M wavy scene: {mem['triangles']:,d} triangles built in {mem['build_s']:.2f} s, "
          f"peak RSS {mem['peak_rss_mib']:.0f} MiB (baseline {mem['baseline_rss_mib']:.0f} MiB, "
          f"after {mem['final_rss_mib']:.0f} MiB)")
    plot(rows)
    meta = dict(segments=N_SEGMENTS, dtype=DTYPE, repeats=REPEATS, device=str(jax.devices()[0]),
                jax=jax.__version__, lights=LIGHTS, load_avg_start=load_start,
                load_avg_end=os.getloadavg())  # fmt: skip
    write_json(FIG.with_suffix(".json"), dict(meta=meta, rows=rows, build_1m=mem))
    print(f"wrote {FIG} and {FIG.with_suffix('.json')}")
