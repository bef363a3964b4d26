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
# # Shader reference data: reading an export with numpy from its manifest
#
# `caustics-jax export --out DIR` (or `caustics_jax.export.export(DIR)`) writes, per
# kernel, a JSON manifest and a little-endian binary of std430 records, plus a C header
# (docs/export.md). A port in another language must be able to read it with nothing but
# the manifest; this notebook does exactly that with plain numpy (no `caustics_jax`
# reader), then shows the cases, the tolerances and how a port's outputs are judged.
#
# The export goes to a temporary folder. `CAUSTICS_JAX_QUICK=1` (what CI runs) exports 64
# records per kernel instead of 1024.

# %%
import json
import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

QUICK = os.environ.get("CAUSTICS_JAX_QUICK", "") not in ("", "0")
COUNT = 64 if QUICK else 1024
plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": 100, "font.size": 9})

# %% [markdown]
# ## Write an export
#
# Same arguments, same bytes: the seed fixes every generated case.

# %%
from caustics_jax import export  # noqa: E402

out = Path(tempfile.mkdtemp(prefix="caustics_refdata_"))
written = export.export(out, count=COUNT, seed=0)
for p in sorted(written, key=lambda p: p.name):
    print(f"{p.name:<32}{p.stat().st_size:>10,} bytes")

# %% [markdown]
# ## A manifest
#
# The kernel and its equations, the record stride, every field's dtype, shape, storage
# shape (a `vec3` is stored in 16 bytes) and byte offset, the tolerances, the case counts,
# the seed and the versions.

# %%
manifest = json.loads((out / "refract.json").read_text())
print(json.dumps({k: v for k, v in manifest.items() if k != "fields"}, indent=1))
print(f"\n{'field':<12}{'role':<8}{'glsl':<10}{'dtype':<9}{'shape':<10}{'storage':<10}{'offset':>6}")
for f in manifest["fields"]:
    print(f"{f['name']:<12}{f['role']:<8}{f['glsl']:<10}{f['dtype']:<9}{str(f['shape']):<10}"
          f"{str(f['storage_shape']):<10}{f['offset']:>6}")

# %% [markdown]
# ## Reading the records with numpy and the manifest only
#
# One structured dtype per kernel: each field at its offset, with its storage shape, in
# a record of `stride` bytes; padding lanes (the fourth float of a `vec3`) are dropped
# after reading.

# %%
NUMPY = {"float32": "<f4", "int32": "<i4", "uint32": "<u4"}


def read_export(folder: Path, kernel: str) -> tuple[dict, dict[str, np.ndarray]]:
    m = json.loads((folder / f"{kernel}.json").read_text())
    dtype = np.dtype({"names": [f["name"] for f in m["fields"]],
                      "formats": [(NUMPY[f["dtype"]], tuple(f["storage_shape"])) for f in m["fields"]],
                      "offsets": [f["offset"] for f in m["fields"]], "itemsize": m["stride"]})
    raw = np.fromfile(folder / f"{kernel}.bin", dtype)
    assert raw.shape == (m["count"],), "the binary must hold count records of stride bytes"
    rec = {}
    for f in m["fields"]:
        v = raw[f["name"]]
        rec[f["name"]] = v[..., : f["shape"][-1]] if f["shape"] != f["storage_shape"] else v
    return m, rec


kernels = sorted(p.stem for p in out.glob("*.json"))
data = {k: read_export(out, k) for k in kernels}
# the package's own reader agrees field by field, bit for bit
for k, (_, rec) in data.items():
    _, theirs = export.load(out, k)
    assert all(np.array_equal(rec[n], theirs[n].reshape(rec[n].shape)) for n in rec), k
print(f"{len(kernels)} kernels read; identical to caustics_jax.export.load")

# %% [markdown]
# ## The cases
#
# `random` (drawn, then filtered so no discrete outcome hangs on a float32 rounding),
# `planted` (inputs built around a known answer) and `adversarial` (fixed edge cases:
# grazing angles, total internal reflection, degenerate triangles, overflow).

# %%
names = list(export.CASES)
print(f"{'kernel':<22}" + "".join(f"{n:>13}" for n in names) + f"{'stride':>8}")
for k, (m, rec) in data.items():
    counts = [int(np.sum(rec["case_tag"] == export.CASES[n])) for n in names]
    assert counts == [m["cases"][n]["count"] for n in names]
    print(f"{k:<22}" + "".join(f"{c:>13}" for c in counts) + f"{m['stride']:>8}")

# %% [markdown]
# ## The tolerances
#
# A float output passes when every element is within `abs + rel * scale`, `scale` the
# largest magnitude of the field (or of the field named `scale_field`) in that record;
# integer outputs must be equal. Tolerances come from the measured float32 error of the
# package's kernels (the float32 audit), never below one float32 rounding of storage.

# %%
print(manifest["tolerance_rule"], "\n")
print(f"{'kernel.field':<34}{'abs':>10}{'rel':>10}  scale field")
for k, (m, _) in data.items():
    for field, tol in m["tolerance"].items():
        if tol.get("exact"):
            print(f"{k + '.' + field:<34}{'exact':>10}")
        else:
            print(f"{k + '.' + field:<34}{tol['abs']:>10.1e}{tol['rel']:>10.1e}  {tol.get('scale_field') or '-'}")

# %% [markdown]
# ## What the cases look like
#
# The refraction inputs: the angle between the incident direction and the normal, and
# the index ratio, by case tag; total internal reflection (an all-zero `T`) where the
# ratio times the sine of the angle exceeds 1.

# %%
m, rec = data["refract"]
I, N, eta = rec["I"].astype(np.float64), rec["N"].astype(np.float64), rec["eta"].reshape(-1).astype(np.float64)
cos_i = -np.sum(I * N, -1) / (np.linalg.norm(I, axis=-1) * np.linalg.norm(N, axis=-1))
angle = np.degrees(np.arccos(np.clip(cos_i, -1, 1)))
tir = np.all(rec["T"] == 0, axis=-1)
fig, ax = plt.subplots(figsize=(7, 3.6))
for n, code in export.CASES.items():
    sel = rec["case_tag"].reshape(-1) == code
    ax.scatter(angle[sel], eta[sel], s=8, label=f"{n} ({sel.sum()})")
ax.scatter(angle[tir], eta[tir], s=40, facecolors="none", edgecolors="k", label="T = 0 (TIR)")
ax.set(xlabel="angle between -I and N (degrees)", ylabel="eta (index ratio)",
       title="refract: the exported cases")
ax.legend(fontsize=7)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## Judging a port
#
# A port reads the inputs, runs its kernel, and compares its outputs with the stored
# reference under the manifest's tolerances. Here the "port" is the package's own
# float32 kernel (what `make conformance` does with the GLSL ports on a Vulkan device);
# a deliberately wrong port (one float32 ULP off on every output, then a 1e-3 relative
# error) shows what a failure looks like.

# %%
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import caustics_jax as cj  # noqa: E402

k = "d_factor"
m, rec = data[k]
kernel = export.KERNELS[k]
with cj.precision("float32"):
    args = {f.name: jnp.asarray(rec[f.name]) for f in kernel.inputs()}
    got = {n: np.asarray(v) for n, v in jax.jit(kernel.evaluate)(args).items()}
for label, outputs in (("package float32", got),
                       ("1 ULP off", {n: np.nextafter(v, np.inf, dtype=v.dtype) if v.dtype == np.float32 else v
                                      for n, v in got.items()}),
                       ("1e-3 relative", {n: v * np.float32(1 + 1e-3) if v.dtype == np.float32 else v
                                          for n, v in got.items()})):
    r = export.compare(m, rec, outputs)
    fields = ", ".join(f"{n}: pass {f['pass_rate']:.3f}" for n, f in r["fields"].items())
    print(f"{label:<16} pass rate {r['pass_rate']:.3f} ({fields})")
