# %% [markdown]
# # Approximation errors of the real-time pipeline kernels (math.md §8)
#
# Three questions, one figure or table each:
#
# 1. How far is seed 004's Schlick-like Fresnel (eq. 14-15) from exact Fresnel, by angle?
# 2. How far is seed 002's projected photon position (eq. 3.3) from the exact
#    intersection of the refracted ray with the terrain, by terrain slope and light angle?
# 3. What does seed 000's 4.28 fixed-point accumulation cost in accuracy, against float64
#    sums and against float32 sums taken in random (atomic) orders, and where does it
#    overflow?
#
# Run: `python -m experiments.kernel_approximations` (writes `figures/`).

# %%
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from caustics_jax import fresnel_reflectance, refract
from caustics_jax.kernels import (
    fixed_point_accumulate,
    fixed_point_decode,
    fresnel_reflect_approx,
    projected_photon_position,
    ray_plane_intersection,
    schlick_f0,
)
from caustics_jax.kernels.fixed_point import MAX_VALUE, RESOLUTION
from experiments.common import figures_dir, use_agg, write_json

use_agg()
import matplotlib.pyplot as plt  # noqa: E402

jax.config.update("jax_enable_x64", True)
FIG = figures_dir()
ETA_WATER = 1.333
results: dict = {}

# %% [markdown]
# ## 1. Schlick-like Fresnel (seed 004 eq. 14) against exact Fresnel, air -> water
#
# `F_frac = ((eta - 1)/(eta + 1))^2 = 0.0204`, `F_exp = 5` (Schlick's values; the paper
# leaves both free). Exact: unpolarised dielectric Fresnel from `caustics_jax.math.geometry`.

# %%
theta_deg = np.linspace(0, 90, 90001)
theta = np.radians(theta_deg)
normal = np.tile([0.0, 0.0, 1.0], (theta.size, 1))
l_dir = np.stack([np.sin(theta), np.zeros_like(theta), -np.cos(theta)], -1)
exact_F = np.asarray(fresnel_reflectance(jnp.asarray(np.cos(theta)), 1 / ETA_WATER))
schlick = {}
for dtype in (jnp.float32, jnp.float64):
    schlick[dtype] = np.asarray(
        fresnel_reflect_approx(
            jnp.asarray(l_dir, dtype), jnp.asarray(normal, dtype), schlick_f0(ETA_WATER)
        ),
        np.float64,
    )
err64 = np.abs(schlick[jnp.float64] - exact_F)
err32 = np.abs(schlick[jnp.float32] - exact_F)
results["fresnel_schlick"] = {
    "eta": ETA_WATER,
    "f_frac": schlick_f0(ETA_WATER),
    "f_exp": 5.0,
    "max_abs_error_float64": float(err64.max()),
    "angle_of_max_error_deg": float(theta_deg[err64.argmax()]),
    "max_abs_error_float32": float(err32.max()),
    "max_abs_error_up_to_50deg": float(err64[theta_deg <= 50].max()),
    "max_abs_error_up_to_70deg": float(err64[theta_deg <= 70].max()),
    "first_angle_error_above_1e-3_deg": float(theta_deg[np.argmax(err64 > 1e-3)]),
    "max_rel_error_of_transmittance": float(np.max(err64 / np.maximum(1 - exact_F, 1e-12))[()]),
    "max_rel_error_of_transmittance_up_to_80deg": float(
        np.max((err64 / (1 - exact_F))[theta_deg <= 80])
    ),
}

fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.2))
ax0.plot(theta_deg, exact_F, "k", label="exact Fresnel (float64)")
ax0.plot(theta_deg, schlick[jnp.float64], "C1--", label="eq. 14, Schlick (float64)")
ax0.set_xlabel("incidence angle (degrees)")
ax0.set_ylabel("reflectance F_refl (unitless)")
ax0.set_title("Reflectance, air -> water (eta = 1.333)")
ax0.legend()
ax1.semilogy(theta_deg[1:], err64[1:], "C1", label="|eq. 14 - exact|, float64")
ax1.semilogy(theta_deg[1:], err32[1:], "C0:", label="|eq. 14 - exact|, float32")
ax1.axhline(1e-3, color="grey", lw=0.8, ls="--", label="1e-3")
ax1.set_xlabel("incidence angle (degrees)")
ax1.set_ylabel("absolute error of F_refl = error of F_refr (unitless)")
ax1.set_title("Schlick-like Fresnel (seed 004 eq. 14-15) vs exact")
ax1.legend()
fig.tight_layout()
fig.savefig(FIG / "fresnel_schlick_error.png", dpi=120)
plt.close(fig)

# %% [markdown]
# ## 2. Projected photon position (seed 002 eq. 3.3) against the exact intersection
#
# Flat water at `z = 0` (normal `+z`), photon entering at the origin. The terrain is a
# plane at depth `d` below that point, tilted by `slope` toward azimuth `phi`. The light
# travels along `l = (sin theta, 0, -cos theta)`; `PosTerrain` is where the unrefracted
# light-view ray meets the terrain (the same light-view texel as the water), `D` the
# refracted direction. Exact: the refracted ray intersected with the terrain plane.
# The error is divided by the exact in-water path length `|exact - PosWater|`: the
# geometry scales with depth, and where the refracted ray runs nearly parallel to a
# steep terrain both positions run off to infinity while this ratio stays finite. The
# worst over `phi` is shown; flat-terrain errors are also given per unit depth `d`.

# %%
slopes = np.radians(np.linspace(0, 45, 91))
light = np.radians(np.linspace(0, 80, 161))
phis = np.radians(np.linspace(0, 360, 72, endpoint=False))
S, Lt, P = np.meshgrid(slopes, light, phis, indexing="ij")
n_t = np.stack([np.sin(S) * np.cos(P), np.sin(S) * np.sin(P), np.cos(S)], -1)
l_vec = np.stack([np.sin(Lt), np.zeros_like(Lt), -np.cos(Lt)], -1)
origin = np.zeros_like(l_vec)
plane_pt = np.broadcast_to([0.0, 0.0, -1.0], l_vec.shape)  # depth d = 1
water_n = np.broadcast_to([0.0, 0.0, 1.0], l_vec.shape)


def projection_error(dtype):
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    T, _, hit_t = ray_plane_intersection(c(origin), c(l_vec), c(plane_pt), c(n_t))
    D = refract(c(l_vec), c(water_n), 1 / ETA_WATER)
    exact, _, hit_x = ray_plane_intersection(c(origin), D, c(plane_pt), c(n_t))
    approx = projected_photon_position(c(origin), T, D)
    exact64, approx64 = np.asarray(exact, np.float64), np.asarray(approx, np.float64)
    err = np.linalg.norm(approx64 - exact64, axis=-1)
    path = np.linalg.norm(exact64 - origin, axis=-1)
    ok = np.asarray(hit_t & hit_x)
    return np.where(ok, err, np.nan), np.where(ok, err / np.where(path > 0, path, 1), np.nan)


err_p64, rel_p64 = projection_error(jnp.float64)
err_p32, rel_p32 = projection_error(jnp.float32)
worst = np.nanmax(rel_p64, axis=-1)  # over azimuth
slope_deg, light_deg = np.degrees(slopes), np.degrees(light)


def at(a, grid):
    return int(np.argmin(np.abs(grid - a)))


def region_max(max_slope, max_light):
    return float(np.nanmax(worst[slope_deg <= max_slope][:, light_deg <= max_light]))


results["projected_photon"] = {
    "setup": "flat water, depth d = 1 below the entry point, planar terrain, eta 1.333",
    "metric": "|eq. 3.3 - exact| / exact in-water path length, worst over terrain azimuth",
    "flat_terrain_error_per_depth_at_light_deg": {
        str(a): float(np.nanmax(err_p64[0, at(a, light_deg)])) for a in (0, 10, 20, 30, 45, 60, 80)
    },
    "flat_terrain_relative_error_at_light_deg": {
        str(a): float(worst[0, at(a, light_deg)]) for a in (0, 10, 20, 30, 45, 60, 80)
    },
    "relative_error_max_slope_le_10_light_le_30": region_max(10, 30),
    "relative_error_max_slope_le_20_light_le_45": region_max(20, 45),
    "relative_error_max_slope_le_45_light_le_60": region_max(45, 60),
    "relative_error_max_whole_map": float(np.nanmax(worst)),
    "relative_error_at_normal_incidence_any_slope": float(np.nanmax(worst[:, 0])),
    # float32 evaluation against float64, where the approximation error itself is < 1
    "max_float32_minus_float64_relative_error_where_below_1": float(
        np.nanmax(np.where(rel_p64 < 1, np.abs(rel_p32 - rel_p64), np.nan))
    ),
    "grazing_note": "the whole-map maximum comes from light nearly parallel to steep terrain, "
    "where PosTerrain runs off to infinity",
    "slope_range_deg": [0, 45],
    "light_zenith_range_deg": [0, 80],
}

fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 4.6))
im = ax0.pcolormesh(
    light_deg,
    slope_deg,
    np.log10(np.maximum(worst, 1e-16)),
    shading="auto",
    cmap="magma",
    vmin=-4,
    vmax=0.5,
)
cs = ax0.contour(
    light_deg, slope_deg, worst, levels=[0.01, 0.05, 0.1, 0.3, 1.0], colors="w", linewidths=0.8
)
ax0.clabel(cs, fmt="%.2f", fontsize=8)
fig.colorbar(im, ax=ax0, label="log10(|eq. 3.3 - exact| / in-water path length)")
ax0.set_xlabel("light zenith angle (degrees)")
ax0.set_ylabel("terrain slope (degrees)")
ax0.set_title("Eq. 3.3 photon position error, worst over terrain azimuth")
for s_deg, color in ((0, "k"), (10, "C0"), (20, "C1"), (30, "C2"), (45, "C3")):
    i = np.argmin(np.abs(slope_deg - s_deg))
    ax1.semilogy(light_deg[1:], worst[i, 1:], color=color, label=f"slope {s_deg} deg, float64")
ax1.semilogy(
    light_deg[1:], np.nanmax(rel_p32, axis=-1)[0, 1:], "y:", lw=2, label="slope 0 deg, float32"
)
ax1.set_xlabel("light zenith angle (degrees)")
ax1.set_ylabel("|eq. 3.3 - exact| / in-water path length (unitless)")
ax1.set_title("Seed 002 eq. 3.3 vs exact ray-plane intersection")
ax1.text(
    0.02,
    0.97,
    "spikes: slope + zenith >= 90 deg,\nlight grazes the terrain for some azimuth",
    transform=ax1.transAxes,
    va="top",
    fontsize=8,
)
ax1.legend(fontsize=8)
fig.tight_layout()
fig.savefig(FIG / "projected_photon_error.png", dpi=120)
plt.close(fig)

# %% [markdown]
# ## 3. Fixed-point 4.28 accumulation (seed 000 §3.2)
#
# `N` photon contributions land on one collection point. Contributions are float32
# (what the shader holds), log-normal with the total scaled to 0.5 ("well below 1").
# Reference: the float64 sum of the same float32 values. Compared: the 4.28 integer
# sum (order-independent by construction), and float32 serial sums (`np.add.accumulate`
# is sequential, like one atomic after another) in 32 random orders.

# %%
rng = np.random.default_rng(2026)
rows = []
for n in (100, 1_000, 10_000, 100_000):
    x = rng.lognormal(0.0, 1.0, n)
    x = (x * 0.5 / x.sum()).astype(np.float32)
    exact = x.astype(np.float64).sum()
    # decode the 32-bit word in float64, so only the 4.28 quantisation is measured
    fixed = float(fixed_point_decode(fixed_point_accumulate(jnp.asarray(x)).code, jnp.float64)[0])
    serial = np.array(
        [np.add.accumulate(x[rng.permutation(n)], dtype=np.float32)[-1] for _ in range(32)],
        np.float64,
    )
    rows.append(
        {
            "n": n,
            "mean_contribution": float(x.mean()),
            "fixed_point_abs_error": abs(fixed - exact),
            "fixed_point_bound_n_half_steps": n * RESOLUTION / 2,
            "float32_max_abs_error": float(np.abs(serial - exact).max()),
            "float32_order_spread": float(serial.max() - serial.min()),
            "float32_distinct_results_of_32": int(np.unique(serial).size),
        }
    )
# Contributions below half a step round to zero: the bias the format has for tiny flux.
tiny = np.full(100_000, 0.9 * RESOLUTION / 2, np.float32)
results["fixed_point"] = {
    "format": "unsigned 4.28 in uint32",
    "resolution": RESOLUTION,
    "max_value_overflow_bound": MAX_VALUE,
    "per_addend_max_error": RESOLUTION / 2,
    "runs": rows,
    "tiny_contributions_lost": {
        "value": float(tiny[0]),
        "n": tiny.size,
        "float64_sum": float(tiny.astype(np.float64).sum()),
        "fixed_point_sum": float(fixed_point_accumulate(jnp.asarray(tiny)).value[0]),
    },
}

# %%
write_json(FIG / "kernel_approximations.json", results)
print("Schlick (eq. 14) vs exact Fresnel, air->water:")
f = results["fresnel_schlick"]
print(
    f"  max |err| {f['max_abs_error_float64']:.4f} at {f['angle_of_max_error_deg']:.1f} deg; "
    f"<= 50 deg: {f['max_abs_error_up_to_50deg']:.4f}; float32 max {f['max_abs_error_float32']:.4f}"
)
p = results["projected_photon"]
print(
    "Eq. 3.3 vs exact, flat terrain, error/depth by light angle:",
    {k: round(v, 4) for k, v in p["flat_terrain_error_per_depth_at_light_deg"].items()},
)
print(
    f"  relative: whole map max {p['relative_error_max_whole_map']:.3f}; slope<=10, light<=30: "
    f"{p['relative_error_max_slope_le_10_light_le_30']:.4f}"
)
print(
    f"{'N':>7} {'fixed err':>10} {'bound':>10} {'f32 max err':>12} {'f32 spread':>11}"
    f" {'distinct':>8}"
)
for r in rows:
    print(
        f"{r['n']:>7} {r['fixed_point_abs_error']:>10.2e}"
        f" {r['fixed_point_bound_n_half_steps']:>10.2e} "
        f"{r['float32_max_abs_error']:>12.2e} {r['float32_order_spread']:>11.2e} "
        f"{r['float32_distinct_results_of_32']:>8}"
    )
print(f"overflow bound {MAX_VALUE!r}; tiny:", results["fixed_point"]["tiny_contributions_lost"])
