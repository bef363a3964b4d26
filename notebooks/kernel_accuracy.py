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
# # Kernel accuracy: float32 against float64, and the seeds' approximations against exact
#
# Two questions:
#
# 1. **float32 against float64, for every exported kernel** (`caustics_jax.export.KERNELS`,
#    the formulas a shader port must reproduce): on the export's own cases (random,
#    planted, adversarial; docs/export.md), how far is the package's float32 evaluation
#    from the float64 reference computed from the same float32-rounded inputs, in units of
#    the tolerance written into the manifest? Every bar below 1 passes.
# 2. **The seeds' approximations against exact formulas** (docs/kernels.md, math.md §8;
#    `experiments/kernel_approximations.py` is the full study): seed 004's Schlick-like
#    Fresnel (eq. 14) against exact Fresnel, seed 002's projected photon position
#    (eq. 3.3) against the exact ray-plane intersection, and seed 004's same-t'
#    compression ratio (Alg. 2) against the exact receiver triangle.
#
# `CAUSTICS_JAX_QUICK=1` (what CI runs) uses 256 records per kernel and coarser grids.

# %%
import os

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import caustics_jax as cj
from caustics_jax import export, kernels, scenes, transport
from caustics_jax.transport.photon_differentials import light_view_texels

cj.enable_x64()  # float64 available; every array below states its dtype
QUICK = os.environ.get("CAUSTICS_JAX_QUICK", "") not in ("", "0")
COUNT = 256 if QUICK else 4096
plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": 100, "font.size": 9})
print(f"quick={QUICK}: {COUNT} records per kernel; kernels: {', '.join(export.KERNELS)}")

# %% [markdown]
# ## 1. float32 against float64 for every exported kernel
#
# `export.export_kernel` builds a kernel's records exactly as `caustics-jax export` writes
# them (inputs rounded to float32, float64 reference from those inputs, tolerances from
# the float32 audit); `export.read_records` reads the bytes back with nothing but the
# manifest; the float32 evaluation is the package kernel run on the stored inputs, what
# a faithful port computes; `export.compare` is the conformance check of a GLSL port.

# %%
rows = []
errors = {}
for name, kernel in export.KERNELS.items():
    manifest, raw = export.export_kernel(kernel, COUNT, seed=0)
    records = export.read_records(manifest, raw)
    with cj.precision("float32"):
        args = {f.name: jnp.asarray(records[f.name], jnp.float32) if f.dtype == "float32"
                else jnp.asarray(records[f.name]) for f in kernel.inputs()}
        got = {k: np.asarray(v) for k, v in jax.jit(kernel.evaluate)(args).items()}
    report = export.compare(manifest, records, got)
    for field, r in report["fields"].items():
        rows.append(dict(kernel=name, field=field, **r))
        tol = manifest["tolerance"][field]
        if "abs" in tol:
            ref = records[field].reshape(manifest["count"], -1).astype(np.float64)
            err = np.abs(got[field].reshape(manifest["count"], -1).astype(np.float64) - ref)
            bound = tol["abs"] + tol["rel"] * export.field_scale(records, ref, tol)[:, None]
            errors[f"{name}.{field}"] = (err / np.where(bound > 0, bound, np.inf)).max(1)

print(f"{'kernel.field':<36}{'max abs':>10}{'max rel':>10}{'max ULP':>12}{'err/tol':>9}{'pass':>7}")
for r in rows:
    key = f"{r['kernel']}.{r['field']}"
    if "max_abs" in r:
        print(f"{key:<36}{r['max_abs']:>10.1e}{r['max_rel']:>10.1e}{r['max_ulp']:>12d}"
              f"{r['max_err_over_tol']:>9.3f}{r['pass_rate']:>7.3f}")
    else:
        print(f"{key:<36}{'integer field: ' + str(r['mismatches']) + ' mismatches':>41}{r['pass_rate']:>7.3f}")

# %% [markdown]
# Relative and ULP errors grow without bound where the reference is near zero (the signed
# sine at a root, a Gaussian weight that underflows); the manifest's tolerance,
# `abs + rel * scale` with `scale` the field's largest magnitude in the record, does not,
# and `err/tol` is what a port is judged by. Integer fields must match exactly: a
# mismatch above is a record where float32 rounding flips a discrete outcome (a
# fixed-point code rounding to its other neighbour, a validity flag at its threshold).

# %%
keys = list(errors)
fig, ax = plt.subplots(figsize=(9, 0.3 * len(keys) + 1.4))
y = np.arange(len(keys))
q = np.array([np.percentile(errors[k], [50, 99, 100]) for k in keys])
q = np.maximum(q, 1e-6)  # an exact float32 result (error 0) is drawn at 1e-6
ax.hlines(y, q[:, 0], q[:, 2], color="0.6")
ax.plot(q[:, 0], y, "o", color="C0", label="median")
ax.plot(q[:, 1], y, "|", color="C1", ms=12, mew=2, label="99th percentile")
ax.plot(q[:, 2], y, "x", color="C3", label="maximum")
ax.set_yticks(y, keys, fontsize=7)
ax.axvline(1, color="C3", ls="--", lw=0.8, label="tolerance (manifest)")
ax.set(xscale="log", xlabel="|float32 - float64 reference| / tolerance, per record (0 drawn at 1e-6)",
       title=f"float32 against float64 on the export's cases ({COUNT} + adversarial records per kernel)")
ax.legend(loc="lower left", fontsize=7)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 2a. Schlick-like Fresnel (seed 004 eq. 14) against exact Fresnel, air to water
#
# `F_frac = ((eta - 1)/(eta + 1))^2`, `F_exp = 5`; exact: the unpolarised dielectric
# Fresnel reflectance of `caustics_jax.fresnel_reflectance` (math.md §6).

# %%
ETA = 1.333
theta_deg = np.linspace(0, 89.9, 2000 if QUICK else 20000)
theta = np.radians(theta_deg)
normal = np.tile([0.0, 0.0, 1.0], (theta.size, 1))
l_dir = np.stack([np.sin(theta), np.zeros_like(theta), -np.cos(theta)], -1)
exact_F = np.asarray(cj.fresnel_reflectance(jnp.asarray(np.cos(theta)), 1 / ETA))
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 3.6))
ax0.plot(theta_deg, exact_F, "k", label="exact Fresnel (float64)")
for dtype, style in ((jnp.float64, "C1--"), (jnp.float32, "C0:")):
    F = np.asarray(kernels.fresnel_reflect_approx(jnp.asarray(l_dir, dtype), jnp.asarray(normal, dtype),
                                                  kernels.schlick_f0(ETA)), np.float64)
    if dtype == jnp.float64:
        ax0.plot(theta_deg, F, style, label="eq. 14 (float64)")
    ax1.semilogy(theta_deg[1:], np.abs(F - exact_F)[1:], style, label=f"|eq. 14 - exact|, {jnp.dtype(dtype).name}")
ax0.set(xlabel="incidence angle (degrees)", ylabel="reflectance (unitless)", title="Reflectance, air to water")
ax1.axhline(1e-3, color="grey", lw=0.8, ls="--")
ax1.set(xlabel="incidence angle (degrees)", ylabel="absolute error (unitless)",
        title="Schlick-like Fresnel (seed 004 eq. 14) against exact")
ax0.legend(fontsize=8)
ax1.legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 2b. Projected photon position (seed 002 eq. 3.3) against the exact intersection
#
# Flat water at `z = 0`, the photon entering at the origin, a planar terrain 1 m below
# tilted by `slope` toward azimuth `phi`, light along `(sin theta, 0, -cos theta)`. The
# error is divided by the exact in-water path length and maximised over `phi`.

# %%
k = 2 if QUICK else 1
slopes, light = np.radians(np.arange(0, 45.1, 0.5 * k)), np.radians(np.arange(0, 80.1, 0.5 * k))
S, Lt, Phi = np.meshgrid(slopes, light, np.radians(np.arange(0, 360, 5 * k)), indexing="ij")
n_t = np.stack([np.sin(S) * np.cos(Phi), np.sin(S) * np.sin(Phi), np.cos(S)], -1)
l_vec = np.stack([np.sin(Lt), np.zeros_like(Lt), -np.cos(Lt)], -1)
origin, plane_pt = np.zeros_like(l_vec), np.broadcast_to([0.0, 0.0, -1.0], l_vec.shape)
water_n = np.broadcast_to([0.0, 0.0, 1.0], l_vec.shape)


def projection_error(dtype):
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    T, _, hit_t = kernels.ray_plane_intersection(c(origin), c(l_vec), c(plane_pt), c(n_t))
    D = cj.refract(c(l_vec), c(water_n), 1 / ETA)
    exact, _, hit_x = kernels.ray_plane_intersection(c(origin), D, c(plane_pt), c(n_t))
    approx = np.asarray(kernels.projected_photon_position(c(origin), T, D), np.float64)
    exact = np.asarray(exact, np.float64)
    rel = np.linalg.norm(approx - exact, axis=-1) / np.maximum(np.linalg.norm(exact, axis=-1), 1e-300)
    return np.nanmax(np.where(np.asarray(hit_t & hit_x), rel, np.nan), axis=-1)


worst64, worst32 = projection_error(jnp.float64), projection_error(jnp.float32)
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10.5, 3.8))
im = ax0.pcolormesh(np.degrees(light), np.degrees(slopes), np.log10(np.maximum(worst64, 1e-16)),
                    shading="auto", cmap="magma", vmin=-4, vmax=0.5)
fig.colorbar(im, ax=ax0, label="log10 relative error")
ax0.set(xlabel="light zenith angle (degrees)", ylabel="terrain slope (degrees)",
        title="Eq. 3.3 error / in-water path, worst over azimuth")
for s_deg, color in ((0, "k"), (10, "C0"), (20, "C1"), (45, "C3")):
    i = int(np.argmin(np.abs(np.degrees(slopes) - s_deg)))
    ax1.semilogy(np.degrees(light)[1:], worst64[i, 1:], color=color, label=f"slope {s_deg}°, float64")
ax1.semilogy(np.degrees(light)[1:], worst32[0, 1:], "y:", lw=2, label="slope 0°, float32")
ax1.set(xlabel="light zenith angle (degrees)", ylabel="relative error (unitless)",
        title="Seed 002 eq. 3.3 against the exact intersection")
ax1.legend(fontsize=7)
fig.tight_layout()
plt.show()
print(f"flat terrain, light 30°: {worst64[0, int(np.argmin(np.abs(np.degrees(light) - 30)))]:.4f}; "
      f"float32 minus float64 where below 1: {np.nanmax(np.abs(worst32 - worst64)[worst64 < 1]):.1e}")

# %% [markdown]
# ## 2c. The same-t' compression ratio (seed 004 Alg. 2) against the exact receiver triangle
#
# Photons on a light-view texel grid over a wavy pool (8192 triangles, amplitude 0.1 m),
# each refracted to the floor 1 m down. For a texel and its right and upper neighbours,
# seed 004 Alg. 2 estimates the area ratio of the receiver triangle to the surface
# triangle by moving every neighbour the *same* distance `t'` along its refracted ray
# (`transport.compression_ratio`, times the foreshortening `a` of eq. 18); the exact
# ratio intersects each neighbour's ray with the floor (`compression_ratio_exact`), and
# is itself checked against the Jacobian of the light-to-floor map (`texel_jacobian`).

# %%
with cj.precision("float64"):
    mesh = scenes.wavy_pool(8192, amplitude=0.1, dtype="float64").surface
    L = jnp.asarray([0.4, -0.3, 3.0])
    rp, rn = jnp.asarray([0.0, 0.0, -1.0]), jnp.asarray([0.0, 0.0, 1.0])
    res = 64 if QUICK else 256
    tx = light_view_texels(mesh, np.asarray(L), res)
    V, Nv = mesh.triangle(tx.face)
    M = cj.barycentric_point(V, tx.ab)
    n_s = cj.safe_normalize(cj.interpolated_normal(Nv, tx.ab))
    l_dir = cj.safe_normalize(M - L)
    J, Y, T, cos_e, r_e, t, ok = cj.texel_jacobian(V, Nv, L, tx.X, ETA, rp, rn)
    h, s = slice(None, -1), slice(1, None)
    c, r, u = (h, h), (h, s), (s, h)  # the texel, its right and its upper neighbour
    a = 1 / -cj.refract(l_dir[c], n_s[c], 1 / ETA)[..., 2]  # seed 004 eq. 18, receiver normal +z
    sig, _ = cj.compression_ratio(M[c], M[r], M[u], n_s[c], n_s[r], n_s[u], l_dir[c], t[c], eta=ETA,
                                  l_dir10=l_dir[r], l_dir01=l_dir[u])
    exact, ok_x = cj.compression_ratio_exact(M[c], M[r], M[u], n_s[c], n_s[r], n_s[u], l_dir[c], rp, rn,
                                             eta=ETA, l_dir10=l_dir[r], l_dir01=l_dir[u])
    area = np.asarray(transport.triangle_area(M[c], M[r], M[u]))
    jac = np.abs(np.linalg.det(np.asarray(J[c]))) * tx.du * tx.dv / 2 / np.where(area > 0, area, 1)
    found = np.asarray(tx.found)
    good = found[c] & found[r] & found[u] & np.asarray(ok[c] & ok_x)
    ex = np.asarray(exact)[good]
    rel_same_t = np.abs((np.asarray(sig) ** 2 * np.asarray(a))[good] / ex - 1)
    rel_jac = np.abs(ex / jac[good] - 1)

fig, ax = plt.subplots(figsize=(7, 3.4))
bins = np.logspace(-12, 1, 60)
ax.hist(rel_same_t, bins=bins, alpha=0.7, label="same-t' (Alg. 2) x a vs exact triangle")
ax.hist(rel_jac, bins=bins, alpha=0.7, label="exact triangle vs Jacobian (finite texel)")
ax.set(xscale="log", xlabel="relative error (unitless)", ylabel="texels",
       title=f"Compression ratio on a wavy pool, {res}² light-view texels")
ax.legend(fontsize=8)
fig.tight_layout()
plt.show()
print(f"same-t' vs exact: median {np.median(rel_same_t):.3f}, p99 {np.percentile(rel_same_t, 99):.3f}; "
      f"exact vs Jacobian: median {np.median(rel_jac):.1e} ({good.sum()} texels)")
