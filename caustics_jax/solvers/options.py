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
from typing import ClassVar

import jax.numpy as jnp

# The checks live below every layer (`caustics_jax.arguments`), so scenes, meshes and
# transport refuse bad values with the same words; solvers import them from here.
from ..arguments import (
    MAX_INT32,
    check_bool,
    check_choice,
    check_eta,
    check_int,
    check_real,
    check_tol,
    is_real_scalar,
)

__all__ = ["MAX_INT32", "SolverOptions", "check_bool", "check_choice", "check_eta", "check_int",
           "check_real", "check_tol", "default_tol", "is_real_scalar"]


def default_tol(dtype) -> float:
    """Default acceptance `|f| <= tol`: 1e-10 in float64, 1e-5 in float32 (the float32
    audit's noise floor of `f` is about 1e-6, docs/conic.md)."""
    return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 1e-5


class _Checked(type):
    """Metaclass of the solver objects: an unknown or surplus argument is a `ValueError`
    naming the known options, as `solve(method="walk", foo=1)` says (`Walk(foo=1)` had
    raised Python's `TypeError` from the dataclass constructor)."""

    def __call__(cls, *args, **kwargs):
        known = [f.name for f in dataclasses.fields(cls)] if dataclasses.is_dataclass(cls) else []
        unknown = sorted(set(kwargs) - set(known))
        if unknown:
            raise ValueError(f"unknown {cls.method or cls.__name__} option(s) {unknown}; known: {known}")
        if len(args) > len(known):
            raise ValueError(f"{cls.__name__} takes at most {len(known)} options ({known}), got {len(args)} "
                             "positional arguments")
        return super().__call__(*args, **kwargs)


@dataclasses.dataclass(frozen=True)
class SolverOptions(metaclass=_Checked):
    """Base of the solver objects: `method` names it for `solve(method=...)`; the fields in
    `traced` are passed to jit as arrays (a sweep over them compiles once), the rest are
    static. Unknown arguments are a `ValueError` naming the known options.

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
