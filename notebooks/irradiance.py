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
# # Caustic irradiance: the walk and D against photons
#
# The irradiance of a solved path, `E = eta^2 T cos(theta_P) I_e / D` (seed 001 eq. 25-33
# with the factors of math.md §6; `caustics_jax.irradiance`), against forward light
# transport: brute-force photons traced through the same mesh and binned on the floor
# (`caustics_jax.photon_irradiance`), on
#
# 1. a wavy pool before the focal distance (every receiver has one path): maps, the
#    z-scores of the difference, and a profile through the brightest caustic line;
# 2. a steep pool 3 m deep, past the focal distance: a transect where several paths
#    reach one receiver, so the walk's one path is only part of the light, and the sum
#    over every solution of the exhaustive reference is the whole.
#
# `experiments/irradiance_agreement.py` is the full study (photon differentials, photon
# counts up to 2^26, the flat-pool exact formula; docs/irradiance.md).
# `CAUSTICS_JAX_QUICK=1` (what CI runs) uses 2^20 photons and coarser grids.

# %%
import os

import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import caustics_jax as cj

cj.enable_x64()  # the float64 reference; float32 is compared below
QUICK = os.environ.get("CAUSTICS_JAX_QUICK", "") not in ("", "0")
ETA = 1.333
LIGHT = np.array([0.4, -0.3, 3.0])
UP = np.array([0.0, 0.0, 1.0])
CELLS = 32 if QUICK else 64                     # receiver cells per side
PHOTONS = 1 << (20 if QUICK else 23)
plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": "figure", "font.size": 9})
print(f"quick={QUICK}: {CELLS}² cells, {PHOTONS:,} photons")

# %% [markdown]
# ## 1. Before the focal distance: a wavy pool 1 m deep
#
# 8192 triangles, waves of amplitude 0.1 m. The walk's value is a cell average (the
# midpoint rule over `k x k` points per cell), which is what a binned photon estimate
# converges to.

# %%
scene = cj.scenes.wavy_pool(8192, amplitude=0.1, dtype="float64")
mesh = scene.surface
receiver = cj.ReceiverGrid(-1.0, -1.6, 1.6, -1.6, 1.6, CELLS, CELLS)
k = 2 if QUICK else 3


def walk_map(dtype):
    P = jnp.asarray(receiver.subsamples(k).reshape(-1, 3), dtype)
    E, sol = cj.irradiance(mesh.astype(dtype), P, jnp.asarray(LIGHT, dtype), intensity=1.0, eta=ETA,
                           receiver_normal=UP, return_solution=True)
    return np.asarray(E, np.float64).reshape(CELLS, CELLS, k * k).mean(-1), sol.summary()


E_walk, status = walk_map("float64")
E_walk32, status32 = walk_map("float32")
pm = cj.photon_irradiance(mesh, LIGHT, intensity=1.0, eta=ETA, receiver=receiver, n_photons=PHOTONS, seed=0,
                          chunk=1 << 18)
z = (pm.irradiance - E_walk) / pm.stderr
print("walk statuses, float64:", status, "float32:", status32)
print(f"photons vs walk: relative L1 {np.abs(pm.irradiance - E_walk).sum() / E_walk.sum():.2e}, "
      f"mean z² {np.mean(z**2):.2f} (1 when the difference is photon noise alone)")
rel32 = np.abs(E_walk32 / E_walk - 1)
print(f"walk float32 vs float64, cell averages: median relative {np.median(rel32):.1e}, max {rel32.max():.1e} "
      f"(a cell average over {k * k} points loses 1/{k * k} of its value per lane without a path)")

# %%
ext = (receiver.x0, receiver.x1, receiver.y0, receiver.y1)
vmin, vmax = np.percentile(E_walk, [0.5, 99.5])
fig, axes = plt.subplots(1, 4, figsize=(15, 3.6))
for ax, E, title in ((axes[0], E_walk, "walk + D (cell averages)"),
                     (axes[1], pm.irradiance, f"photons, N = 2^{int(np.log2(pm.n_photons))}")):
    im = ax.imshow(E, origin="lower", extent=ext, vmin=vmin, vmax=vmax, cmap="inferno", interpolation="nearest")
    ax.set(title=title, xlabel="x (m)", ylabel="y (m)")
    fig.colorbar(im, ax=ax, label="irradiance (W/m², I_e = 1 W/sr)", shrink=0.85)
rel = pm.irradiance / E_walk - 1
lim = np.percentile(np.abs(rel), 99)
im = axes[2].imshow(rel, origin="lower", extent=ext, vmin=-lim, vmax=lim, cmap="RdBu_r", interpolation="nearest")
axes[2].set(title="photons / walk - 1", xlabel="x (m)", ylabel="y (m)")
fig.colorbar(im, ax=axes[2], label="relative difference", shrink=0.85)
g = np.linspace(-4.5, 4.5, 200)
axes[3].hist(z.ravel(), bins=50, density=True, alpha=0.7, label="cells")
axes[3].plot(g, np.exp(-g**2 / 2) / np.sqrt(2 * np.pi), "k--", label="standard normal")
axes[3].set(title="(photons - walk) / photon std. error", xlabel="z-score", ylabel="density")
axes[3].legend(fontsize=8)
fig.suptitle("Caustic irradiance on the floor of a wavy pool: walk + D against brute-force photons")
fig.tight_layout()
plt.show()

# %% [markdown]
# ### A profile through the caustic
#
# The row of cells with the largest contrast (max / median of the walk's irradiance),
# walk against photons with their ±2 standard errors.

# %%
row = int(np.argmax(E_walk.max(1) / np.median(E_walk, 1)))
x = receiver.centers()[row, :, 0]
fig, ax = plt.subplots(figsize=(10, 3.4))
ax.errorbar(x, pm.irradiance[row], yerr=2 * pm.stderr[row], fmt=".", color="0.5", ms=4,
            label="photons (±2 s.e.)")
ax.plot(x, E_walk[row], "-", color="C0", label="walk + D, float64")
ax.plot(x, E_walk32[row], ":", color="C1", label="walk + D, float32")
ax.set(xlabel=f"x on the row y = {receiver.centers()[row, 0, 1]:.2f} m (m)",
       ylabel="irradiance (W/m², I_e = 1 W/sr)", title="Profile through the brightest caustic line")
ax.legend(fontsize=8)
ax.grid(True, alpha=0.3)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 2. Past the focal distance: several paths per receiver
#
# Steep waves (amplitude 0.3 m, 2048 triangles) over a floor 3 m down. First the number
# of refracted paths per receiver over the floor (the exhaustive reference,
# `solve(..., method="exhaustive", return_all=True).count`); then, along the row with the
# most multi-path receivers, the walk's one path against the sum over every solution
# (`irradiance(..., method="exhaustive", all_paths=True)`) and photons. 3 m down the
# light spreads past the pool walls, so the floor is an unbounded plane.

# %%
depth = 3.0
steep = cj.scenes.wavy_pool(2048, amplitude=0.3, depth=depth, dtype="float64").surface
L = jnp.asarray(LIGHT)
G = 16 if QUICK else 32
floor = cj.ReceiverGrid(-depth, -4.0, 2.0, -3.0, 3.0, G, G)
C = jnp.asarray(floor.centers().reshape(-1, 3))
paths = np.asarray(cj.solve(steep, C, jnp.broadcast_to(L, C.shape), eta=ETA, method="exhaustive",
                            return_all=True).count).reshape(G, G)
row = int(np.argmax((paths > 1).sum(1)))
y0 = float(floor.centers()[row, 0, 1])
fig, ax = plt.subplots(figsize=(5.5, 4.4))
im = ax.imshow(paths, origin="lower", extent=(floor.x0, floor.x1, floor.y0, floor.y1),
               cmap="viridis", vmin=0, vmax=max(int(paths.max()), 1), interpolation="nearest")
ax.axhline(y0, color="w", ls="--", lw=1, label=f"transect y = {y0:.2f} m")
fig.colorbar(im, ax=ax, label="refracted paths to the receiver")
ax.set(xlabel="x (m)", ylabel="y (m)", title="Paths per receiver, floor 3 m under steep waves")
ax.legend(fontsize=8, loc="upper right")
fig.tight_layout()
plt.show()

# %%
n, kk = (48, 2) if QUICK else (160, 4)
transect = cj.ReceiverGrid(-depth, -4.0, 2.0, y0 - 0.02, y0 + 0.02, n, 1)
P = jnp.asarray(transect.subsamples(kk).reshape(-1, 3))


def cell(E):
    return np.asarray(E).reshape(n, kk * kk).mean(-1)


walk = cell(cj.irradiance(steep, P, L, intensity=1.0, eta=ETA, receiver_normal=UP))
every = cj.solve(steep, P, jnp.broadcast_to(L, P.shape), eta=ETA, method="exhaustive", return_all=True)
total = cell(cj.irradiance(steep, P, L, intensity=1.0, eta=ETA, receiver_normal=UP, method="exhaustive",
                           all_paths=True))
pt = cj.photon_irradiance(steep, LIGHT, intensity=1.0, eta=ETA, receiver=transect,
                          n_photons=1 << (21 if QUICK else 24), seed=11, chunk=1 << 18)
count = np.asarray(every.count).reshape(n, kk * kk).max(-1)
xs = transect.centers()[0, :, 0]
fig, (ax, ax2) = plt.subplots(2, 1, figsize=(10, 5.2), sharex=True, gridspec_kw=dict(height_ratios=[3, 1]))
ax.errorbar(xs, pt.irradiance[0], yerr=2 * pt.stderr[0], fmt=".", color="0.5", ms=4,
            label=f"photons (2^{int(np.log2(pt.n_photons))}, ±2 s.e.)")
ax.plot(xs, total, "-", color="C3", label="sum over all exhaustive solutions")
ax.plot(xs, walk, "--", color="C0", label="walk + D (one path)")
ax.set(ylabel="irradiance (W/m², I_e = 1 W/sr)",
       title="Past the focal distance (floor 3 m deep): one path is not the whole irradiance")
ax.legend(fontsize=8)
ax.grid(True, alpha=0.3)
ax2.step(xs, count, where="mid", color="k")
ax2.set(xlabel=f"x on the transect y = {y0:.2f} m (m)", ylabel="paths")
ax2.grid(True, alpha=0.3)
fig.tight_layout()
plt.show()
multi = count > 1
print(f"{multi.sum()} of {n} cells are reached by several paths; there the walk carries a median "
      f"{np.median(walk[multi] / total[multi]) if multi.any() else float('nan'):.2f} of the total")
