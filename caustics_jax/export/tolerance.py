"""Tolerances of the shader reference data and the comparison a port is judged by
(DESIGN.md "Reference data for shader tests"; docs/export.md "Tolerances").

Per float output field a record passes when `|value - ref| <= abs + rel * scale` for every
element, `scale` the largest magnitude of the field in that record (or of the field named
by `scale_field`). `abs` and `rel` come from measurements: the same kernel run in float32
(XLA on the CPU) on the same float32 inputs, its worst error over this export, and for
the kernels that `experiments/float32_audit.py` measured over 200k paths the audit's
maximum where larger; times `SAFETY`, plus the storage rounding of the reference (half a
float32 ulp) and its own float64 error budget (`F64_BUDGET`). Integer outputs (flags,
counts, codes) must match exactly.

The audit table ships with the package (`float32_audit.json`, package data written by
`python -m experiments.float32_audit`), so a checkout and an installed wheel derive the
same tolerances; a missing or malformed table is an error. numpy only.
"""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path

import numpy as np

from .records import Field

#: Factor between the worst measured float32 error and the tolerance. A GLSL port orders
#: its operations differently, may contract `a * b + c` to an FMA, and GLSL allows 2-3 ulp
#: for division, `sqrt` and `exp` where XLA rounds correctly.
SAFETY = 4.0
#: Relative error budget of the float64 reference itself (64 float64 ulps; the audit
#: measures at most ~10 ulps on the planted residuals) and of storing it as float32.
F64_BUDGET = 64 * float(np.finfo(np.float64).eps)
STORAGE_ROUNDING = 0.5 * float(np.finfo(np.float32).eps)
#: The float32 audit of experiments/float32_audit.py (200k planted paths), package data.
AUDIT_FILE = resources.files(__package__).joinpath("float32_audit.json")


def load_audit(path=None) -> dict[str, dict]:
    """The audit's float32 table (entry name -> {"max", "p99", "median", "n"}) from `path`
    (default: the package's `float32_audit.json`). Raises RuntimeError, naming the file and
    how to regenerate it, when it is missing or malformed; never returns a silent `{}`."""
    source = AUDIT_FILE if path is None else Path(path)
    fix = "regenerate it with `python -m experiments.float32_audit`"
    try:
        table = json.loads(source.read_text())["float32"]
        if not isinstance(table, dict) or not table:
            raise ValueError("'float32' is not a non-empty table")
        for key, entry in table.items():
            if not (isinstance(entry, dict) and isinstance(entry.get("max"), int | float)
                    and math.isfinite(entry["max"]) and entry["max"] >= 0):
                raise ValueError(f"entry {key!r} has no finite non-negative 'max'")
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise RuntimeError(f"float32 audit {source} is missing or malformed ({exc!r}); {fix}") from exc
    return table


def ulp_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance in float32 units in the last place (ordered integer difference); 2^32 for NaN."""
    a, b = np.asarray(a, np.float32), np.asarray(b, np.float32)

    def ordered(x):
        i = x.view(np.int32).astype(np.int64)
        return np.where(i < 0, -(i & 0x7FFFFFFF), i)

    d = np.abs(ordered(a) - ordered(b))
    return np.where(np.isnan(a) | np.isnan(b), 2**32, d)


def field_scale(records: dict[str, np.ndarray], ref: np.ndarray, field: dict | Field) -> np.ndarray:
    """Per-record tolerance scale: the largest magnitude of the field (or of `scale_field`)."""
    name = field["scale_field"] if isinstance(field, dict) else field.scale_field
    src = np.asarray(records[name] if name else ref, np.float64)
    return np.max(np.abs(src.reshape(len(src), -1)), axis=1)


def derive_tolerance(field: Field, records: dict[str, np.ndarray], ref: np.ndarray, f32: np.ndarray,
                     audit: dict[str, dict], audit_key: tuple[str, str] | None = None) -> dict:
    """Manifest tolerance of one float output field (module docstring).

    `ref` the float64 reference rounded to float32, `f32` the kernel run in float32 on the
    same stored inputs, `records` every stored field (for `scale_field`), `audit` the table
    of `load_audit`, `audit_key` the kernel's `(entry, "abs"/"rel")` for this field, if any.
    """
    count = len(ref)
    err = np.abs(f32.astype(np.float64) - ref.astype(np.float64)).reshape(count, -1).max(axis=1)
    scale = field_scale(records, ref, field)
    # errors of values below 1 in magnitude count as absolute, above 1 as relative
    small = scale <= 1
    meas_abs = float(err[small].max()) if small.any() else 0.0
    meas_rel = float((err[~small] / scale[~small]).max()) if (~small).any() else 0.0
    key, kind = audit_key or (None, None)
    if key is not None and key not in audit:
        raise RuntimeError(f"{field.name}: the float32 audit has no entry {key!r}; regenerate it with "
                           "`python -m experiments.float32_audit`")
    audit_max = float(audit[key]["max"]) if key is not None else 0.0
    abs_tol = SAFETY * max(meas_abs, audit_max if kind == "abs" else 0.0)
    rel_tol = SAFETY * max(meas_rel, audit_max if kind == "rel" else 0.0, STORAGE_ROUNDING)
    # storage rounding of the reference and its own float64 error, on top of the margin
    abs_tol += STORAGE_ROUNDING * float(min(scale.max(initial=0.0), 1.0))
    rel_tol += STORAGE_ROUNDING + F64_BUDGET
    return {"abs": abs_tol, "rel": rel_tol, "scale_field": field.scale_field,
            "measured_float32": {"max_abs_below_1": meas_abs, "max_rel_above_1": meas_rel},
            "audit": {"key": key, "max": audit_max} if key is not None else None,
            "safety": SAFETY}


def compare(manifest: dict, records: dict[str, np.ndarray], got: dict[str, np.ndarray]) -> dict:
    """Per output field and over the kernel: max abs / rel / ULP error and pass rate vs tolerance.

    `got` holds a port's outputs (e.g. read back from a GPU), `records` the export. A record
    passes when every element of every output field is within `abs + rel * scale` (float
    fields) or equal (integer fields); NaN never passes.
    """
    count = manifest["count"]
    ok = np.ones(count, bool)
    fields = {}
    for e in manifest["fields"]:
        if e["role"] != "output":
            continue
        ref, val = records[e["name"]].reshape(count, -1), np.asarray(got[e["name"]]).reshape(count, -1)
        if e["dtype"] != "float32":
            good = np.all(ref == val, axis=1)
            fields[e["name"]] = {"mismatches": int(np.sum(~good)), "pass_rate": float(np.mean(good))}
        else:
            tol = manifest["tolerance"][e["name"]]
            err = np.abs(val.astype(np.float64) - ref.astype(np.float64))
            err = np.where(np.isnan(err), np.inf, err)
            scale = field_scale(records, ref, tol)
            bound = tol["abs"] + tol["rel"] * scale[:, None]
            good = np.all(err <= bound, axis=1)
            usage = np.where(err == 0, 0.0, err / np.where(bound > 0, bound, np.finfo(np.float64).tiny))
            pos = scale > 0  # relative error only where the reference is not all zero
            rel = err[pos] / scale[pos, None]
            fields[e["name"]] = {"max_abs": float(err.max()), "max_rel": float(rel.max(initial=0.0)),
                                 "max_ulp": int(ulp_distance(val, ref).max()), "pass_rate": float(np.mean(good)),
                                 "tol_abs": tol["abs"], "tol_rel": tol["rel"], "max_err_over_tol": float(usage.max())}
        ok &= good
    return {"kernel": manifest["kernel"], "count": count, "fields": fields, "pass_rate": float(np.mean(ok)),
            "failures": np.nonzero(~ok)[0].tolist()}
