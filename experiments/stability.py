# %% [markdown]
# # Stress suite: every kernel and solver on adversarial configurations
#
# Issue 7, part 1. Each category of `caustics_jax.testing.stress` (grazing light, near total
# internal reflection, sliver triangles, constant normals, vertices and edges, `P` next
# to the surface, far light, scales 1e-3 and 1e4, a large mesh) plants refracted paths on
# a surface; every kernel is evaluated at the planted point and every solver is run
# from the segment `P -> L`, in float32 and float64. Counted per category and dtype:
#
# - **non-finite**: lanes with a NaN/Inf in any output (goal 0);
# - **silent failures**: lanes reported FOUND whose `|residual| > tol`, or whose
#   refraction-angle error (float64 re-evaluation, `testing.oracle.refraction_angle_error`, on
#   the data the solver saw: the float32 mesh and paths cast exactly to float64) exceeds
#   `10 tol` (`f` is the sine of that angle, so `tol` bounds it; goal 0);
# - found fraction, status counts, angle-error distribution, and per kernel its error
#   against a reference (planted truth, an independent float64 formula, or the float64
#   kernel).
#
# Run: `python -m experiments.stability` (writes `figures/stability.json`,
# `figures/stability.png`; about 2 minutes on 2 cores) or `--quick` (about 1.5 minutes: fewer
# lanes, no `large` category).

# %%
from __future__ import annotations

import argparse
import inspect
import json
import pathlib
import time

import jax
import jax.numpy as jnp
import numpy as np

import caustics_jax as cj
from caustics_jax.app.compare import CONFIGS
from caustics_jax.math.conic import conic_value
from caustics_jax.runtime.progress import progress
from caustics_jax.solvers import Status, default_tol
from caustics_jax.testing import oracle, stress
from experiments.common import ROOT, log, parse_args, stats, use_agg, write_json

# The stress suite runs the exhaustive reference on its small categories only (the `large`
# category's 250k triangles are left to the solvers: docs/stability.md).
MAX_REFERENCE_FACES = 20_000

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

DTYPES = ("float32", "float64")
KERNELS = ("refract", "fresnel", "conic_coefficients", "conic_tangent", "edge_intersections",
           "signed_sine", "ray_differential_D")
# The Newton configuration compare.py ranks best on the default pool (docs/solvers.md).
SOLVERS = {"walk": ("walk", {}), "newton": CONFIGS["newton-hv"], "exhaustive": ("exhaustive", {})}
SILENT_ANGLE_FACTOR = 10.0
# The general solver path, not a scene-feature specialisation (issue 7 part 2, where present).
GENERAL = {"features": None} if "features" in inspect.signature(cj.solve).parameters else {}


def _number(x) -> float:
    """A statistic as a float: NaN where there was none (NaN in memory, null in the JSON)."""
    return float("nan") if x is None else float(x)


def _sci(x) -> str:
    return f"{_number(x):.1e}" if np.isfinite(_number(x)) else "-"


def _nonfinite(*arrays):
    """Lanes (axis 0) with a NaN/Inf in any of `arrays`."""
    bad = np.zeros(len(arrays[0]), bool)
    for a in arrays:
        a = np.asarray(a)
        bad |= ~np.all(np.isfinite(a.reshape(len(a), -1)), -1)
    return bad


# %% kernels
def _path_frame(V, N, P, L, ab):
    """`M`, `n_s`, `n~`, `w_P` in float64 numpy (math.md §1), for the kernels' direct inputs."""
    M, n_t = oracle.barycentric_point(V, ab), oracle.interpolated_normal(N, ab)
    return M, oracle.unit(n_t), n_t, oracle.unit(P - M)


@jax.jit
def _all_kernels(V, N, P, L, ab, I, Ns, cos_i, eta):
    coef = cj.conic_coefficients(V, N, P, L)
    t, valid = cj.edge_intersections(coef)
    f_plane, status = cj.signed_sine_and_status(V, N, P, L, ab, eta, orientation="plane")
    D, D_ok = cj.ray_differential_D(V, N, P, L, ab, eta)
    return {
        "refract": cj.refract(I, Ns, eta),
        "fresnel": cj.fresnel_transmittance(cos_i, 1 / eta),
        "conic_coefficients": coef,
        "conic_tangent": cj.conic_tangent(coef, ab),
        "edge_intersections": (t, valid),
        "signed_sine": (f_plane, cj.signed_sine(V, N, P, L, ab, eta), status),
        "ray_differential_D": (D, D_ok),
    }


def run_kernels(case: stress.StressCase) -> dict:
    """Every kernel at the planted points, per dtype: non-finite lanes and an error."""
    V, N = case.triangles()
    M, n_s, n_t, w_P = _path_frame(V, N, case.P, case.L, case.ab)
    I, Ns, cos_i = -w_P, -n_s, np.abs(np.sum(w_P * n_s, -1))
    PL, PM = case.L - case.P, M - case.P
    truth_scale = np.linalg.norm(n_t, axis=-1) * np.linalg.norm(PL, axis=-1) * np.linalg.norm(PM, axis=-1)
    out = {}
    with cj.precision("float64"):
        D_ref = np.asarray(cj.autodiff_D(*(jnp.asarray(x) for x in (V, N, case.P, case.L, case.ab)), case.eta))
        r_ref = oracle.refract(I, Ns, case.eta)
        k64 = None
        for dtype in DTYPES:
            args = [jnp.asarray(x, dtype) for x in (V, N, case.P, case.L, case.ab, I, Ns, cos_i)]
            k = jax.tree.map(np.asarray, _all_kernels(*args, jnp.asarray(case.eta, dtype)))
            if dtype == "float64":
                k64 = k
            out[dtype] = k
        rows = {}
        for dtype in DTYPES:
            k = out[dtype]
            row = {}
            for name in KERNELS:
                row[name] = {"nonfinite": int(_nonfinite(*jax.tree.leaves(k[name])).sum())}
            f64 = lambda x: np.asarray(x, np.float64)  # noqa: E731
            row["refract"]["error"] = stats(np.max(np.abs(f64(k["refract"]) - r_ref), -1))
            row["refract"]["reference"] = "independent float64 numpy refract"
            coef = f64(k["conic_coefficients"])
            # conic at the planted point: n~ . (PL x PM) = 0 on a refracted path (eq. 9-12)
            res = np.abs(np.asarray(conic_value(jnp.asarray(coef), jnp.asarray(case.ab)))) / truth_scale
            row["conic_coefficients"]["error"] = stats(res)
            row["conic_coefficients"]["reference"] = "conic value at planted M / (|n~||PL||PM|), truth 0"
            t, valid = f64(k["edge_intersections"][0]), k["edge_intersections"][1]
            edge_ab = np.asarray(cj.edge_barycentric(jnp.broadcast_to(jnp.arange(3)[:, None], t.shape),
                                                     jnp.asarray(t)))
            c64 = np.asarray(k64["conic_coefficients"])  # exact conic of the float64 data
            val = np.asarray(conic_value(jnp.asarray(c64)[:, None, None], jnp.asarray(edge_ab)))
            scale = np.max(np.abs(c64), -1)[:, None, None]
            row["edge_intersections"]["error"] = stats((np.abs(val) / np.where(scale > 0, scale, 1))[valid])
            row["edge_intersections"]["reference"] = "float64 conic at the returned roots / max|coef|, truth 0"
            f_plane, _, st = k["signed_sine"]
            ok = st == cj.ObjectiveStatus.OK
            row["signed_sine"]["error"] = stats(np.abs(f64(f_plane))[ok])
            row["signed_sine"]["reference"] = "|f| at planted M, truth 0"
            row["signed_sine"]["not_ok"] = int((~ok).sum())
            D, D_ok = f64(k["ray_differential_D"][0]), k["ray_differential_D"][1]
            rel = np.abs(D - D_ref) / np.abs(D_ref)
            row["ray_differential_D"]["error"] = stats(rel[D_ok])
            row["ray_differential_D"]["reference"] = "autodiff_D, float64"
            row["ray_differential_D"]["valid"] = int(D_ok.sum())
            if dtype == "float32":
                row["fresnel"]["error"] = stats(np.abs(f64(k["fresnel"]) - k64["fresnel"]))
                tan64 = k64["conic_tangent"]
                # relative to the coefficients' scale: the tangent itself vanishes at a
                # singular point (normal incidence at a vertex, P, L and n~ aligned)
                row["conic_tangent"]["error"] = stats(
                    np.linalg.norm(f64(k["conic_tangent"]) - tan64, axis=-1)
                    / np.maximum(np.max(np.abs(k64["conic_coefficients"]), -1), 1e-300))
            else:
                row["fresnel"]["error"] = row["conic_tangent"]["error"] = stats([])
            row["fresnel"]["reference"] = "float64 kernel"
            row["conic_tangent"]["reference"] = "float64 kernel, / max|coef|"
            rows[dtype] = row
    return rows


# %% solvers
def run_solvers(case: stress.StressCase, n_exhaustive: int) -> dict:
    rows = {}
    for dtype in DTYPES:
        with cj.precision(dtype):
            mesh = case.mesh(dtype)
            # The problem the solver saw, exactly in float64: judge it on that.
            seen = oracle.NumpyMesh.from_mesh(mesh)
            P = np.asarray(case.P, dtype)
            L = np.asarray(case.L, dtype)
            row = {}
            for name, (method, opts) in SOLVERS.items():
                lanes, tol = slice(None), default_tol(dtype)
                if method == "exhaustive":
                    if dtype != "float64" or case.n_faces > MAX_REFERENCE_FACES or n_exhaustive == 0:
                        continue
                    lanes = slice(0, n_exhaustive)
                    tol = 1e-9  # the exhaustive reference's acceptance (docs/solvers.md)
                t0 = time.perf_counter()
                sol = jax.block_until_ready(cj.solve(mesh, P[lanes], L[lanes], method=method, **opts,
                                                          **(GENERAL if method != "exhaustive" else {})))
                seconds = time.perf_counter() - t0
                found = np.asarray(sol.found)
                tri, ab = np.asarray(sol.triangle), np.asarray(sol.barycentric, np.float64)
                angle = np.full(len(found), np.nan)
                P64, L64 = np.asarray(P[lanes], np.float64), np.asarray(L[lanes], np.float64)
                angle[found] = oracle.refraction_angle_error(seen, tri[found], ab[found], P64[found], L64[found],
                                                             case.eta)
                residual = np.asarray(sol.residual, np.float64)
                silent = found & ((np.abs(residual) > tol) | (angle > SILENT_ANGLE_FACTOR * tol))
                # beyond what refract's own rounding near the critical angle explains
                bound = np.zeros(len(found))
                bound[found] = oracle.refraction_rounding_bound(seen, tri[found], ab[found], P64[found],
                                                                case.eta, dtype)
                beyond = silent & ((np.abs(residual) > tol) | (angle > SILENT_ANGLE_FACTOR * (tol + bound)))
                bad = _nonfinite(sol.point, sol.barycentric, sol.residual, sol.start_point)
                row[name] = {
                    "n": int(len(found)), "found": int(found.sum()), "silent": int(silent.sum()),
                    "silent_beyond_rounding_bound": int(beyond.sum()),
                    "silent_angle_rad": angle[silent].tolist()[:20],
                    "silent_rounding_bound_rad": bound[silent].tolist()[:20],
                    "silent_lanes": np.nonzero(silent)[0].tolist()[:20],
                    "nonfinite": int(bad.sum()), "status": sol.summary(), "tol": tol,
                    "angle_error_rad": stats(angle[found]),
                    "crossed_mean": float(np.mean(np.asarray(sol.crossed)[found])) if found.any() else None,
                    "seconds": seconds,
                }
            rows[dtype] = row
    return rows


# %% several solutions per receiver (category `multi_solution`)
def multi_solution_recall(case: stress.StressCase, n_lanes: int) -> dict:
    """Recall of the reference's solutions for each method on the first `n_lanes` paths:
    the fraction of all solutions found, and of receivers with at least one. The certified
    exhaustive reference (float64) defines the solutions; found points match within 1e-6 m
    (1e-4 m in float32)."""
    from caustics_jax.transport import sms_biased

    out = {}
    with cj.precision("float64"):
        mesh = case.mesh("float64")
        P, L = case.P[:n_lanes], case.L[:n_lanes]
        ref = cj.solve(mesh, P, L, method="exhaustive", return_all=True)
    ref_sets = [ref.all_points[i, : ref.count[i]] for i in range(n_lanes)]

    def score(sets, tol):
        hit = sum(sum(bool(len(m)) and np.min(np.linalg.norm(m - q, axis=-1)) < tol for q in r)
                  for r, m in zip(ref_sets, sets, strict=True))
        any_ = np.mean([len(r) == 0 or any(bool(len(m)) and np.min(np.linalg.norm(m - q, axis=-1)) < tol
                                           for q in r) for r, m in zip(ref_sets, sets, strict=True)])
        return {"solutions": int(ref.count.sum()), "found": int(hit), "recall": hit / max(int(ref.count.sum()), 1),
                "receivers_with_one": float(any_)}

    for dtype in DTYPES:
        tol = 1e-6 if dtype == "float64" else 1e-4
        with cj.precision(dtype):
            mesh = case.mesh(dtype)
            Pd, Ld = np.asarray(P, dtype), np.asarray(L, dtype)
            for name, method, opts in (("walk", "walk", {}), ("newton", *CONFIGS["newton-hv"]),
                                       ("walk all paths", "walk", {"solutions": "all"})):
                t0 = time.perf_counter()
                sol = cj.solve(mesh, Pd, Ld, method=method, **opts)
                seconds = time.perf_counter() - t0
                if isinstance(sol, cj.ExhaustiveSolution):
                    sets = [np.asarray(sol.all_points[i, : sol.count[i]], np.float64) for i in range(n_lanes)]
                else:
                    pts, found = np.asarray(sol.point, np.float64), np.asarray(sol.found)
                    sets = [pts[i:i + 1] if found[i] else np.zeros((0, 3)) for i in range(n_lanes)]
                out[f"{name}/{dtype}"] = {**score(sets, tol), "seconds": seconds}
    with cj.precision("float64"):
        for k in (4, 16):
            est = sms_biased(case.mesh("float64"), P, L, k=k, seed=0,
                             intensity=1.0, receiver_normal=[0.0, 0.0, 1.0])
            out[f"SMS biased k={k}/float64"] = {"solutions": int(ref.count.sum()), "found": int(est.paths.sum()),
                                                "recall": float(est.paths.sum() / max(ref.count.sum(), 1))}
    out["reference_paths_per_receiver"] = np.bincount(ref.count).tolist()
    return out


def multi_table(rec: dict) -> str:
    lines = ["| method | dtype | solutions found / reference | recall | receivers with >= 1 found |",
             "|---|---|---|---|---|"]
    for key, v in rec.items():
        if "/" not in key:
            continue
        name, dtype = key.rsplit("/", 1)
        one = "" if "receivers_with_one" not in v else f"{v['receivers_with_one']:.3f}"
        lines.append(f"| {name} | {dtype} | {v['found']} / {v['solutions']} | {v['recall']:.3f} | {one} |")
    return "\n".join(lines)


def run(n: int = 256, n_exhaustive: int = 64, categories=stress.CATEGORIES, seed: int = 0) -> dict:
    cj.enable_x64()  # float64 available; every float32 array is built explicitly
    result = {"n": n, "n_exhaustive": n_exhaustive, "seed": seed, "categories": {}}
    for c in progress(categories, desc="stress suite", unit="category"):
        t0 = time.perf_counter()
        case = stress.stress_case(c, n, seed)
        kern = run_kernels(case)
        solv = run_solvers(case, n_exhaustive)
        result["categories"][c] = {"n_faces": case.n_faces, "kernels": kern, "solvers": solv}
        if c == "multi_solution":
            result["categories"][c]["recall"] = multi_solution_recall(case, n_exhaustive)
        log(f"{c}: {time.perf_counter() - t0:.1f} s")
    return result


# %% report
def totals(result) -> dict:
    """Non-finite and silent counts over every category, per dtype and component."""
    out = {}
    for r in result["categories"].values():
        for dtype in DTYPES:
            for name, k in r["kernels"][dtype].items():
                key = (dtype, name)
                out.setdefault(key, {"nonfinite": 0, "silent": 0})["nonfinite"] += k["nonfinite"]
            for name, s in r["solvers"][dtype].items():
                key = (dtype, name)
                out.setdefault(key, {"nonfinite": 0, "silent": 0, "silent_beyond_rounding_bound": 0})
                out[key]["nonfinite"] += s["nonfinite"]
                out[key]["silent"] += s["silent"]
                out[key]["silent_beyond_rounding_bound"] += s["silent_beyond_rounding_bound"]
    return {f"{d}/{n}": v for (d, n), v in out.items()}


def _short(status: dict) -> str:
    abbrev = {s.name: a for s, a in zip(Status, ("F", "NC", "TIR", "LM", "MS", "UE", "DG", "LC", "NCV", "NS"),
                                        strict=True)}
    return " ".join(f"{abbrev[k]}{v}" for k, v in status.items() if k != "FOUND") or "-"


def table(result) -> str:
    lines = []
    head = ("| category | dtype | kernel NaN/Inf | max \\|f\\| at planted M | walk found | walk silent | walk NaN "
            "| walk other statuses | walk angle err max | newton found | newton silent | newton NaN "
            "| newton other statuses | newton angle err max | exhaustive found / silent / NaN |")
    lines.append(head)
    lines.append("|" + "---|" * (head.replace("\\|", "").count("|") - 1))
    for c, r in result["categories"].items():
        for dtype in DTYPES:
            k, s = r["kernels"][dtype], r["solvers"][dtype]
            knan = sum(v["nonfinite"] for v in k.values())
            cells = [c, dtype, str(knan), _sci(k["signed_sine"]["error"]["max"])]
            for name in ("walk", "newton"):
                v = s[name]
                silent = str(v["silent"]) + (f" ({v['silent_beyond_rounding_bound']} beyond)" if v["silent"] else "")
                cells += [f"{v['found']}/{v['n']}", silent, str(v["nonfinite"]), _short(v["status"]),
                          _sci(v["angle_error_rad"]["max"])]
            if "exhaustive" in s:
                v = s["exhaustive"]
                cells.append(f"{v['found']}/{v['n']} / {v['silent']} / {v['nonfinite']}")
            else:
                cells.append("-")
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def kernel_table(result) -> str:
    lines = ["| category | dtype | " + " | ".join(KERNELS) + " |", "|" + "---|" * (len(KERNELS) + 2)]
    for c, r in result["categories"].items():
        for dtype in DTYPES:
            k = r["kernels"][dtype]
            cells = []
            for name in KERNELS:
                cells.append(_sci(k[name]["error"]["max"]) + (f" ({k[name]['nonfinite']} NaN)"
                                                               if k[name]["nonfinite"] else ""))
            lines.append(f"| {c} | {dtype} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(result, path):
    cats = list(result["categories"])
    y = np.arange(len(cats))
    fig, axes = plt.subplots(1, 2, figsize=(13, 0.42 * len(cats) + 3.4), sharey=True)
    styles = {("walk", "float32"): ("C0", "o"), ("walk", "float64"): ("C0", "s"),
              ("newton", "float32"): ("C1", "o"), ("newton", "float64"): ("C1", "s"),
              ("exhaustive", "float64"): ("C2", "D")}
    for j, ((name, dtype), (color, marker)) in enumerate(styles.items()):
        off = (j - 2) * 0.13
        frac, amax, a99 = [], [], []
        for c in cats:
            s = result["categories"][c]["solvers"][dtype].get(name)
            frac.append(np.nan if s is None else s["found"] / s["n"])
            e = None if s is None else s["angle_error_rad"]
            amax.append(np.nan if not e else max(_number(e["max"]), 1e-17))
            a99.append(np.nan if not e else max(_number(e["p99"]), 1e-17))
        face = color if dtype == "float64" else "white"
        axes[0].scatter(frac, y + off, color=color, marker=marker, facecolor=face, label=f"{name} {dtype}")
        axes[1].scatter(amax, y + off, color=color, marker=marker, facecolor=face, label=f"{name} {dtype} (max)")
        axes[1].scatter(a99, y + off, color=color, marker="|", s=60)
    crossing = [1 - result["categories"][c]["solvers"]["float64"]["walk"]["status"].get("NO_CROSSING", 0)
                / result["categories"][c]["solvers"]["float64"]["walk"]["n"] for c in cats]
    axes[0].scatter(crossing, y, marker="|", s=400, color="gray", label="lanes with a start point M0")
    for dtype, ls in (("float32", "--"), ("float64", ":")):
        axes[1].axvline(default_tol(dtype), color="gray", ls=ls, lw=1, label=f"tol {dtype}")
    axes[0].set_yticks(y, cats)
    axes[0].invert_yaxis()
    axes[0].set_xlabel("lanes FOUND (fraction of planted paths)")
    axes[0].set_title("Success on planted paths, per stress category")
    axes[0].legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=3)
    axes[1].set_xscale("log")
    axes[1].set_xlabel("refraction angle error of FOUND lanes (rad, float64 re-evaluation)\nmarker: max, bar: p99")
    axes[1].set_title("Accuracy of what the solvers report as found")
    axes[1].legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=3)
    nan = sum(v["nonfinite"] for v in totals(result).values())
    silent = sum(v["silent"] for v in totals(result).values())
    beyond = sum(v.get("silent_beyond_rounding_bound", 0) for v in totals(result).values())
    fig.suptitle(f"Stress suite: walk, optimistix Newton (half-vector) and exhaustive, float32 (open) / "
                 f"float64 (filled), {result['n']} paths per category\nNaN/Inf lanes {nan}, silent failures {silent} "
                 f"({beyond} beyond refract's own rounding near the critical angle)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# %%
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="64 paths, 16 exhaustive lanes, no `large`")
    ap.add_argument("--out", default=str(ROOT / "figures"))
    ap.add_argument("--replot", action="store_true", help="redraw the figure from stability.json")
    ap.add_argument("--multi-only", action="store_true",
                    help="only the recall of each method on `multi_solution` (stability_multi.json)")
    args = parse_args(ap, argv)
    t0 = time.perf_counter()
    if args.multi_only:
        cj.enable_x64()
        rec = multi_solution_recall(stress.stress_case("multi_solution", 64, 0), 64)
        rec["seconds"] = time.perf_counter() - t0
        write_json(pathlib.Path(args.out) / "stability_multi.json", rec)
        print(multi_table(rec))
        print(f"{rec['seconds']:.0f} s")
        return
    if args.replot:  # figure only, from the JSON of an earlier run
        result = json.loads((pathlib.Path(args.out) / "stability.json").read_text())
        plot(result, pathlib.Path(args.out) / "stability.png")
        return
    if args.quick:
        result = run(64, 16, tuple(c for c in stress.CATEGORIES if c != "large"))
    else:
        result = run(256, 64)
    result["totals"] = totals(result)
    result["seconds"] = time.perf_counter() - t0
    out = pathlib.Path(args.out)
    write_json(out / "stability.json", result)
    plot(result, out / "stability.png")
    print(table(result))
    print()
    print(kernel_table(result))
    print()
    print("totals:", json.dumps(result["totals"]))
    if "recall" in result["categories"].get("multi_solution", {}):
        print()
        print(multi_table(result["categories"]["multi_solution"]["recall"]))
    print(f"{result['seconds']:.0f} s")


if __name__ == "__main__":
    main()
