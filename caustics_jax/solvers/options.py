"""The options contract every solver shares: validation at the API boundary, the static /
traced split, and the acceptance tolerance.

Each solver is a frozen dataclass of its options (`Walk`, `Newton`, `Exhaustive`), in the
style of optimistix's solver objects: hashable (a static argument of jit), validated once
in `__post_init__` by the checks below, each raising `ValueError` that names the argument
and its valid range before any jitted work (docs/input_contract.md).

Acceptance: a lane is FOUND when `|f| <= tol` for the signed sine `f` (seed 001 eq. 21),
the sine of the angle between the refracted direction and `w_L`. `f` lies in `[-1, 1]`,
so a `tol` of 1 or more accepts every point: `tol` must lie in `(0, 1)`.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

#: Largest iteration cap (the counters are int32).
MAX_INT32 = 2**31 - 1


def default_tol(dtype) -> float:
    """Default acceptance `|f| <= tol`: 1e-10 in float64, 1e-5 in float32 (the float32
    audit's noise floor of `f` is about 1e-6, docs/kernels.md)."""
    return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 1e-5


def _is_real_scalar(value) -> bool:
    if isinstance(value, bool | np.bool_):
        return False
    if isinstance(value, np.ndarray | np.generic):
        return value.ndim == 0 and np.issubdtype(value.dtype, np.integer | np.floating)
    return isinstance(value, numbers.Real)


def check_tol(name: str, value, *, optional: bool = True):
    """A finite real in `(0, 1)` (or None when `optional`); returns it as a float."""
    if value is None and optional:
        return None
    if not _is_real_scalar(value) or not math.isfinite(float(value)) or not 0 < float(value) < 1:
        raise ValueError(
            f"{name} must be a finite real number in (0, 1) (|signed sine| <= {name} accepts a point; "
            f"the sine is at most 1), got {value!r}")
    return float(value)


def check_int(name: str, value, lo: int, hi: int = MAX_INT32) -> int:
    """An integer (not a bool) in `[lo, hi]`; returns it as an int."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral | np.integer):
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    if not lo <= int(value) <= hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def check_real(name: str, value, lo: float, hi: float = math.inf, *, lo_open: bool = False) -> float:
    """A finite real in `[lo, hi]` (`(lo, hi]` with `lo_open`); returns it as a float."""
    ok = _is_real_scalar(value) and math.isfinite(float(value))
    if ok:
        v = float(value)
        ok = (v > lo if lo_open else v >= lo) and v <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        raise ValueError(f"{name} must be a finite real number in {bracket}{lo}, {hi}], got {value!r}")
    return float(value)


def check_choice(name: str, value, choices) -> str:
    """One of `choices`."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def check_bool(name: str, value) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_eta(eta) -> float:
    """The index ratio `eta_in / eta_out`: one finite positive real number."""
    if not _is_real_scalar(eta) or not math.isfinite(float(eta)) or float(eta) <= 0:
        raise ValueError(
            f"eta must be one finite positive real number (eta_in / eta_out, water 1.333), got {eta!r}")
    return float(eta)


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Base of the solver objects: `method` names it for `solve(method=...)`; the fields in
    `traced` are passed to jit as arrays (a sweep over them compiles once), the rest are
    static.

    Subclasses call the `check_*` functions in `__post_init__` (via `_validate`).
    """

    method: ClassVar[str] = ""
    traced: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self):
        self._validate()  # each subclass defines it

    @classmethod
    def from_kwargs(cls, **options):
        """`cls(**options)`, with unknown names reported as a `ValueError`."""
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise ValueError(f"unknown {cls.method} option(s) {unknown}; known: {known}")
        return cls(**options)

    def static(self):
        """The options with the traced fields blanked: the hashable part jit compiles for."""
        blank = {name: (None if name == "tol" else 0) for name in self.traced}
        out = object.__new__(type(self))  # no validation: the blanks are placeholders
        for f in dataclasses.fields(self):
            object.__setattr__(out, f.name, blank.get(f.name, getattr(self, f.name)))
        return out

    def tolerance(self, dtype) -> float:
        tol = getattr(self, "tol", None)
        return default_tol(dtype) if tol is None else tol
