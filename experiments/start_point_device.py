# %% [markdown]
# # Start points on an accelerator: the same code, the same answers, how fast
#
# Questions: does `start_points` (and `segment_blocked`) run unchanged on the default
# backend (a GPU when there is one), with the same per-lane results as on the CPU? How
# many start points per second does it reach there on the 1M-triangle pool (grid cells),
# a jittered pool (binned cells) and with the BVH?
#
# Lanes: planted crossings exactly on cell walls, edges and vertices (issue 14 class 5;
# also for `segment_blocked`: through them blocked, ending on them not), and floor
# receivers under the scenes' point light. Compared lane by lane: `found` (must be
# identical), face, and the point (within the rounding of the coordinates).
#
# Run: `python -m experiments.start_point_device` (writes
# `figures/start_point_device.json`, prints a table). On a CPU-only machine both sides are
# the CPU.

# %%
from __future__ import annotations

import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from caustics_jax.accel.bvh import build_bvh  # noqa: E402
from caustics_jax.accel.occlusion import segment_blocked  # noqa: E402
from caustics_jax.accel.prepared import prepare  # noqa: E402
from caustics_jax.accel.start_points import start_points  # noqa: E402
from caustics_jax.math.barycentric import barycentric_point  # noqa: E402
from caustics_jax.surface.scenes import wavy_pool  # noqa: E402
from caustics_jax.testing.meshes import jittered_grid  # noqa: E402
from experiments.common import ROOT, write_json  # noqa: E402

OUT = ROOT / "figures" / "start_point_device.json"
QUICK = bool(os.environ.get("CAUSTICS_JAX_QUICK"))  # a smoke run: 16k triangles, few lanes
N_PLANTED = 2_000 if QUICK else 20_000
LANES = (8_192,) if QUICK else (100_000, 1_000_000)


def planted_on_walls(mesh, n, seed=0):
    """Segments through points exactly on grid vertices, cell walls and diagonals."""
    g = mesh.grid
    V = np.asarray(mesh.vertices, np.float64)
    rng = np.random.default_rng(seed)
    i, j = rng.integers(2, g.nx - 2, n), rng.integers(2, g.ny - 2, n)
    kind, t = rng.integers(0, 4, n), rng.uniform(0, 1, (n, 1))
    v = lambda i, j: V[j * (g.nx + 1) + i]  # noqa: E731
    v00, v10, v01, v11 = v(i, j), v(i + 1, j), v(i, j + 1), v(i + 1, j + 1)
    M = np.select([kind[:, None] == k for k in range(4)],
                  [v00, v00 + t * (v01 - v00), v00 + t * (v10 - v00), v00 + t * (v11 - v00)])  # fmt: skip
    w = np.concatenate([rng.uniform(-1, 1, (n, 2)), rng.uniform(1.5, 3, (n, 1))], -1)
    w[rng.random(n) < 0.3, :2] = 0
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    return M - rng.uniform(0.2, 1.5, (n, 1)) * w, M + rng.uniform(0.5, 3, (n, 1)) * w, M


def floor_lanes(n, seed=1):
    rng = np.random.default_rng(seed)
    P = np.concatenate([rng.uniform(-2, 2, (n, 2)), np.full((n, 1), -1.0)], -1)
    return P, np.broadcast_to([0.4, -0.3, 3.0], P.shape)


def on(device, x):
    return jax.device_put(x, device)


def compare(mesh, P, L, accel, dev, cpu) -> dict:
    """Start points on `dev` and on the CPU, lane by lane."""
    out = {}
    for name, d in (("dev", dev), ("cpu", cpu)):
        with jax.default_device(d):
            m = jax.device_put(mesh, d)
            sp = start_points(m, on(d, P), on(d, L), accel=jax.device_put(accel, d))
            out[name] = jax.device_get(sp), np.asarray(barycentric_point(m.triangle(sp.face)[0], sp.barycentric))
    (a, Ma), (b, Mb) = out["dev"], out["cpu"]
    found = np.asarray(b.found)
    return dict(lanes=len(P), found=float(found.mean()), found_equal=bool(np.array_equal(a.found, b.found)),
                face_equal=float(np.mean(np.asarray(a.face) == np.asarray(b.face))),
                max_point_diff_m=float(np.max(np.abs(Ma - Mb)[found & np.asarray(a.found)], initial=0)))  # fmt: skip


def throughput(mesh, accel, n, repeats=3) -> dict:
    P, L = floor_lanes(n)
    P, L = jax.numpy.asarray(P, mesh.dtype), jax.numpy.asarray(L, mesh.dtype)
    t = time.perf_counter()
    jax.block_until_ready(start_points(mesh, P, L, accel=accel))
    first = time.perf_counter() - t
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(start_points(mesh, P, L, accel=accel))
        times.append(time.perf_counter() - t)
    return dict(lanes=n, per_s=n / float(np.median(times)), compile_s=max(first - float(np.median(times)), 0.0))


# %%
if __name__ == "__main__":
    dev, cpu = jax.devices()[0], jax.devices("cpu")[0]
    print(f"default device {dev} ({dev.platform}), jax {jax.__version__}", flush=True)
    rows = []
    n_tri = 16_000 if QUICK else 1_000_000
    for dtype in ("float32", "float64"):
        pool = wavy_pool(n_tri, seed=0, dtype=dtype).surface
        jittered = jittered_grid(n_tri // 4, 0.2, seed=0, dtype=dtype)
        prep_pool, prep_jit = prepare(pool), prepare(jittered)
        P, L, M = (x.astype(dtype) for x in planted_on_walls(pool, N_PLANTED))
        for mesh_name, mesh, accel in (("pool", pool, prep_pool.accel), ("pool", pool, build_bvh(pool)),
                                       ("jittered", jittered, prep_jit.accel)):  # fmt: skip
            kind = getattr(accel, "kind", "bvh")
            lanes = (P, L) if mesh_name == "pool" else tuple(np.asarray(x, dtype) for x in floor_lanes(N_PLANTED))
            agree = compare(mesh, *lanes, accel, dev, cpu)
            speed = [throughput(mesh, accel, n) for n in (LANES[:1] if kind == "bvh" else LANES)]
            row = dict(dtype=dtype, mesh=mesh_name, triangles=int(mesh.faces.shape[0]), accel=kind,
                       agreement=agree, throughput=speed)  # fmt: skip
            rows.append(row)
            print(f"{dtype} {mesh_name:9s} F={row['triangles']:,d} {kind:5s} agree {agree}  "
                  + "  ".join(f"{s['lanes']:,d} lanes {s['per_s']:,.0f}/s (compile {s['compile_s']:.1f}s)"
                              for s in speed), flush=True)  # fmt: skip
        # Occlusion on the device: segments through the planted points (on walls, edges and
        # vertices) are blocked, the halves ending on them are not.
        blocked = np.asarray(segment_blocked(prep_pool, P, L))
        halves = np.asarray(segment_blocked(prep_pool, P, M)) | np.asarray(segment_blocked(prep_pool, M, L))
        with jax.default_device(cpu):
            blocked_cpu = np.asarray(segment_blocked(jax.device_put(pool, cpu), on(cpu, P), on(cpu, L),
                                                     accel=jax.device_put(prep_pool.accel, cpu)))  # fmt: skip
        occ = dict(dtype=dtype, blocked=float(blocked.mean()), equal_to_cpu=bool(np.array_equal(blocked, blocked_cpu)),
                   halves_blocked=float(halves.mean()))  # fmt: skip
        rows.append(dict(occlusion=occ))
        print(f"{dtype} occlusion {occ}", flush=True)
    write_json(OUT, dict(device=str(dev), platform=dev.platform, jax=jax.__version__, rows=rows))
    print(f"wrote {OUT}")
