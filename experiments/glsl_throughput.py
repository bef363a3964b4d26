# %% [markdown]
# # The GLSL walk and the GLSL Newton on lavapipe against the JAX solvers, same CPU, same lanes
#
# Question: what does each solver's shader port cost per receiver, next to the other and to
# the testbed? Every run does the whole per-lane pipeline of an exported scene (docs/export.md
# "Scenes"): the start point (a 2D DDA over the face cells, the same cells as the testbed's),
# the solver in float32 (the curve walk of seed 001 §3.4, or the one-step Newton on the
# half-vector constraint, `newton-hv-step`), D (eq. 26-33) and the irradiance (eq. 25,
# math.md §6) at the found point.
#
# - JAX: `solve(..., method=Walk(fallback="none") or export.NEWTON, features=None)` (start
#   points included) and `path_irradiance` at the solutions, jitted, on the CPU, after a
#   warm-up call.
# - GLSL: the scene shader (`caustics_jax.shaders.scene_conformance`) in Mesa's lavapipe on
#   the same CPU, dispatch time only (submit to fence; the shader and pipeline are compiled
#   and the buffers uploaded before), on the walk's and the Newton's scene files.
#
# Rounds alternate the four (JAX walk, GLSL walk, JAX Newton, GLSL Newton) so that the load
# of a shared machine falls on all; the median of the rounds is reported, as CPU time (the
# process's, all threads: on a shared machine the load stretches wall time, not CPU time)
# and as wall time. Divergence: lavapipe runs a subgroup of `subgroup_size` consecutive
# lanes in lockstep, so a subgroup costs its slowest lane's iterations; the table gives the
# iterations per lane and the mean over subgroups of their largest (the lanes are in the
# export's order, shuffled cases: a renderer's screen-ordered lanes are more coherent),
# also for the subgroups of 32 and 64 lanes of GPUs.
#
# Run: `python -m experiments.glsl_throughput` (needs glslangValidator, a C compiler and a
# Vulkan driver; writes `figures/glsl_throughput.png` and `.json`, prints a table).
# `CJ_VK_DEVICE_NAME=<text>` picks another Vulkan device (tools/gpu_recipe.py).

# %%
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from caustics_jax import SurfaceMesh, Walk, precision, solve
from caustics_jax.export import NEWTON, SCENES, load_scene, scene_stem, write_scenes
from caustics_jax.shaders import conformance as conf
from caustics_jax.shaders import scene_conformance as sc
from caustics_jax.shaders import vulkan as vk
from caustics_jax.transport.contribution import path_irradiance
from experiments.common import ROOT, parse_args, use_agg, write_json

use_agg()
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

FIG = ROOT / "figures" / "glsl_throughput.png"
SCENE_NAMES = ("wavy_gentle", "wavy_steep", "lagoon", "wavy_jittered")
SOLVERS = {"walk": Walk(fallback="none"), "newton": NEWTON}
#: Subgroup widths whose lockstep iteration cost is reported besides the device's own (GPU
#: subgroups: 32 on NVIDIA, 32 or 64 on AMD).
LOCKSTEP_WIDTHS = (8, 32, 64)


# %%
def jax_pipeline(manifest, buffers, method):
    """A function running start point + `method` + D and E on the scene's lanes (float32),
    and the lane count. The mesh is rebuilt from the scene buffers; the grid layout (the
    manifest's, in float64 as the export had it) is set without the check of `from_arrays`,
    which the float32-rounded vertices need not pass."""
    import dataclasses

    from caustics_jax.surface.mesh import GridInfo

    v, f, lanes = buffers["vertices"], buffers["faces"], buffers["lanes"]
    g = manifest["grid"]
    mesh = SurfaceMesh.from_arrays(v["position"], f["v"], v["normal"], dtype="float32")
    if g is not None:
        mesh = dataclasses.replace(mesh, grid=GridInfo(g["nx"], g["ny"], g["x0"], g["y0"], g["dx"], g["dy"]))
    P, L = jnp.asarray(lanes["P"]), jnp.asarray(lanes["L"])
    n_P, I_e, sigma_t = (jnp.asarray(lanes[k]) for k in ("receiver_normal", "intensity", "sigma_t"))
    eta = float(lanes["eta"][0])

    def run():
        sol = solve(mesh, P, L, eta=eta, method=method, features=None)
        V, N = mesh.triangle(sol.triangle)
        E, _ = path_irradiance(V, N, P, L, sol.barycentric, eta, I_e, n_P, sigma_t)
        return jax.block_until_ready((sol.status, E))

    return run, len(lanes["P"])


def timed(fn) -> tuple[float, float]:
    """Wall time and this process's CPU time (all threads) of `fn()`, in seconds."""
    t, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t, time.process_time() - c


def lockstep_iterations(iterations: np.ndarray, width: int) -> float:
    """Mean over consecutive groups of `width` lanes of their largest iteration count: what a
    subgroup running its lanes in lockstep pays per lane (the last group padded with 0)."""
    it = np.asarray(iterations, np.float64)
    pad = (-len(it)) % width
    return float(np.mean(np.pad(it, (0, pad)).reshape(-1, width).max(1)))


# %%
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--lanes", type=int, default=16384)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--scenes", nargs="+", default=list(SCENE_NAMES), choices=sorted(SCENES))
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
    ap.add_argument("--figure", default=str(FIG))
    ap.add_argument("--data", default=None, help="reuse the scene files of this directory (written with --lanes)")
    args = parse_args(ap, argv)
    rows = []
    with tempfile.TemporaryDirectory() as work_dir, precision("float32"):
        work = Path(work_dir)
        data = Path(args.data) if args.data else work / "scenes"
        if not args.data:
            data.mkdir()
            write_scenes(data, [SCENES[n] for n in args.scenes], args.lanes, seed=0)
        host = conf.build_host(work)
        spv = conf.compile_shader(sc.scene_shader_source(), work / "scene.spv")
        wanted = os.environ.get("CJ_VK_DEVICE_NAME") or ""
        device_info = next((d for d in vk.list_devices(host) if wanted in d["name"]), {})
        width = int(device_info.get("subgroup_size") or 1)
        for name in args.scenes:
            runs = {}
            for solver, method in SOLVERS.items():
                manifest, buffers = load_scene(data, scene_stem(name, solver))
                run, n = jax_pipeline(manifest, buffers, method)
                compile_s, _ = timed(run)
                runs[solver] = {"run": run, "n": n, "first_call_s": compile_s, "buffers": buffers,
                                "jax_s": [], "jax_cpu_s": [], "glsl_s": [], "glsl_cpu_s": []}
            for _ in range(args.rounds):
                for solver, r in runs.items():
                    wall, cpu = timed(r["run"])
                    r["jax_s"].append(wall)
                    r["jax_cpu_s"].append(cpu)
                    rep = sc.run_scene(data, scene_stem(name, solver), work / name, host=host, spv=spv, repeat=3,
                                       keep_lanes=True)
                    r["glsl_s"].append(rep["dispatch_seconds"])
                    r["glsl_cpu_s"].append(rep["dispatch_cpu_seconds"])
                    r["report"] = rep
            for solver, r in runs.items():
                n, rep = r["n"], r["report"]
                us = lambda x, n=n: 1e6 * float(np.median(x)) / n  # noqa: E731
                it_port = rep.pop("port_lanes")["iterations"]
                scene_rec = r["buffers"]["scene"]
                row = {"scene": name, "solver": solver, "lanes": n, "jax_s": r["jax_s"], "jax_cpu_s": r["jax_cpu_s"],
                       "glsl_s": r["glsl_s"], "glsl_cpu_s": r["glsl_cpu_s"], "jax_first_call_s": r["first_call_s"],
                       "jax_us_per_lane": us(r["jax_s"]), "glsl_us_per_lane": us(r["glsl_s"]),
                       "jax_cpu_us_per_lane": us(r["jax_cpu_s"]), "glsl_cpu_us_per_lane": us(r["glsl_cpu_s"]),
                       "device": rep["device"], "passed": rep["passed"], "status_agreement": rep["status_agreement"],
                       "found_port": rep["found_port"], "found_testbed": rep["found_testbed"],
                       "iterations_per_lane": float(np.mean(it_port)),
                       "iterations_per_subgroup_lane": lockstep_iterations(it_port, width),
                       "iterations_lockstep": {str(w): lockstep_iterations(it_port, w) for w in LOCKSTEP_WIDTHS},
                       "crossed_per_lane": float(np.mean(r["buffers"]["lanes"]["crossed"])),
                       "general_mesh": not scene_rec["has_grid"][0],
                       "start_points": f"face cells ({'grid' if scene_rec['cell_kind'][0] == 0 else 'bins'}, "
                                       f"{int(scene_rec['cell_width'][0])} per row)"}
                row["glsl_over_jax"] = row["glsl_us_per_lane"] / row["jax_us_per_lane"]
                row["glsl_over_jax_cpu"] = row["glsl_cpu_us_per_lane"] / row["jax_cpu_us_per_lane"]
                rows.append(row)
                print(f"{name} {solver}: CPU JAX {row['jax_cpu_us_per_lane']:.2f} / GLSL "
                      f"{row['glsl_cpu_us_per_lane']:.2f} us per lane; iterations {row['iterations_per_lane']:.2f} "
                      f"(subgroup {row['iterations_per_subgroup_lane']:.2f})", flush=True)
    by = {(r["scene"], r["solver"]): r for r in rows}
    ratios = {name: {"glsl_walk_over_newton_cpu": by[name, "walk"]["glsl_cpu_us_per_lane"]
                     / by[name, "newton"]["glsl_cpu_us_per_lane"],
                     "jax_walk_over_newton_cpu": by[name, "walk"]["jax_cpu_us_per_lane"]
                     / by[name, "newton"]["jax_cpu_us_per_lane"]} for name in args.scenes}
    result = {"lanes": args.lanes, "rounds": args.rounds, "solvers": list(SOLVERS), "rows": rows, "ratios": ratios,
              "subgroup_size": width, "device": device_info, "cpu_count": os.cpu_count() or 0,
              "jax": jax.__version__, "backend": jax.default_backend()}
    write_json(args.json, result)
    plot(result, Path(args.figure))
    print(table(result))
    return result


def table(result) -> str:
    w = result["subgroup_size"]
    lines = ["| scene | solver | lanes | CPU us per lane: JAX | GLSL (lavapipe) | GLSL / JAX | wall us per lane: JAX | "
             f"GLSL | iterations per lane | per lane in subgroups of {w} | crossings per lane | status agreement |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['scene']} | {r['solver']} | {r['lanes']} | {r['jax_cpu_us_per_lane']:.1f} | "
                     f"{r['glsl_cpu_us_per_lane']:.2f} | {r['glsl_over_jax_cpu']:.2f} | {r['jax_us_per_lane']:.1f} | "
                     f"{r['glsl_us_per_lane']:.2f} | {r['iterations_per_lane']:.2f} | "
                     f"{r['iterations_per_subgroup_lane']:.2f} | {r['crossed_per_lane']:.2f} | "
                     f"{r['status_agreement']:.4f} |")
    lines += ["", "| scene | GLSL walk / GLSL Newton (CPU time) | JAX walk / JAX Newton |", "|---|---|---|"]
    for name, q in result["ratios"].items():
        lines.append(f"| {name} | {q['glsl_walk_over_newton_cpu']:.2f} | {q['jax_walk_over_newton_cpu']:.2f} |")
    return "\n".join(lines)


def plot(result, path: Path = FIG) -> None:
    rows = result["rows"]
    scenes = list(result["ratios"])
    x = np.arange(len(scenes))
    by = {(r["scene"], r["solver"]): r for r in rows}
    fig, ax = plt.subplots(figsize=(8.5, 4.8))
    bars = [("jax", "walk", "JAX walk (XLA:CPU)", "#9ecae1"), ("jax", "newton", "JAX one-step Newton", "#fdae6b"),
            ("glsl", "walk", "GLSL walk (lavapipe)", "#3182bd"), ("glsl", "newton", "GLSL one-step Newton", "#e6550d")]
    for k, (side, solver, label, color) in enumerate(bars):
        ax.bar(x + (k - 1.5) * 0.2, [by[s, solver][f"{side}_cpu_us_per_lane"] for s in scenes], 0.2, label=label,
               color=color)
    device = rows[0]["device"] if rows else ""
    ax.set_xticks(x, [f"{s}\n({by[s, 'walk']['start_points']})" for s in scenes], fontsize=8)
    ax.set_yscale("log")
    top = max(max(r["jax_cpu_us_per_lane"], r["glsl_cpu_us_per_lane"]) for r in rows)
    ax.set_ylim(1, 1.3 * top)
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.set_ylabel("CPU time per lane (us, all threads)\nstart point + solver + D + E")
    ax.set_title(f"Walk against one-step Newton per receiver, float32, {result['lanes']} lanes per scene\n"
                 f"GLSL on {device}; {result['cpu_count']} CPU cores, median of {result['rounds']} rounds",
                 fontsize=10)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.16))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)


# %%
if __name__ == "__main__":
    main()
