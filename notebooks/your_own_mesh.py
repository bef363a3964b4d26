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
# # Your own mesh, end to end
#
# A water surface nobody here made (a jittered Delaunay triangulation with a few waves,
# written as an OBJ file, as a modelling tool would), taken through everything a user
# needs before porting: load it with trimesh, build a `SurfaceMesh`, solve the refraction
# paths, compute the caustic irradiance on a floor under it, check it against photons
# (under a point light and under the sun), and export shader reference data for it and run the GLSL ports on it
# (`caustics-jax export --scene PATH`, `caustics-jax conformance DIR`;
# docs/export.md "Your own mesh"). `CAUSTICS_JAX_QUICK=1` (what CI runs) uses fewer
# receivers and photons.

# %%
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import trimesh
from scipy.spatial import Delaunay

import caustics_jax as cj

cj.enable_x64()
QUICK = os.environ.get("CAUSTICS_JAX_QUICK", "") not in ("", "0")
CELLS = 24 if QUICK else 48
PHOTONS = 1 << (18 if QUICK else 22)
plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": "figure", "font.size": 9})
work = Path(tempfile.mkdtemp(prefix="own_mesh_"))

# %% [markdown]
# ## 1. A mesh file
#
# 2,000 jittered points over a 3 m square, triangulated, heights from three waves. The
# faces are wound so that the normals point up, toward the light (math.md §1: the
# receivers are inside the medium, behind the normals).

# %%
rng = np.random.default_rng(7)
xy = rng.uniform(-1.5, 1.5, (2000, 2))
corners = np.array([[-1.5, -1.5], [1.5, -1.5], [1.5, 1.5], [-1.5, 1.5]])
xy = np.concatenate([corners, xy])
faces = Delaunay(xy).simplices
z = 0.03 * np.sin(3.1 * xy[:, 0] + 0.4) * np.cos(2.3 * xy[:, 1]) + 0.015 * np.sin(5.7 * xy[:, 0] - 4.1 * xy[:, 1])
V = np.column_stack([xy, z])
up = np.cross(V[faces[:, 1]] - V[faces[:, 0]], V[faces[:, 2]] - V[faces[:, 0]])[:, 2] > 0
faces = np.where(up[:, None], faces, faces[:, ::-1])
path = work / "my_water.obj"
trimesh.Trimesh(V, faces, process=False).export(path)
print(path.name, path.stat().st_size // 1024, "KiB")

# %% [markdown]
# ## 2. Load it and solve
#
# `SurfaceMesh.from_trimesh` computes the vertex normals and the adjacency and refuses a
# mesh it cannot use with a `ValueError` naming the problem. The floor is 0.8 m below the
# water and the light 2.5 m above it.

# %%
mesh = cj.SurfaceMesh.from_trimesh(trimesh.load(path), dtype="float64")
light = np.array([0.3, -0.2, 2.5])
floor = float(np.min(np.asarray(mesh.vertices)[:, 2])) - 0.8
grid = cj.ReceiverGrid(floor, -1.2, 1.2, -1.2, 1.2, CELLS, CELLS)
P = grid.centers().reshape(-1, 3)
sol = cj.solve(mesh, P, light)
counts = {s.name: int(np.sum(np.asarray(sol.status) == s)) for s in cj.Status if np.any(np.asarray(sol.status) == s)}
print(f"{mesh.faces.shape[0]} faces, {len(P)} receivers:", counts)

# %% [markdown]
# ## 3. Irradiance against photons
#
# The walk's irradiance (one path per receiver, `cj.irradiance`) next to brute-force
# photons traced through the same mesh (`cj.photon_irradiance`), on the same cells. The
# walk's values are point values at the cell centres, the photons' are cell averages
# with Monte-Carlo noise: the speckle of the walk's map is the irregular mesh's own
# (interpolated normals over uneven triangles), which cell averages smooth out.

# %%
E = np.asarray(cj.irradiance(mesh, P, light, intensity=1.0, receiver_normal=[0, 0, 1])).reshape(CELLS, CELLS)
pm = cj.photon_irradiance(mesh, light, intensity=1.0, n_photons=PHOTONS, receiver=grid)
fig, ax = plt.subplots(1, 2, figsize=(8.4, 3.8), constrained_layout=True)
vmax = float(np.percentile(E, 99))
for a, img, title in ((ax[0], E, "walk: E at the cell centres"), (ax[1], pm.irradiance, f"{PHOTONS:,} photons")):
    im = a.imshow(img, origin="lower", extent=(-1.2, 1.2, -1.2, 1.2), vmin=0, vmax=vmax, cmap="inferno")
    a.set(title=title, xlabel="x (m)", ylabel="y (m)")
fig.colorbar(im, ax=ax, label="irradiance (W/m², intensity 1 W/sr)")
fig.suptitle("Caustic irradiance under your own mesh: walk against photons")
plt.show()
print(f"mean E: walk {E.mean():.4f}, photons {pm.irradiance.mean():.4f} W/m²")

# %% [markdown]
# ## 3b. Under the sun
#
# Water caustics under the sun: `cj.Directional(direction)`, with `direction` the way the
# rays travel (the sun overhead is `(0, 0, -1)`), goes wherever the point light went. Its
# `intensity` is the sun's irradiance on a plane perpendicular to its rays (W/m²), and the
# irradiance is the limit of a point light at infinity (math.md §9). The photons are
# parallel, through the same emission plane.

# %%
sun = cj.Directional([0.2, 0.1, -1.0])
E_sun = np.asarray(cj.irradiance(mesh, P, sun, intensity=1000.0, receiver_normal=[0, 0, 1])).reshape(CELLS, CELLS)
pm_sun = cj.photon_irradiance(mesh, sun, intensity=1000.0, n_photons=PHOTONS, receiver=grid)
fig, ax = plt.subplots(1, 2, figsize=(8.4, 3.8), constrained_layout=True)
vmax = float(np.percentile(E_sun, 99))
for a, img, title in ((ax[0], E_sun, "walk: E at the cell centres"),
                      (ax[1], pm_sun.irradiance, f"{PHOTONS:,} parallel photons")):
    im = a.imshow(img, origin="lower", extent=(-1.2, 1.2, -1.2, 1.2), vmin=0, vmax=vmax, cmap="inferno")
    a.set(title=title, xlabel="x (m)", ylabel="y (m)")
fig.colorbar(im, ax=ax, label="irradiance (W/m², sun 1000 W/m²)")
fig.suptitle("Under the sun (travelling along (0.2, 0.1, -1)): walk against photons")
plt.show()
print(f"mean E: walk {E_sun.mean():.1f}, photons {pm_sun.irradiance.mean():.1f} W/m²")

# %% [markdown]
# ## 4. Shader reference data for it, and the GLSL ports on it
#
# `caustics-jax export --scene PATH` exports this scene alone, named after the file's
# stem, with the floor and light given here (a TOML `--scene-file` holds the same
# options). `caustics-jax conformance DIR` runs the GLSL start point, walk, D and
# irradiance on it on a Vulkan device (lavapipe on a CPU) and judges them lane by lane;
# without a Vulkan toolchain it says so and exits with status 3.

# %%
cli = [sys.executable, "-m", "caustics_jax.app.cli"]
out = work / "refdata"
lanes = "64" if QUICK else "1024"
run = subprocess.run([*cli, "export", "--out", str(out), "--scene", str(path), "--lanes", lanes,
                      "--light", *map(str, light), "--floor-depth", "0.8"], capture_output=True, text=True)
print(run.stdout.strip() or run.stderr.strip())
conf = subprocess.run([*cli, "conformance", str(out)], capture_output=True, text=True)
print(conf.stdout.strip() or conf.stderr.strip(), f"(exit status {conf.returncode})")
