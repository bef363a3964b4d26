"""Writing the shader reference data (DESIGN.md "Reference data for shader tests"; docs/export.md).

`export(out_dir)` writes, per registered kernel, `<kernel>.json` (the manifest) and
`<kernel>.bin` (little-endian std430 records, `records.py`), plus `caustics_records.h`.
Every record holds the kernel's inputs, rounded to float32, its outputs, the float64
reference computed *from those rounded inputs* by the package's own kernel and then
rounded to float32, and a case tag (`random`, `planted`, `adversarial`). Random (and, where
a kernel asks, planted) candidates pass the kernel's conditioning filter first; the
tolerances come from `tolerance.py`. Same arguments, same bytes.
"""

from __future__ import annotations

import json
import os
import tempfile
import zlib
from collections.abc import Iterable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..runtime.arguments import MAX_INT32, check_int
from ..runtime.precision import precision
from ..runtime.progress import progress
from .cases import split
from .records import CASES, FORMAT_VERSION, c_header, layout, pack_records, record_fields
from .registry import KERNELS, Kernel
from .tolerance import derive_tolerance, load_audit


def _evaluate(kernel: Kernel, inputs: dict[str, np.ndarray], dtype: str) -> dict[str, np.ndarray]:
    with precision(dtype):
        args = {k: jnp.asarray(v, dtype) for k, v in inputs.items()}
        return {k: np.asarray(v) for k, v in jax.jit(kernel.evaluate)(args).items()}


#: Further batches `export_kernel` draws when a batch holds too few well-conditioned cases.
MAX_REDRAWS = 8


def _draw(kernel: Kernel, rng: np.random.Generator, count: int):
    """One batch of `count` cases: `(stored float32 inputs, float64 reference, case tags,
    keep)`, `keep` False for random and planted cases the kernel calls ill-conditioned."""
    inputs, case = kernel.generate(rng, count)
    # inputs as stored (float32), and the reference computed in float64 from exactly those
    stored = {f.name: np.asarray(inputs[f.name], np.float32) for f in kernel.inputs()}
    ref = _evaluate(kernel, {k: v.astype(np.float64) for k, v in stored.items()}, "float64")
    if kernel.keep is None:
        return stored, ref, case, np.ones(len(case), bool)
    x64 = {k: v.astype(np.float64) for k, v in stored.items()}
    with np.errstate(invalid="ignore", divide="ignore"):  # adversarial rows may be degenerate
        filtered = (case == CASES["random"]) | ((case == CASES["planted"]) & kernel.filter_planted)
        keep = kernel.keep(x64, ref) | ~filtered
    return stored, ref, case, keep


def export_kernel(kernel: Kernel, count: int, seed: int, audit: dict | None = None):
    """`(manifest, binary bytes)` for one kernel: `count` random and planted records plus the adversarial set.

    `audit` is the float32 audit table (`tolerance.load_audit()`, the package's, when None).
    `count` at least 4 (a quarter planted, `cases.split`) and `seed` non-negative, as
    `export` requires: `ValueError` otherwise.
    """
    if not isinstance(kernel, Kernel):
        raise ValueError(f"kernel must be an export Kernel (export.KERNELS[name]), got {type(kernel).__name__}")
    count = check_int("count", count, 4)  # (-5 had been numpy's "negative dimensions are not allowed")
    seed = check_int("seed", seed, 0, 2**63 - 1)
    audit = load_audit() if audit is None else audit
    rng = np.random.default_rng([seed, zlib.crc32(kernel.name.encode())])
    n_pl, n_rand = split(count)
    stored, ref, case, keep = _draw(kernel, rng, count)
    # Too few well-conditioned random or planted cases: draw further batches from the same
    # stream and keep their well-conditioned cases (the first batch, and so the bytes of
    # every seed that needs no redraw, is unchanged).
    for _ in range(MAX_REDRAWS):
        short = (np.sum(keep & (case == CASES["random"])) < n_rand
                 or np.sum(keep & (case == CASES["planted"])) < n_pl)
        if not short:
            break
        more = _draw(kernel, rng, count)
        extra = more[3] & (more[2] != CASES["adversarial"])
        stored = {k: np.concatenate([v, more[0][k][extra]]) for k, v in stored.items()}
        ref = {k: np.concatenate([v, more[1][k][extra]]) for k, v in ref.items()}
        case, keep = np.concatenate([case, more[2][extra]]), np.concatenate([keep, more[3][extra]])
    rand_idx = np.nonzero(keep & (case == CASES["random"]))[0][:n_rand]
    if len(rand_idx) < n_rand:
        raise RuntimeError(f"{kernel.name}: only {len(rand_idx)} of {n_rand} random cases are well conditioned "
                           f"after {MAX_REDRAWS} redraws")
    planted_idx = np.nonzero(keep & (case == CASES["planted"]))[0][:n_pl]
    if len(planted_idx) < n_pl:
        raise RuntimeError(f"{kernel.name}: only {len(planted_idx)} of {n_pl} planted cases are well conditioned "
                           f"after {MAX_REDRAWS} redraws")
    idx = np.concatenate([rand_idx, planted_idx, np.nonzero(case == CASES["adversarial"])[0]])
    stored = {k: v[idx] for k, v in stored.items()}
    ref = {k: v[idx] for k, v in ref.items()}
    case = case[idx]
    f32 = _evaluate(kernel, stored, "float32")
    records = {**stored, **ref, "case_tag": case}
    tolerance = {}
    for f in kernel.outputs():
        if f.dtype == "float32":
            tolerance[f.name] = derive_tolerance(f, records, ref[f.name], f32[f.name], audit, kernel.audit.get(f.name))
        else:
            tolerance[f.name] = {"exact": True}
    _, stride = layout(kernel.fields)
    from .._version import __version__

    manifest = {
        "kernel": kernel.name,
        "equations": kernel.equations,
        "reference": kernel.reference,
        "count": int(len(case)),
        "stride": stride,
        "endianness": "little",
        "layout": "std430, vec3 padded to 16 bytes",
        "fields": record_fields(kernel.fields),
        "tolerance": tolerance,
        "tolerance_rule": "float fields: |value - ref| <= abs + rel * scale per element, scale = max |.| of the "
                          "field (or of scale_field) in the record; integer fields: equal",
        "cases": {name: {"code": code, "count": int(np.sum(case == code))} for name, code in CASES.items()},
        "seed": seed,
        "version": {"format": FORMAT_VERSION, "caustics_jax": __version__},
    }
    return manifest, pack_records(kernel.fields, records)


def _check_out_dir(out: Path) -> None:
    """Create `out` (with parents) and make sure a file can be written there; ValueError, one
    line, otherwise: before any case is generated, not as a traceback after the work."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a directory")
    blocker = next((p for p in out.parents if p.exists() and not p.is_dir()), None)
    if blocker is not None:
        raise ValueError(f"--out {out}: {blocker} is a file, not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):  # permissions, read-only mounts, /proc, ...
            pass
    except OSError as exc:
        raise ValueError(f"--out {out} is not writable: {exc.strerror or exc}") from None


def _selection(arg: str, value, registry: dict, what: str) -> list[str]:
    """`kernels` / `scenes` as registered names: None is all of them, one string is one
    name, a name given twice counts once (at its first place: a header declaring a record
    twice does not compile); a `ValueError` for anything else or an unknown name."""
    if value is None:
        return list(registry)
    if isinstance(value, str):
        value = [value]
    if isinstance(value, bytes | bytearray) or not isinstance(value, Iterable):
        raise ValueError(f"{arg} must be None, a {what} name or a list of {what} names, got {value!r}")
    names = list(value)
    unknown = [n for n in names if not isinstance(n, str) or n not in registry]
    if unknown:
        raise ValueError(f"unknown {what}(s) {unknown}; choose from {sorted(registry)}")
    return list(dict.fromkeys(names))


def export(out_dir, kernels: list[str] | None = None, count: int = 256, seed: int = 0,
           scenes: list[str] | None = (), lanes: int = 256, extra_scenes=(), solvers=("walk", "newton"),
           newton=None) -> list[Path]:
    """Write `<kernel>.json`, `<kernel>.bin` per kernel and `caustics_records.h`, and
    `<scene>.json`, `<scene>.bin` per scene (the walk's; `<scene>.newton.json` and `.bin` the
    one-step Newton's) and `caustics_scene.h`, into `out_dir`.

    `kernels`: names of `KERNELS` (None: all; empty: none; one string: that kernel; a
    name given twice is exported once). `count` random and planted records per kernel (a
    quarter planted), plus each kernel's fixed adversarial cases. `scenes`: names of
    `SCENES` (None: all; default none; as `kernels`), each with `lanes` lanes; `extra_scenes`:
    further scenes as `SceneSpec`s (a mesh file's, `scene_cases.mesh_file_scene`)
    (`scene_writer.export_scene`); `solvers`: which solvers' scene files, of "walk" and
    "newton"; `newton`: the Newton's options (default `scene_writer.NEWTON`; a
    `Newton(stepping="one_step", constraint="half_vector", initial_step=0.1)` is Cycles' MNEE
    step control). Same arguments, same bytes. Raises ValueError, before
    any work, on unknown kernel or scene names, a count below 4, lanes outside
    [1, 2^20], a seed outside [0, 2^63 - 1], or an `out_dir` that is empty, a file, lies below a file
    or cannot be created or written.
    """
    from .scene_records import SOLVERS
    from .scene_registry import SCENES, SceneSpec
    from .scene_writer import check_scene_solver, write_scenes

    names = _selection("kernels", kernels, KERNELS, "kernel")
    scene_names = _selection("scenes", scenes, SCENES, "scene")
    extra = list(extra_scenes)
    if not all(isinstance(x, SceneSpec) for x in extra):
        raise ValueError(f"extra_scenes must be export SceneSpecs (scene_cases.mesh_file_scene), got {extra!r}")
    specs = [SCENES[n] for n in scene_names] + extra
    solver_names = _selection("solvers", solvers, SOLVERS, "solver")
    if "newton" in solver_names:
        check_scene_solver("newton", newton=newton)  # before any work
    if len({sp.name for sp in specs}) < len(specs):
        raise ValueError(f"two exported scenes share a name: {[sp.name for sp in specs]} (rename the mesh file)")
    count = check_int("count", count, 4, MAX_INT32)  # (as export_kernel and export_scene check them)
    lanes = check_int("lanes", lanes, 1, 2**20)
    seed = check_int("seed", seed, 0, 2**63 - 1)
    if not isinstance(out_dir, str | os.PathLike):
        raise ValueError(f"--out (out_dir) must be a directory path (str or os.PathLike), got {out_dir!r}")
    if not os.fspath(out_dir):  # Path("") is the current directory: an empty --out had written there
        raise ValueError("--out (out_dir) must name a directory, got an empty path")
    out = Path(out_dir)
    _check_out_dir(out)
    written = []
    if names:
        audit = load_audit()
        for name in progress(names, desc="export", unit="kernel"):
            manifest, raw = export_kernel(KERNELS[name], int(count), int(seed), audit)
            (out / f"{name}.json").write_text(json.dumps(manifest, indent=1) + "\n")
            (out / f"{name}.bin").write_bytes(raw)
            written += [out / f"{name}.json", out / f"{name}.bin"]
        (out / "caustics_records.h").write_text(c_header([KERNELS[n] for n in names]))
        written.append(out / "caustics_records.h")
    if specs:
        written += write_scenes(out, specs, int(lanes), int(seed), tuple(solver_names), newton)
    return written
