# %% [markdown]
# # XLA options of the solver programs: compile time and speed
#
# Question: which XLA options should the project's programs compile with? A first `solve`
# spends most of its time in XLA:CPU's backend (LLVM code generation of the fused
# kernels), and XLA has options that trade compile time against run time.
#
# In one process, for each dtype and solver, the solver's block program is compiled once
# with XLA's defaults and once with the project's options (`compilation.XLA_OPTIONS`,
# `compilation.using_xla_options`); then the calls of both are timed interleaved (the
# machine's load drifts alike for both). The start points are found once and passed to
# `solve` (`start=`), so a first call is the solver program's trace, compile and one run;
# "compile" is XLA's backend compile of that call (JAX's
# `/jax/core/compile/backend_compile_duration` events), which does not depend on which
# option set is traced first (the second reuses traces of nested functions).
# Statuses must agree lane for lane, points within float rounding: reported.
#
# The walk's slot pool alone ("scheduler" rows): `pools.run_pools` on the walk's real lane
# states and its real step counts (from the walk's own solve, crossings then refinement
# steps), with steps that only count, so that only the scheduler's data movement (refill
# gathers, write-back scatters, queues) is timed, under both option sets.
#
# Persistent compilation cache off (compile times, not cache loads). Run:
# `python -m experiments.compile_options` (`--quick`: 8192 receivers, 2 repeats).
# Writes `figures/compile_options.png` and `.json` and prints the table; docs/solvers.md
# "Compilation" quotes a run.

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
from caustics_jax.runtime.compilation import XLA_OPTIONS, using_xla_options  # noqa: E402
from caustics_jax.runtime.lane_solver import pool_widths, stage_lane  # noqa: E402
from caustics_jax.runtime.pools import run_pools  # noqa: E402
from caustics_jax.solvers.walk import WalkLane, WalkSolver  # noqa: E402
from caustics_jax.solvers.walk_steps import BISECT, DONE, WALK  # noqa: E402
from experiments.common import figures_dir, log, run_and_write, use_agg  # noqa: E402

CONFIGS = {"walk": Walk(), "newton-hv-step": Newton(stepping="one_step"), "newton-hv": Newton()}
#: The option sets compared: XLA's defaults, and the project's.
OPTION_SETS = {"xla-default": {}, "project": dict(XLA_OPTIONS)}


def parser():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--scene", default="wavy")
    p.add_argument("--n", type=int, default=65536, help="receivers")
    p.add_argument("--repeats", type=int, default=5, help="timed calls per configuration (interleaved)")
    p.add_argument("--dtypes", nargs="+", default=["float32", "float64"])
    p.add_argument("--configs", nargs="+", default=list(CONFIGS))
    p.add_argument("--quick", action="store_true", help="8192 receivers, 2 repeats")
    p.add_argument("--out", default=str(figures_dir() / "compile_options"), help="figure and JSON path (no suffix)")
    return p


# %%
def agreement(a, b) -> dict:
    """Lanes whose status differs, and the largest point distance (m) over lanes found by both."""
    sa, sb = np.asarray(a.status), np.asarray(b.status)
    both = np.asarray(a.found) & np.asarray(b.found)
    d = np.linalg.norm(np.asarray(a.point, np.float64) - np.asarray(b.point, np.float64), axis=-1)
    far = float(d[both].max()) if both.any() else 0.0
    return {"status_differs": int((sa != sb).sum()), "max_point_distance_m": far}


def scheduler_alone(prep, P, L, sol, repeats: int) -> dict:
    """Seconds per block of the walk's slot pool with counting steps, per option set (module
    docstring). Each lane needs `crossed` WALK steps then the rest of its `iterations` as
    BISECT steps, as the walk's solve `sol` took them; the counts ride in the state's
    `crossed` and `side` fields, and the two passes with the turn-back between them are
    the walk's (`walk.WalkSolver`: its records, restart and pool widths)."""
    mesh, dtype = prep.padded, prep.dtype
    solver = Walk()
    eta, tol = jnp.asarray(1.333, dtype), jnp.asarray(solver.tolerance(dtype), dtype)
    P, L = jnp.asarray(P), jnp.asarray(L)
    face, ab0, found = prep.start_points(P, L)
    walk = WalkSolver(mesh, eta, tol, jnp.int32(solver.max_steps), solver)
    records = jax.jit(jax.vmap(lambda lane: stage_lane(walk, lane)))(WalkLane(P, L, face, ab0, found))
    steps = np.asarray(sol.iterations)
    need_w = jnp.asarray(np.minimum(np.asarray(sol.crossed), steps), jnp.int32)
    need_b = jnp.asarray(steps, jnp.int32) - need_w

    def program(records, need_w, need_b):
        s = records.lane.state
        mode = jnp.where(need_w > 0, WALK, jnp.where(need_b > 0, BISECT, DONE)).astype(jnp.int32)
        records = records._replace(lane=records.lane._replace(state=s._replace(
            mode=mode, steps=jnp.zeros_like(s.steps), crossed=need_w, side=need_b)))

        def count(lane):
            s = lane.state
            k = s.steps + 1
            mode = jnp.where(k < s.crossed, WALK, jnp.where(k < s.crossed + s.side, BISECT, DONE))
            return lane._replace(state=s._replace(steps=k, mode=mode.astype(jnp.int32)))

        def route(lane):
            return jnp.where(lane.state.mode != DONE, lane.state.mode, -1).astype(jnp.int32)

        def walk_pass(_, records):  # as `lane_solver.run_lanes`: the turn-back between two passes
            records = jax.vmap(walk.restart)(records)
            moved = run_pools((count,) * 3, route, jax.vmap(walk.moving)(records), pool_widths(walk))
            return jax.vmap(walk.settle)(records, moved)

        return jax.lax.fori_loop(0, 2, walk_pass, records)

    args = (records, need_w, need_b)
    compiled = {}
    for key, options in OPTION_SETS.items():
        compiled[key] = jax.jit(program, compiler_options=options or None).lower(*args).compile()
    times = {k: [] for k in OPTION_SETS}
    for _ in range(max(repeats, 3)):
        for key, c in compiled.items():
            jax.block_until_ready(c(*args))
            t = time.perf_counter()
            jax.block_until_ready(c(*args))
            times[key].append(time.perf_counter() - t)
    return {key: float(np.median(v)) for key, v in times.items()}


_EVENT = "/jax/core/compile/backend_compile_duration"
_backend = [0.0]


def _listen(name, seconds, **_):
    if name == _EVENT:
        _backend[0] += seconds


def run(args) -> dict:
    jax.monitoring.register_event_duration_secs_listener(_listen)
    n = 8192 if args.quick else args.n
    repeats = 2 if args.quick else args.repeats
    cfg = compare.CompareConfig(scene=args.scene, n=n)
    sc64, _, P, L = compare.scene_arrays(cfg)
    rows = []
    for dtype in args.dtypes:
        prep = prepare(sc64.surface.astype(dtype))
        Pd, Ld = np.asarray(P, dtype), np.asarray(L, dtype)
        start = jax.block_until_ready(prep.start_points(jax.device_put(Pd), jax.device_put(Ld)))
        for name in args.configs:
            solver = CONFIGS[name]
            first, backend, sols, times = {}, {}, {}, {k: [] for k in OPTION_SETS}
            for key, options in OPTION_SETS.items():
                with using_xla_options(options):
                    t, _backend[0] = time.perf_counter(), 0.0
                    sols[key] = jax.block_until_ready(solve(prep, Pd, Ld, method=solver, start=start))
                    first[key], backend[key] = time.perf_counter() - t, _backend[0]
            for _ in range(repeats):  # interleaved
                for key, options in OPTION_SETS.items():
                    with using_xla_options(options):
                        t = time.perf_counter()
                        jax.block_until_ready(solve(prep, Pd, Ld, method=solver, start=start))
                        times[key].append(time.perf_counter() - t)
            agree = agreement(sols["xla-default"], sols["project"])
            if name == "walk":
                sched = scheduler_alone(prep, Pd, Ld, sols["xla-default"], repeats)
                for key in OPTION_SETS:
                    rows.append({"dtype": dtype, "config": "walk scheduler alone", "options": key, "n": n,
                                 "seconds": sched[key], "solves_per_s": n / sched[key]})
                log(f"[{dtype}] walk's slot pool alone (counting steps): " + ", ".join(
                    f"{k} {v * 1e3:.1f} ms" for k, v in sched.items()))
            for key in OPTION_SETS:
                wall = float(np.median(times[key]))
                rows.append({"dtype": dtype, "config": name, "options": key, "n": n, "first_s": first[key],
                             "compile_s": backend[key], "seconds": wall, "solves_per_s": n / wall,
                             "found": float(np.asarray(sols[key].found).mean()), **agree})
                r = rows[-1]
                log(f"[{dtype}] {name:<16}{key:<12} compile {r['compile_s']:5.1f} s  {r['solves_per_s']:>9.0f} solves/s"
                    f"  status differs {agree['status_differs']}  max point distance "
                    f"{agree['max_point_distance_m']:.1e} m")
    return {"rows": rows, "n": n, "repeats": repeats, "scene": args.scene, "options": OPTION_SETS,
            "platform": jax.default_backend(), "devices": [str(d) for d in jax.local_devices()]}


# %%
def plot(report, path):
    use_agg()
    import matplotlib.pyplot as plt

    rows = [r for r in report["rows"] if "compile_s" in r]  # the scheduler rows are in the table only
    labels = sorted({(r["dtype"], r["config"]) for r in rows})
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    x = np.arange(len(labels))
    for i, key in enumerate(OPTION_SETS):
        sel = {(r["dtype"], r["config"]): r for r in rows if r["options"] == key}
        for ax, field, scale in ((axes[0], "compile_s", 1.0), (axes[1], "solves_per_s", 1e-3)):
            ax.bar(x + (i - 0.5) * 0.38, [sel[k][field] * scale for k in labels], 0.38, label=key)
    names = [f"{c}\n{d}" for d, c in labels]
    for ax, title, unit in ((axes[0], "XLA compile of the solver program", "seconds"),
                            (axes[1], "throughput after compiling", "thousand solves per second")):
        ax.set_xticks(x, names, fontsize=7, rotation=20)
        ax.set_ylabel(unit)
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7)
    project = ", ".join(f"{k}={v}" for k, v in XLA_OPTIONS.items())
    fig.suptitle(f"XLA's default options against the project's ({project}),"
                 f"\n{report['n']} receivers of '{report['scene']}', {report['platform']}, "
                 f"{len(report['devices'])} device(s)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def table(report) -> str:
    head = (f"{'dtype':<9}{'config':<17}{'options':<13}{'compile':>9}{'first':>8}{'solves/s':>11}{'found':>8}"
            f"{'status differs':>16}")
    lines = [head, "-" * len(head)]
    for r in report["rows"]:
        if "compile_s" not in r:
            continue
        lines.append(f"{r['dtype']:<9}{r['config']:<17}{r['options']:<13}{r['compile_s']:>8.1f}s{r['first_s']:>7.1f}s"
                     f"{r['solves_per_s']:>11.0f}{r['found']:>8.4f}{r['status_differs']:>16d}")
    for r in report["rows"]:
        if "compile_s" not in r:
            lines.append(f"{r['dtype']:<9}{r['config']} ({r['options']}): {r['seconds'] * 1e3:.1f} ms per "
                         f"{r['n']} lanes")
    return "\n".join(lines)


# %%
if __name__ == "__main__":
    run_and_write(parser(), run, plot, table)
