# %% [markdown]
# # Throughput and the machine's limit
#
# Question: how fast are the walk and its Newton baselines, per lane, and how far is each
# from what the machine can do? In one process, calls interleaved (the machine's load
# drifts; ratios within one run are what counts), on the comparison's receivers
# (`compare.scene_arrays`, the `make demo` layout) over three 8192-triangle scenes:
# the default pool (`wavy`), a steep pool (`wavy_steep`) and a jittered irregular mesh
# (`wavy_jittered`), float32 and float64:
#
# - the walk with the slot-pool scheduler (`walk`, default) and with the previous chunked
#   scheduler (`walk-chunked`: every lane computes the first triangle's 64 ellipse
#   samples, chunks of 256 lanes each run until their slowest lane);
# - each Newton variant: optimistix converging in every triangle (`newton-hv`, pool and
#   `-chunked`), one projected step per iteration as MNEE/SMS do (`newton-hv-step`), and
#   that from Cycles' gentle first step 0.1 (`newton-hv-step-gentle`);
# - success against the exhaustive float64 reference (`compare.reference`) on `ref_n` lanes;
# - FLOPs per solve from XLA's cost analysis (`jax.jit(f).lower(...).compile().cost_analysis()`)
#   of each lane program the solver runs (the first triangle with and without the ellipse
#   samples, one step; XLA counts a loop body once, so the per-lane programs are lowered
#   alone and multiplied by the counts that ran): **useful** FLOPs are what each lane
#   needs (its first triangle, its own steps), **executed** FLOPs what the schedule makes
#   the machine do (every lane's ellipse samples under the chunked scheduler, each chunk
#   until its slowest lane, the pool's idle slots while it drains: the pool's loop trips
#   are replayed on the host from the lanes' step counts, exactly as `pools.run_pools`
#   refills its slots);
#   each counted twice: XLA's **compiled** programs (after its fusion copies shared values
#   into every consuming kernel) and the **traced** ones (the lowered program, before
#   XLA's passes);
# - the **formula** count: the arithmetic the mathematics needs, each formula's own
#   function counted alone on one lane and summed over the steps the lanes took
#   (`formula_flops`: a crossing, a refinement step, the first triangle, a Newton step and
#   each face of its re-projection; docs/solvers.md "Formula count");
# - the machine's practical peak: a jitted element-wise fused multiply-add loop in the
#   same process, per dtype.
#
# Newton "converge" runs optimistix's own loop inside each patch, which XLA's cost analysis
# counts once: its FLOPs are not reported (its throughput is).
#
# Run: `python -m experiments.throughput` (`--quick` for a smoke run). Writes
# `figures/throughput.png` and `.json` and prints the table; docs/solvers.md
# "Throughput and the machine's limit" quotes a run.

# %%
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("CAUSTICS_JAX_COMPILATION_CACHE", "0")  # measure compile times, not cache loads

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # float32 arrays stay float32 (built explicitly)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from caustics_jax import Newton, Walk, prepare, solve  # noqa: E402
from caustics_jax.app import compare  # noqa: E402
from caustics_jax.curve.arcs import (  # noqa: E402
    boundary_crossings,
    orientation,
    pencil_angle,
    pencil_point,
    project_to_conic,
    sign_test_exit,
)
from caustics_jax.math.barycentric import ray_plane_barycentric  # noqa: E402
from caustics_jax.math.conic import conic_coefficients, conic_tangent  # noqa: E402
from caustics_jax.math.geometry import newton_step_2x2  # noqa: E402
from caustics_jax.math.objectives import bracket_objective, half_vector_residual_and_jacobian  # noqa: E402
from caustics_jax.runtime.blocks import lanes_per_block  # noqa: E402
from caustics_jax.runtime.lane_solver import pool_widths, stage_lane  # noqa: E402
from caustics_jax.runtime.pools import pool_slots  # noqa: E402
from caustics_jax.solvers.newton import NewtonSolver, newton_init, newton_iteration  # noqa: E402
from caustics_jax.solvers.walk import WalkLane, WalkSolver  # noqa: E402
from caustics_jax.solvers.walk_steps import BISECT, WALK  # noqa: E402
from caustics_jax.surface.mesh import cross_edge  # noqa: E402
from experiments.common import figures_dir, log, run_and_write, use_agg  # noqa: E402

CONFIGS = {
    "walk": Walk(),
    "walk-chunked": Walk(scheduler="chunked"),
    "newton-hv": Newton(),
    "newton-hv-chunked": Newton(scheduler="chunked"),
    "newton-hv-step": Newton(stepping="one_step"),
    "newton-hv-step-gentle": Newton(stepping="one_step", initial_step=0.1),
}
SCENES = ("wavy", "wavy_steep", "wavy_jittered")
WIDTH = 256  # lanes per cost-analysis program (the CPU pool's width)


def parser():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--n", type=int, default=65536, help="receivers per scene")
    p.add_argument("--ref-n", type=int, default=1024, help="lanes checked against the exhaustive reference")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per configuration (interleaved)")
    p.add_argument("--scenes", nargs="+", default=list(SCENES))
    p.add_argument("--dtypes", nargs="+", default=["float32", "float64"])
    p.add_argument("--configs", nargs="+", default=list(CONFIGS))
    p.add_argument("--quick", action="store_true", help="8192 receivers, 256 reference lanes, 2 repeats")
    p.add_argument("--out", default=str(figures_dir() / "throughput"), help="figure and JSON path (no suffix)")
    return p


# %% [markdown]
# ## The machine's peak: an element-wise fused multiply-add loop

# %%
def peak_flops(dtype, size: int = 1 << 16, iters: int = 2000, repeats: int = 5) -> float:
    """FLOP/s of `x <- a x + b` (2 FLOPs per element) over `size` elements, `iters` times in
    one jitted loop (unrolled by 8); best of `repeats`."""
    a, b = jnp.asarray(0.999, dtype), jnp.asarray(1e-3, dtype)

    @jax.jit
    def loop(x):
        return jax.lax.fori_loop(0, iters, lambda _, x: x * a + b, x, unroll=8)

    x = jnp.ones(size, dtype)
    jax.block_until_ready(loop(x))
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(loop(x))
        best = min(best, time.perf_counter() - t)
    return 2 * size * iters / best


# %% [markdown]
# ## FLOPs of the lane programs (XLA cost analysis)

# %%
def _flops(fn, *args, traced: bool = False) -> float:
    """FLOPs per lane of `vmap(fn)` on a batch of `WIDTH` lanes: of XLA's compiled program
    (with its fusion copies), or `traced` (the lowered program, before XLA's passes)."""
    lowered = jax.jit(jax.vmap(fn)).lower(*args)
    cost = lowered.cost_analysis() if traced else lowered.compile().cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    return float(cost["flops"]) / WIDTH


def _traced_flops(fn, *args) -> float:
    """XLA's count of `fn` as traced (the lowered program, before XLA's optimisation: no
    fusion copies), for one lane (unbatched arguments)."""
    cost = jax.jit(fn).lower(*args).cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    return float(cost["flops"])


def formula_flops(mesh, P, L, face, ab0, eta: float = 1.333) -> dict:
    """The arithmetic the mathematics needs, per lane: each formula's own function counted
    alone on one lane (`_traced_flops`), and summed as seed 001 §3.4 and the one-step
    Newton need them (docs/solvers.md "Formula count"). Compares and selects inside a
    formula count as XLA counts them; nothing of the solvers' bookkeeping is in it.

    A crossing: the edge crossing, the face's conic (eq. 10-12), the exit by the vertex
    signs and one edge quadratic (eq. 22-24), the travel direction from the tangent (eq.
    13-15), the exit's pencil angle, `f` at the exit (eq. 19-21; the entry's `f` is the
    previous exit's). A refinement step: one cut of the arc (the chord cut, a line cut of
    the conic) and `f` there (the face's conic carried). The first triangle: the conic,
    both boundary crossings, one orientation (the other direction is its negation), two
    pencil angles, `f` at `M0` and at both exits. A Newton step: the half-vector residual
    and its closed-form Jacobian, the 2x2 solve, `f` at the new point; each face its
    re-projection visits: an edge crossing and a ray-plane intersection."""
    dtype = mesh.dtype
    eta = jnp.asarray(eta, dtype)
    P, L, face, ab0 = P[0], L[0], face[0], ab0[0]
    V, N = mesh.triangle(face)
    coef = conic_coefficients(V, N, P, L)
    tau, perp = orientation(coef, ab0, conic_tangent(coef, ab0))
    k, t = jnp.int32(0), jnp.asarray(0.5, dtype)
    pieces = {
        "cross_edge": _traced_flops(lambda f, k, t: cross_edge(mesh, f, k, t), face, k, t),
        "conic_coefficients": _traced_flops(conic_coefficients, V, N, P, L),
        "sign_test_exit": _traced_flops(sign_test_exit, coef, k, t),
        "boundary_crossings": _traced_flops(boundary_crossings, coef),
        "orientation": _traced_flops(lambda c, e: orientation(c, e, conic_tangent(c, e)), coef, ab0),
        "pencil_angle": _traced_flops(lambda v, a, b: pencil_angle(v, a, b, jnp.linalg.norm(v), jnp.sum(jnp.abs(v))),
                                      ab0 - 0.1, tau, perp),
        "f": _traced_flops(lambda x: bracket_objective(V, N, P, L, x[None], eta), ab0),
        "chord_cut": _traced_flops(project_to_conic, coef, ab0),
        "pencil_cut": _traced_flops(lambda c, a, t_, p_: pencil_point(c, a, t_, p_, jnp.asarray(0.5, dtype)),
                                    coef, ab0, tau, perp),
        "half_vector_jacobian": _traced_flops(lambda x: half_vector_residual_and_jacobian(V, N, P, L, x, eta), ab0),
        "solve_2x2": _traced_flops(newton_step_2x2, jnp.eye(2, dtype=dtype), jnp.ones(2, dtype)),
        "ray_plane": _traced_flops(ray_plane_barycentric, V, P, L),
    }
    q = pieces
    return {"pieces": pieces,
            "crossing": q["cross_edge"] + q["conic_coefficients"] + q["sign_test_exit"] + q["orientation"]
            + q["pencil_angle"] + q["f"],
            "refinement": q["chord_cut"] + q["f"],
            "first_triangle": q["conic_coefficients"] + q["boundary_crossings"] + q["orientation"]
            + 2 * q["pencil_angle"] + 3 * q["f"],
            "newton_start": q["f"],
            "newton_step": q["half_vector_jacobian"] + q["solve_2x2"] + q["f"],
            "newton_face": q["cross_edge"] + q["ray_plane"],
            "ellipse_sample": q["pencil_cut"] + q["f"]}


def formula_per_solve(solver, counts: dict, sol, ellipse: np.ndarray, n_ellipse: int) -> float:
    """`formula_flops` summed over the steps each lane took (`sol`), per solve: the walk's
    first triangle on every lane with a start point (and the ellipse samples where the curve
    has no edge crossing), its crossings (`crossed`, plus an exit through the boundary) and
    refinement steps; Newton's start, its steps, and one face per step plus one per
    triangle crossed in the re-projections."""
    status = np.asarray(sol.status)
    started = status != 1  # NO_CROSSING = 1
    steps = np.asarray(sol.iterations).astype(np.int64)
    crossed = np.asarray(sol.crossed).astype(np.int64)
    if isinstance(solver, Walk):
        w = np.minimum(crossed + (status == 3), steps)  # LEFT_MESH = 3
        total = (started.sum() * counts["first_triangle"] + ellipse.sum() * (n_ellipse - 1) * counts["ellipse_sample"]
                 + w.sum() * counts["crossing"] + (steps - w).sum() * counts["refinement"])
    else:
        total = (started.sum() * counts["newton_start"] + steps.sum() * counts["newton_step"]
                 + (steps.sum() + crossed.sum()) * counts["newton_face"])
    return float(total) / len(status)


def lane_flops(solver, mesh, P, L, start, eta: float = 1.333, traced: bool = False) -> dict:
    """Per-lane FLOPs of the programs `solver` runs: `init` (first triangle without the
    ellipse samples, or Newton's start), `init_full` (with them), `step` (one iteration);
    XLA's compiled programs, or `traced` (`_flops`)."""
    dtype = mesh.dtype
    eta, tol = jnp.asarray(eta, dtype), jnp.asarray(solver.tolerance(dtype), dtype)
    face, ab0, found = start
    P, L = P[:WIDTH], L[:WIDTH]
    if isinstance(solver, Walk):
        walk = WalkSolver(mesh, eta, tol, jnp.int32(solver.max_steps), solver)
        lean, _, walks, ellipse = walk.stages()
        # Each stage alone, as the runtime stores each stage's record before the next
        # reads it (one program of all of them would count XLA's fusion copies).
        lane = WalkLane(P, L, face, ab0, found)
        first = jax.jit(jax.vmap(lean.fn))(lane)
        records = jax.jit(jax.vmap(walks.fn))(first)
        moving = jax.vmap(walk.moving)(records)
        init = _flops(lean.fn, lane, traced=traced) + _flops(walks.fn, first, traced=traced)
        # with the ellipse samples: what a lane whose curve has no edge crossing adds
        return {"init": init, "init_full": init + _flops(ellipse.fn, records, traced=traced),
                "step": _flops(lambda m: walk.step(m, None), moving, traced=traced),
                "step_walk": _flops(lambda m: walk.step(m, WALK), moving, traced=traced),
                "step_bisect": _flops(lambda m: walk.step(m, BISECT), moving, traced=traced)}
    if solver.stepping == "converge":
        return None  # optimistix's inner loop: XLA counts a loop body once (module docstring)
    beta0 = jnp.asarray(solver.initial_step, dtype)
    init = lambda p, l, f, a, ok: newton_init(mesh, p, l, f, a, ok, eta, tol, beta0)  # noqa: E731
    states = jax.jit(jax.vmap(init))(P, L, face, ab0, found)
    flops_init = _flops(init, P, L, face, ab0, found, traced=traced)
    return {"init": flops_init, "init_full": flops_init,
            "step": _flops(lambda p, l, s: newton_iteration(mesh, p, l, eta, tol, solver, s), P, L, states,
                          traced=traced)}


def pool_trips(phases: np.ndarray, widths: tuple[int, ...]) -> np.ndarray:
    """Loop trips of `pools.run_pools`, replayed: `phases` `(lanes, K)` holds how many steps
    each lane needs in pool 0, then pool 1, ... (in queue order; a lane visits the pools
    in that order). Each trip steps every pool with a busy slot; a lane whose phase ends
    is queued for its next pool; free slots refill from their pool's queue. Returns the
    trips in which each pool stepped (`(K,)`)."""
    lanes, K = phases.shape
    slots = max(widths)
    queues = [list(np.flatnonzero((phases[:, k] > 0) & (phases[:, :k].sum(1) == 0))) for k in range(K)]
    slot_lane = np.full((K, slots), -1)
    for k in range(K):  # pool k has widths[k] slots: the others never take a lane
        slot_lane[k, widths[k]:] = -2
    left = np.zeros((K, slots), np.int64)
    heads = [0] * K
    stepped = np.zeros(K, np.int64)

    def refill(k):
        for i in np.flatnonzero(slot_lane[k] == -1):
            if heads[k] >= len(queues[k]):
                break
            lane = queues[k][heads[k]]
            heads[k] += 1
            slot_lane[k, i], left[k, i] = lane, phases[lane, k]

    for k in range(K):
        refill(k)
    while (slot_lane >= 0).any():
        for k in range(K):
            busy = slot_lane[k] >= 0
            if not busy.any():
                continue
            stepped[k] += 1
            left[k, busy] -= 1
            for i in np.flatnonzero(busy & (left[k] == 0)):
                lane = slot_lane[k, i]
                slot_lane[k, i] = -1
                nxt = [j for j in range(k + 1, K) if phases[lane, j] > 0]
                if nxt:
                    queues[nxt[0]].append(lane)
        for k in range(K):
            refill(k)
    return stepped


def ellipse_lanes(solver, mesh, P, L, start, eta: float = 1.333) -> np.ndarray:
    """Which lanes' curve is an ellipse inside the first triangle (the walk's rare branch)."""
    if not isinstance(solver, Walk):
        return np.zeros(P.shape[0], bool)
    dtype = mesh.dtype
    eta, tol = jnp.asarray(eta, dtype), jnp.asarray(solver.tolerance(dtype), dtype)
    walk = WalkSolver(mesh, eta, tol, jnp.int32(solver.max_steps), solver)
    fn = jax.jit(jax.vmap(lambda lane: stage_lane(walk, lane).is_ellipse))
    return np.asarray(fn(WalkLane(P, L, *start))) & np.asarray(start[2])


def executed_and_useful(solver, flops: dict | None, sol, ellipse: np.ndarray, block: int) -> dict:
    """Total FLOPs executed by the schedule and needed by the lanes (module docstring), for
    lanes solved in blocks of `block` (the last one padded), one device. The walk's steps
    split into crossings (`crossed`, plus a boundary exit) and refinement steps; a lane's
    crossings are replayed before its refinement steps."""
    if flops is None:
        return {"useful": np.nan, "executed": np.nan}
    found0 = np.asarray(sol.status) != 1  # lanes with a start point (NO_CROSSING = 1)
    steps = np.asarray(sol.iterations).astype(np.int64)
    walk = isinstance(solver, Walk)
    if walk:
        w = np.minimum(np.asarray(sol.crossed) + (np.asarray(sol.status) == 3), steps)  # LEFT_MESH = 3
        phases = np.stack([w, steps - w], 1)
        useful_steps = w.sum() * flops["step_walk"] + (steps - w).sum() * flops["step_bisect"]
    else:
        phases = steps[:, None]
        useful_steps = steps.sum() * flops["step"]
    useful = (found0 & ~ellipse).sum() * flops["init"] + ellipse.sum() * flops["init_full"] + useful_steps
    executed = 0.0
    for lo in range(0, len(steps), block):
        part = slice(lo, lo + block)
        k = steps[part].size
        s, f, e = np.zeros(block, np.int64), np.zeros(block, bool), np.zeros(block, bool)
        ph = np.zeros((block, phases.shape[1]), np.int64)
        s[:k], f[:k], e[:k], ph[:k] = steps[part], found0[part], ellipse[part], phases[part]
        if solver.scheduler == "chunked":  # every lane's full first triangle; chunks until their slowest lane
            executed += block * flops["init_full"] + WIDTH * s.reshape(-1, WIDTH).max(1).sum() * flops["step"]
            continue
        widths = pool_widths(WalkSolver if walk else NewtonSolver)
        trips = pool_trips(ph, widths[:ph.shape[1]])
        if walk:  # first triangles and ellipses on the compacted lanes (`pools.map_where`); two pools
            executed += -(-int(f.sum()) // WIDTH) * WIDTH * flops["init"]
            executed += -(-int(e.sum()) // WIDTH) * WIDTH * flops["init_full"]
            executed += widths[0] * trips[0] * flops["step_walk"] + widths[1] * trips[1] * flops["step_bisect"]
        else:
            executed += block * flops["init"] + widths[0] * trips[0] * flops["step"]
    return {"useful": useful, "executed": executed}


# %% [markdown]
# ## Success against the exhaustive reference

# %%
def success(sol, ref, ref_mesh_points_tol: float = 1e-4) -> dict:
    """Of the reference lanes with a solution: the fraction found, and the fraction whose
    point is one of the reference's solutions (within 1e-4 m)."""
    idx, count, pts = ref["idx"], ref["count"], ref["all_points"]
    has = count > 0
    found = np.asarray(sol.found)[idx]
    M = np.asarray(sol.point, np.float64)[idx]
    d = np.linalg.norm(pts - M[:, None], axis=-1)
    d = np.where(np.arange(pts.shape[1])[None] < count[:, None], d, np.inf).min(1)
    return {"success": float((found & has).sum() / max(has.sum(), 1)),
            "matches_reference": float((found & has & (d < ref_mesh_points_tol)).sum() / max(has.sum(), 1)),
            "spurious": int((found & ~has).sum())}


# %% [markdown]
# ## The run

# %%
def run(args) -> dict:
    n = 8192 if args.quick else args.n
    ref_n = 256 if args.quick else args.ref_n
    repeats = 2 if args.quick else args.repeats
    configs = {k: CONFIGS[k] for k in args.configs}
    peaks = {dt: peak_flops(dt) for dt in args.dtypes}
    log("peak element-wise FMA rate: " + ", ".join(f"{dt} {p / 1e9:.2f} GFLOP/s" for dt, p in peaks.items()))
    rows = []
    for scene in args.scenes:
        cfg = compare.CompareConfig(scene=scene, n=n, ref_n=ref_n)
        sc64, _, P, L = compare.scene_arrays(cfg)
        ref = compare.reference(cfg, sc64, P, L)
        for dtype in args.dtypes:
            mesh = sc64.surface.astype(dtype)
            Pd, Ld = np.asarray(P, dtype), np.asarray(L, dtype)
            prep = prepare(mesh)
            start_all = tuple(prep.start_points(jax.device_put(Pd), jax.device_put(Ld)))
            start = tuple(x[:WIDTH] for x in start_all)
            ellipse = None
            first, first_cpu, times, cpu, sols = {}, {}, {k: [] for k in configs}, {k: [] for k in configs}, {}
            for name, solver in configs.items():
                t, c = time.perf_counter(), time.process_time()
                sols[name] = jax.block_until_ready(solve(prep, Pd, Ld, method=solver))
                first[name], first_cpu[name] = time.perf_counter() - t, time.process_time() - c
            for _ in range(repeats):  # interleaved: the load drifts alike for every configuration
                for name, solver in configs.items():
                    t, c = time.perf_counter(), time.process_time()
                    jax.block_until_ready(solve(prep, Pd, Ld, method=solver))
                    times[name].append(time.perf_counter() - t)
                    cpu[name].append(time.process_time() - c)
            counts = formula_flops(prep.padded, jnp.asarray(Pd), jnp.asarray(Ld), *start[:2])
            for name, solver in configs.items():
                sol = sols[name]
                wall = float(np.median(times[name]))
                fl = lane_flops(solver, prep.padded, jnp.asarray(Pd), jnp.asarray(Ld), start)
                fl_traced = lane_flops(solver, prep.padded, jnp.asarray(Pd), jnp.asarray(Ld), start, traced=True)
                if isinstance(solver, Walk) and ellipse is None:
                    ellipse = ellipse_lanes(solver, prep.padded, jnp.asarray(Pd), jnp.asarray(Ld), start_all)
                lane_ellipse = ellipse if isinstance(solver, Walk) else np.zeros(n, bool)
                work = executed_and_useful(solver, fl, sol, lane_ellipse, lanes_per_block())
                traced = executed_and_useful(solver, fl_traced, sol, lane_ellipse, lanes_per_block())["useful"]
                formula = (formula_per_solve(solver, counts, sol, lane_ellipse, getattr(solver, "ellipse_samples", 0))
                           if fl is not None else np.nan)
                it = np.asarray(sol.iterations)[np.asarray(sol.found)]
                row = {"scene": scene, "dtype": dtype, "config": name, "n": n,
                       "solves_per_s": n / wall, "seconds": wall, "cpu_seconds": float(np.median(cpu[name])),
                       "compile_s": max(first[name] - wall, 0.0),
                       "compile_cpu_s": max(first_cpu[name] - float(np.median(cpu[name])), 0.0),
                       "found": float(np.asarray(sol.found).mean()),
                       **success(sol, ref), "status": sol.summary(),
                       "iterations_median": float(np.median(it)) if it.size else None,
                       "iterations_p99": float(np.quantile(it, 0.99)) if it.size else None,
                       "flops_per_lane_program": fl, "traced_flops_per_lane_program": fl_traced,
                       "formula_counts": counts, "formula_flops_per_solve": formula,
                       "traced_flops_per_solve": traced / n,
                       "useful_flops_per_solve": work["useful"] / n, "executed_flops_per_solve": work["executed"] / n,
                       "useful_gflops": work["useful"] / wall / 1e9, "executed_gflops": work["executed"] / wall / 1e9,
                       "peak_gflops": peaks[dtype] / 1e9}
                rows.append(row)
                log(f"[{scene} {dtype}] {name:<22} {row['solves_per_s']:>9.0f} solves/s  success "
                    f"{row['success']:.4f}  useful {_kilo(row['useful_flops_per_solve'], 7)}  executed "
                    f"{_kilo(row['executed_flops_per_solve'], 7)} FLOP/solve (traced "
                    f"{_kilo(row['traced_flops_per_solve'], 1)}, formula {_kilo(formula, 1)})  compile "
                    f"{row['compile_s']:.1f} s")
    return {"rows": rows, "peaks_gflops": {k: v / 1e9 for k, v in peaks.items()}, "n": n, "ref_n": ref_n,
            "repeats": repeats, "platform": jax.default_backend(), "devices": [str(d) for d in jax.local_devices()],
            "pool_slots": pool_slots(), "block_lanes": lanes_per_block(),
            "ratios": ratios(rows)}


def ratios(rows) -> list[dict]:
    """Per scene and dtype: walk over the fastest Newton variant with the walk's success or
    better, walk over the fastest Newton overall, and walk over walk-chunked."""
    out = []
    for scene in {r["scene"] for r in rows}:
        for dtype in {r["dtype"] for r in rows}:
            sel = {r["config"]: r for r in rows if r["scene"] == scene and r["dtype"] == dtype}
            walk = sel.get("walk")
            newton = [r for k, r in sel.items() if k.startswith("newton")]
            if walk is None or not newton:
                continue
            fastest = max(newton, key=lambda r: r["solves_per_s"])
            equal = [r for r in newton if r["success"] >= walk["success"]]
            best_equal = max(equal, key=lambda r: r["solves_per_s"]) if equal else None
            out.append({"scene": scene, "dtype": dtype,
                        "walk_over_fastest_newton": walk["solves_per_s"] / fastest["solves_per_s"],
                        "fastest_newton": fastest["config"],
                        "walk_over_newton_at_equal_success": (walk["solves_per_s"] / best_equal["solves_per_s"]
                                                              if best_equal else None),
                        "newton_at_equal_success": best_equal["config"] if best_equal else None,
                        "walk_over_chunked": (walk["solves_per_s"] / sel["walk-chunked"]["solves_per_s"]
                                              if "walk-chunked" in sel else None)})
    return sorted(out, key=lambda r: (r["scene"], r["dtype"]))


# %% [markdown]
# ## Figure: throughput, and FLOP rates against the peak

# %%
def plot(report, path):
    use_agg()
    import matplotlib.pyplot as plt

    rows = report["rows"]
    scenes_ = list(dict.fromkeys(r["scene"] for r in rows))
    dtypes = list(dict.fromkeys(r["dtype"] for r in rows))
    configs = list(dict.fromkeys(r["config"] for r in rows))
    fig, axes = plt.subplots(2, len(dtypes), figsize=(6.5 * len(dtypes), 8.5), squeeze=False)
    width = 0.8 / len(configs)
    for j, dtype in enumerate(dtypes):
        ax = axes[0, j]
        for i, c in enumerate(configs):
            v = [next((r["solves_per_s"] for r in rows if r["scene"] == s and r["dtype"] == dtype
                       and r["config"] == c), np.nan) for s in scenes_]
            ax.bar(np.arange(len(scenes_)) + i * width, np.asarray(v) / 1e3, width, label=c)
        ax.set_xticks(np.arange(len(scenes_)) + 0.4 - width / 2, scenes_)
        ax.set_ylabel("throughput (1000 solves/s)")
        ax.set_title(f"{dtype}: solves per second, same process, interleaved")
        ax.set_ylim(top=ax.get_ylim()[1] * 1.35)  # room for the legend above the bars
        ax.legend(fontsize=7, ncol=3, loc="upper center")
        ax = axes[1, j]
        sel = [r for r in rows if r["dtype"] == dtype and r["scene"] == scenes_[0]]
        x = np.arange(len(sel))
        ax.bar(x - 0.2, [r["useful_gflops"] for r in sel], 0.4, label="useful FLOP/s (what the lanes need)")
        ax.bar(x + 0.2, [r["executed_gflops"] for r in sel], 0.4, label="executed FLOP/s (what the schedule runs)")
        ax.axhline(report["peaks_gflops"][dtype], color="k", ls="--", label="peak: element-wise FMA loop")
        ax.set_yscale("log")
        for xi, r in zip(x, sel, strict=True):
            if not _counted(r["useful_gflops"]):  # Newton converge: optimistix's loop counts once
                ax.text(xi, ax.get_ylim()[0] * 1.15, "n/c", ha="center", va="bottom", fontsize=8)
        ax.set_xticks(x, [r["config"] for r in sel], rotation=20, fontsize=7)
        ax.set_ylabel("GFLOP/s (log)")
        ax.set_title(f"{dtype}, {scenes_[0]}: achieved FLOP rate against the machine's peak")
        ax.legend(fontsize=7)
    fig.suptitle(f"Walk and Newton throughput, {report['n']} receivers per scene, {report['platform']} "
                 f"({len(report['devices'])} device(s))")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# %%
def _counted(x) -> bool:
    """A FLOP count that was counted: not NaN (in memory) or None (read back from the JSON)."""
    return x is not None and bool(np.isfinite(x))


def _kilo(flops: float, width: int) -> str:
    """`flops` in thousands, right-aligned in `width`; "n/c" where not counted (NaN: Newton
    `converge`, whose optimistix loop XLA's cost analysis counts once, module docstring)."""
    return f"{'n/c':>{width}}" if not _counted(flops) else f"{flops / 1e3:>{width - 1}.1f}k"


def _ratio(a: float, b: float, width: int) -> str:
    return f"{'n/c':>{width}}" if not (_counted(a) and _counted(b)) else f"{a / b:>{width}.2f}"


def _percent(a: float, b: float, width: int) -> str:
    return f"{'n/c':>{width}}" if not _counted(a) else f"{100 * a / b:>{width - 1}.1f}%"


def table(report) -> str:
    head = (f"{'scene':<14}{'dtype':<9}{'config':<23}{'solves/s':>10}{'success':>9}{'formula':>9}{'traced':>9}"
            f"{'useful':>9}{'executed':>10}{'exec/useful':>12}{'% peak':>8}{'compile':>9}")
    lines = [head, "-" * len(head)]
    for r in report["rows"]:
        lines.append(f"{r['scene']:<14}{r['dtype']:<9}{r['config']:<23}{r['solves_per_s']:>10.0f}{r['success']:>9.4f}"
                     f"{_kilo(r['formula_flops_per_solve'], 9)}{_kilo(r['traced_flops_per_solve'], 9)}"
                     f"{_kilo(r['useful_flops_per_solve'], 9)} {_kilo(r['executed_flops_per_solve'], 9)}"
                     f"{_ratio(r['executed_flops_per_solve'], r['useful_flops_per_solve'], 12)}"
                     f"{_percent(r['executed_gflops'], r['peak_gflops'], 8)}{r['compile_s']:>8.1f}s")
    lines.append("")
    for q in report["ratios"]:
        eq, chunked = q["walk_over_newton_at_equal_success"], q["walk_over_chunked"]
        lines.append(f"[{q['scene']} {q['dtype']}] walk / fastest Newton ({q['fastest_newton']}) "
                     f"{q['walk_over_fastest_newton']:.2f}; at equal success ({q['newton_at_equal_success']}) "
                     f"{'n/a' if eq is None else f'{eq:.2f}'}; walk / walk-chunked "
                     f"{'n/a' if chunked is None else f'{chunked:.2f}'}")
    return "\n".join(lines)


# %%
if __name__ == "__main__":
    run_and_write(parser(), run, plot, table)
