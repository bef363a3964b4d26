# %% [markdown]
# # The GLSL walk on lavapipe against the JAX walk, same CPU, same lanes
#
# Question: what does the shader port of the solver cost per receiver, next to the testbed?
# Both run the whole per-lane pipeline of an exported scene (docs/export.md "Scenes"): the
# start point (grid DDA on a heightfield, a first-crossing search on a general mesh), the
# curve walk of seed 001 §3.4 in float32, D (eq. 26-33) and the irradiance (eq. 25, math.md
# §6) at the found point.
#
# - JAX: `solve(..., method=Walk(fallback="none"), features=None)` (start points included) and
#   `path_irradiance` at the solutions, jitted, on the CPU, after a warm-up call.
# - GLSL: the scene shader (`caustics_jax.shaders.scene_conformance`) in Mesa's lavapipe on
#   the same CPU, dispatch time only (submit to fence; the shader and pipeline are compiled
#   and the buffers uploaded before).
#
# Rounds alternate JAX and GLSL so that the load of a shared machine falls on both; the
# median of the rounds is reported, as CPU time (the process's, all threads: on a shared
# machine the load stretches wall time, not CPU time) and as wall time. The GLSL
# general-mesh start point tests every face (O(F) per lane, documented in
# start_point.glsl), where the testbed traverses a BVH.
#
# Run: `python -m experiments.glsl_throughput` (needs glslangValidator, a C compiler and a
# Vulkan driver; writes `figures/glsl_throughput.png` and `.json`, prints a table).

# %%
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from caustics_jax import SurfaceMesh, Walk, precision, solve
from caustics_jax.export import SCENES, load_scene, write_scenes
from caustics_jax.shaders import conformance as conf
from caustics_jax.shaders import scene_conformance as sc
from caustics_jax.transport.contribution import path_irradiance
from experiments.common import ROOT, parse_args, use_agg, write_json

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

FIG = ROOT / "figures" / "glsl_throughput.png"
SCENE_NAMES = ("wavy_gentle", "wavy_steep", "lagoon", "wavy_jittered")


# %%
def jax_pipeline(manifest, buffers):
    """A function running start point + walk + D and E on the scene's lanes (float32), and the
    lane count. The mesh is rebuilt from the scene buffers; the grid layout (the manifest's,
    in float64 as the export had it) is set without the check of `from_arrays`, which the
    float32-rounded vertices need not pass."""
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
        sol = solve(mesh, P, L, eta=eta, method=Walk(fallback="none"), features=None)
        V, N = mesh.triangle(sol.triangle)
        E, _ = path_irradiance(V, N, P, L, sol.barycentric, eta, I_e, n_P, sigma_t)
        return jax.block_until_ready((sol.status, E))

    return run, len(lanes["P"])


def timed(fn) -> tuple[float, float]:
    """Wall time and this process's CPU time (all threads) of `fn()`, in seconds."""
    t, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t, time.process_time() - c


# %%
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--lanes", type=int, default=16384)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--scenes", nargs="+", default=list(SCENE_NAMES), choices=sorted(SCENES))
    ap.add_argument("--json", default=str(FIG.with_suffix(".json")))
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
        for name in args.scenes:
            manifest, buffers = load_scene(data, name)
            run, n = jax_pipeline(manifest, buffers)
            compile_s, _ = timed(run)
            jax_s, jax_cpu, glsl_s, glsl_cpu, device = [], [], [], [], ""
            for _ in range(args.rounds):
                wall, cpu = timed(run)
                jax_s.append(wall)
                jax_cpu.append(cpu)
                r = sc.run_scene(data, name, work / name, host=host, spv=spv, repeat=3)
                glsl_s.append(r["dispatch_seconds"])
                glsl_cpu.append(r["dispatch_cpu_seconds"])
                device = r["device"]
            us = lambda x, n=n: 1e6 * float(np.median(x)) / n  # noqa: E731
            row = {"scene": name, "lanes": n, "jax_s": jax_s, "jax_cpu_s": jax_cpu, "glsl_s": glsl_s,
                   "glsl_cpu_s": glsl_cpu, "jax_first_call_s": compile_s, "jax_us_per_lane": us(jax_s),
                   "glsl_us_per_lane": us(glsl_s), "jax_cpu_us_per_lane": us(jax_cpu),
                   "glsl_cpu_us_per_lane": us(glsl_cpu), "device": device,
                   "status_agreement": r["status_agreement"], "found_port": r["found_port"],
                   "iterations_per_lane": r["iterations_port"] / n, "general_mesh": not buffers["scene"]["has_grid"][0]}
            row["glsl_over_jax"] = row["glsl_us_per_lane"] / row["jax_us_per_lane"]
            row["glsl_over_jax_cpu"] = row["glsl_cpu_us_per_lane"] / row["jax_cpu_us_per_lane"]
            rows.append(row)
            print(f"{name}: wall JAX {row['jax_us_per_lane']:.2f} / GLSL {row['glsl_us_per_lane']:.2f} us per lane; "
                  f"CPU JAX {row['jax_cpu_us_per_lane']:.2f} / GLSL {row['glsl_cpu_us_per_lane']:.2f}", flush=True)
    result = {"lanes": args.lanes, "rounds": args.rounds, "rows": rows, "cpu_count": _cpu_count(),
              "jax": jax.__version__, "backend": jax.default_backend()}
    write_json(args.json, result)
    plot(result)
    print(table(result))
    return result


def _cpu_count() -> int:
    import os

    return os.cpu_count() or 0


def table(result) -> str:
    lines = ["| scene | lanes | GLSL start point | CPU us per lane: JAX | GLSL (lavapipe) | GLSL / JAX | "
             "wall us per lane: JAX | GLSL | GLSL / JAX | iterations per lane | status agreement |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['scene']} | {r['lanes']} | {'all faces' if r['general_mesh'] else 'grid DDA'} | "
                     f"{r['jax_cpu_us_per_lane']:.1f} | {r['glsl_cpu_us_per_lane']:.1f} | "
                     f"{r['glsl_over_jax_cpu']:.2f} | {r['jax_us_per_lane']:.1f} | {r['glsl_us_per_lane']:.1f} | "
                     f"{r['glsl_over_jax']:.2f} | {r['iterations_per_lane']:.1f} | {r['status_agreement']:.4f} |")
    return "\n".join(lines)


def plot(result) -> None:
    rows = result["rows"]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    ax.bar(x - 0.2, [r["jax_cpu_us_per_lane"] for r in rows], 0.4, label="JAX walk (XLA, CPU)")
    ax.bar(x + 0.2, [r["glsl_cpu_us_per_lane"] for r in rows], 0.4, label="GLSL walk (lavapipe, same CPU)")
    ax.set_xticks(x, [r["scene"] + ("\n(GLSL start point: all faces)" if r["general_mesh"] else "\n(grid DDA)")
                      for r in rows], fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("CPU time per lane (us, all threads)\nstart point + walk + D + E")
    ax.set_title(f"Solver pipeline per receiver, float32, {result['lanes']} lanes per scene\n"
                 f"({result['cpu_count']} CPU cores, shared machine; median of {result['rounds']} rounds)", fontsize=10)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    FIG.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIG, dpi=130)
    plt.close(fig)


# %%
if __name__ == "__main__":
    main()
