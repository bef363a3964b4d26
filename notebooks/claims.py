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
# # The seeds' claims: what the experiments measured, and seed 003's culling and budget live
#
# docs/claims.md states, for each claim a real-time renderer tunes by, whether it holds
# against the certified reference; `make figures` runs the experiments that write
# `figures/NAME.json`. This notebook reads those JSON files for a summary, then runs seed
# 003's two knobs live on a small pool, where a picture helps: what the final cull takes
# away on a tiled floor, and where the adaptive photon budget puts the photons.
# `CAUSTICS_JAX_QUICK=1` (what CI runs) uses a coarser pool and fewer photons.

# %%
import json
import os
import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = pathlib.Path.cwd().parent
sys.path.insert(0, str(ROOT))  # the experiments package of the repository
from caustics_jax.kernels import CullStatus, photon_budget, photon_cull, throughput  # noqa: E402
from caustics_jax.transport import EmissionPlane, trace_photons  # noqa: E402
from experiments import budget, cull  # noqa: E402
from experiments.caustic_reference import ETA, LIGHT, pool, receiver_grid  # noqa: E402

QUICK = os.environ.get("CAUSTICS_JAX_QUICK", "") not in ("", "0")
TRIANGLES, PHOTONS, CELLS = (2048, 1 << 16, 32) if QUICK else (8192, 1 << 20, 64)

# %% [markdown]
# ## What the experiments measured (from `figures/*.json`)

# %%
fig_dir = ROOT / "figures"


def load(name):
    return json.loads((fig_dir / f"{name}.json").read_text())


c, b = load("cull"), load("budget")
over, low = c["lights"]["overhead"], c["lights"]["low"]
final_01 = next(r for r in over["final"] if r["threshold"] == 0.1)
uniform = next(r for r in b["rows"] if r["method"] == "uniform")
best = min(b["rows"], key=lambda r: r["rel_L1"])
print(f"final cull at 0.1 (light overhead): {100 * final_01['saved']:.1f}% of photons not stored, "
      f"{100 * final_01['energy_removed']:.1f}% of the reflected light removed")
print(f"throughput after the water: overhead {over['beta_percentiles']['p1']:.2f}-"
      f"{over['beta_percentiles']['p99']:.2f}, low light {low['beta_percentiles']['p1']:.2f}-"
      f"{low['beta_percentiles']['p99']:.2f} (p1-p99)")
print(f"adaptive budget: rel. L1 {uniform['rel_L1']:.4f} (uniform) -> {best['rel_L1']:.4f} ({best['method']}) "
      f"at {b['photons_per_frame']:,} photons per frame; uniform needs "
      f"{(uniform['rel_L1'] / best['rel_L1']) ** 2:.1f}x the photons for that error")

# %% [markdown]
# ## The final cull on a tiled floor
#
# Photons from the claims' light through the pre-focal pool (water attenuating at
# `sigma_t = 0.3 / m`) land on a floor of tiles with albedos 0.05-0.8 (`cull.albedo`). The
# final cull (`kernels.photon_cull`) does not store a photon whose reflected energy
# `albedo * beta` is below the threshold: the dark tiles lose theirs first, and with them
# little of the light a viewer sees.

# %%
mesh = pool(TRIANGLES)
receiver = receiver_grid(CELLS)
plane = EmissionPlane.covering(mesh, LIGHT)
rng = np.random.default_rng(0)
X = np.stack([rng.uniform(plane.x0, plane.x1, PHOTONS), rng.uniform(plane.y0, plane.y1, PHOTONS),
              np.full(PHOTONS, plane.z)], -1)
hits = trace_photons(mesh, LIGHT, X, intensity=1.0, area=plane.area / PHOTONS, eta=ETA, receiver_z=receiver.z)
beta = np.where(hits.valid, np.asarray(throughput(jnp.asarray(hits.cos_i), jnp.asarray(hits.t), 1 / ETA,
                                                  cull.SIGMA_T)), 0.0)
rho = cull.albedo(hits.Y[:, 0], hits.Y[:, 1])
cell, inside = receiver.cells(hits.Y, hits.valid)


def reflected(final):
    stored, status = photon_cull(jnp.asarray(beta), jnp.asarray(rho), jnp.asarray(0.0), jnp.asarray(final))
    w = np.where(inside, rho * np.asarray(stored) * hits.flux, 0.0)
    E = np.bincount(cell, w, receiver.nx * receiver.ny).reshape(receiver.ny, receiver.nx) / receiver.cell_area
    return E, float(np.mean(np.asarray(status)[inside] == CullStatus.FINAL))


full, _ = reflected(0.0)
culled, share = reflected(0.1)
extent = (receiver.x0, receiver.x1, receiver.y0, receiver.y1)
fig, axes = plt.subplots(1, 3, figsize=(13, 4))
for ax, img, title in ((axes[0], full, "albedo x E, every photon stored"),
                       (axes[1], culled, f"final cull at 0.1: {100 * share:.0f}% of photons not stored"),
                       (axes[2], full - culled, f"removed: {100 * (1 - culled.sum() / full.sum()):.1f}% of the light")):
    im = ax.imshow(img, origin="lower", extent=extent, cmap="inferno")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x (m)")
    fig.colorbar(im, ax=ax, label="reflected irradiance (W/m^2 per W/sr)")
axes[0].set_ylabel("y (m)")
fig.suptitle(f"Seed 003's final cull on a tiled floor 1 m under the pool ({PHOTONS:,} photons)", fontsize=10)
fig.tight_layout()

# %% [markdown]
# ## Where the adaptive budget puts the photons
#
# One frame of uniform photons gives each light-space texel its footprint on the floor
# (`budget.frame_map`); `kernels.photon_budget` turns it into the next frame's photons per
# texel. Texels whose photons miss the floor's cells keep only the floor share (a quarter
# of the uniform count): that, far more than the exponent `gamma`, is what the budget gains
# (docs/claims.md "The adaptive photon budget").

# %%
g = 32
counts = budget.rounded(np.full(g * g, PHOTONS / (g * g)))
E_uniform, footprint, landed = budget.frame_map(mesh, plane, counts, g, receiver, rng)
alloc = budget.rounded(np.asarray(photon_budget(jnp.asarray(footprint), PHOTONS, 1 / 3))).reshape(g, g)
E_adaptive, _, landed_adaptive = budget.frame_map(mesh, plane, np.maximum(alloc.reshape(-1), 1), g, receiver, rng)
fig, axes = plt.subplots(1, 2, figsize=(10, 4))
im = axes[0].imshow(alloc, origin="lower", cmap="magma")
fig.colorbar(im, ax=axes[0], label="photons per texel")
axes[0].set_title(f"next frame's budget, gamma 1/3 ({g}^2 texels on the emission plane)", fontsize=9)
axes[0].set_xlabel("texel x")
axes[0].set_ylabel("texel y")
axes[1].bar(["uniform", "adaptive"], [100 * landed, 100 * landed_adaptive])
axes[1].set_ylabel("photons landing on the floor's cells (%)")
axes[1].set_title("equal photon count, one frame", fontsize=9)
fig.tight_layout()
print(f"photons on the floor's cells: uniform {100 * landed:.0f}%, adaptive {100 * landed_adaptive:.0f}%")
