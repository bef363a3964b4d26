# %% [markdown]
# # float32 audit of the conic kernels
#
# Every kernel of issue 2 evaluated in float32 and float64 on the same inputs (planted
# paths and random configurations from `caustics_jax.testing`). The float64 result is the
# reference; the table gives max and p99 of the float32 error, from which the tests'
# float32 tolerances are set. Run: `python -m experiments.float32_audit`.
#
# Writes `figures/float32_audit.{png,json}` and the same JSON as package data,
# `caustics_jax/export/float32_audit.json`: the shader reference data's tolerances are never
# tighter than these maxima (docs/export.md "Tolerances"), so rerunning this changes them.

# %%
from __future__ import annotations

import json
import pathlib

import jax
import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import caustics_jax as cj  # noqa: E402
from caustics_jax.math.conic import edge_intersection_points  # noqa: E402
from caustics_jax.testing import oracle, planted_paths  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: Package data read by `caustics_jax.export.load_audit` (an installed wheel carries it).
PACKAGE_AUDIT = ROOT / "caustics_jax" / "export" / "float32_audit.json"
N_PATHS = 200_000


def run(n_paths: int = N_PATHS) -> dict:
    with cj.precision("float64"):
        p = planted_paths(2026, n_paths)
        args64 = [jnp.asarray(x, jnp.float64) for x in (p.V, p.N, p.P, p.L, p.ab)]
        args32 = [jnp.asarray(x, jnp.float32) for x in (p.V, p.N, p.P, p.L, p.ab)]
        errors: dict[str, np.ndarray] = {}

        # refract: unit incident directions -w_P at the planted points
        def refract_at(V, N, P, L, ab):
            return cj.objectives.refracted_direction(V, N, P, L, ab, p.eta)

        r64 = np.asarray(jax.jit(refract_at)(*args64))
        r32 = np.asarray(jax.jit(refract_at)(*args32), np.float64)
        errors["refract (abs, unit vector)"] = np.max(np.abs(r32 - r64), -1)

        rng = np.random.default_rng(1)
        cos_i = rng.uniform(0, 1, n_paths)
        F64 = np.asarray(cj.fresnel_reflectance(jnp.asarray(cos_i), 1 / 1.333))
        F32 = np.asarray(cj.fresnel_reflectance(jnp.asarray(cos_i, jnp.float32), jnp.float32(1 / 1.333)))
        errors["Fresnel R air->water (abs)"] = np.abs(F32 - F64)

        coef_fn = jax.jit(cj.conic_coefficients)
        c64 = np.asarray(coef_fn(*args64[:4]))
        c32 = np.asarray(coef_fn(*args32[:4]), np.float64)
        scale = np.max(np.abs(c64), -1)
        errors["conic coefficients (max abs / max |coef|)"] = np.max(np.abs(c32 - c64), -1) / scale

        V, N, P, L = (np.asarray(x, np.float64) for x in args32[:4])
        t32, v32 = (np.asarray(x) for x in jax.jit(cj.edge_intersections)(jnp.asarray(c32, jnp.float32)))
        ab = np.asarray(edge_intersection_points(jnp.asarray(t32, jnp.float64)))
        lanes = np.nonzero(v32)
        # |n~ . (PL x PM)| / (|n~| |PL| |PM|) in float64 (seed 001 eq. 9): the conic's own
        # relative residual, by the oracle
        errors["edge roots: triple-product residual (rel)"] = oracle.triple_product(
            V[lanes[0]], N[lanes[0]], P[lanes[0]], L[lanes[0]], ab[lanes], relative=True)

        # M0 = line PL' meets the plane: put L' on the line P' -> M through the planted M.
        P_line = p.M - 0.5 * (p.L - p.M)
        c_line = np.asarray(coef_fn(*[jnp.asarray(x, jnp.float32) for x in (p.V, p.N, P_line, p.L)]))
        val = np.asarray(cj.conic_value(jnp.asarray(c_line, jnp.float64), jnp.asarray(p.ab)))
        n = oracle.interpolated_normal(p.N, p.ab)
        errors["conic value at M0 (rel, as triple product)"] = np.abs(val) / (
            np.linalg.norm(n, axis=-1) * np.linalg.norm(p.L - P_line, axis=-1)
            * np.linalg.norm(p.M - P_line, axis=-1))

        obj = jax.jit(lambda V, N, P, L, ab: (
            cj.signed_sine(V, N, P, L, ab, p.eta),
            cj.half_vector_residual(V, N, P, L, ab, p.eta),
            cj.angle_difference_residual(V, N, P, L, ab, p.eta)))
        f32, h32, a32 = (np.asarray(x, np.float64) for x in obj(*args32))
        f64, h64, a64 = (np.asarray(x) for x in obj(*args64))
        errors["signed sine at planted M (abs)"] = np.abs(f32)
        errors["half-vector residual at planted M (abs)"] = np.max(np.abs(h32), -1)
        errors["angle-difference residual at planted M (abs)"] = np.max(np.abs(a32), -1)
        float64_max = {
            "signed sine at planted M (abs)": float(np.max(np.abs(f64))),
            "half-vector residual at planted M (abs)": float(np.max(np.abs(h64))),
            "angle-difference residual at planted M (abs)": float(np.max(np.abs(a64))),
        }
    table = {
        k: {"max": float(np.max(v)), "p99": float(np.percentile(v, 99)),
            "median": float(np.median(v)), "n": int(v.size)}
        for k, v in errors.items()
    }
    return {"n_paths": n_paths, "float32": table, "float64_max": float64_max, "_errors": errors}


def plot(result: dict, path: pathlib.Path) -> None:
    errors = result["_errors"]
    fig, ax = plt.subplots(figsize=(9, 5))
    names = list(errors)
    data = [np.log10(np.maximum(errors[k], 1e-12)) for k in names]
    ax.boxplot(data, orientation="horizontal", whis=(1, 99), showfliers=False)
    ax.scatter([np.max(d) for d in data], range(1, len(names) + 1), marker="x", color="C3",
               label="max", zorder=3)
    ax.set_yticks(range(1, len(names) + 1), names, fontsize=8)
    ax.set_xlabel("log10 float32 error against float64 (dimensionless, floored at 1e-12; whiskers p1-p99)")
    ax.set_title(f"float32 error of the conic kernels, {result['n_paths']:,} planted paths")
    ax.axvline(np.log10(np.finfo(np.float32).eps), color="gray", ls="--", label="float32 eps")
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# %%
if __name__ == "__main__":
    result = run()
    (ROOT / "figures").mkdir(exist_ok=True)
    plot(result, ROOT / "figures" / "float32_audit.png")
    out = {k: v for k, v in result.items() if not k.startswith("_")}
    text = json.dumps(out, indent=2)
    for path in (ROOT / "figures" / "float32_audit.json", PACKAGE_AUDIT):
        path.write_text(text)
    print(f"{'kernel':50s} {'max':>10s} {'p99':>10s} {'median':>10s}")
    for k, v in out["float32"].items():
        print(f"{k:50s} {v['max']:10.2e} {v['p99']:10.2e} {v['median']:10.2e}")
    print("float64 max at planted M:", out["float64_max"])
