"""The options contract every solver shares: validation at the API boundary, the static /
traced split, and the acceptance tolerance.

Each solver is an equinox Module of its options (`Walk`, `Newton`, `Exhaustive`,
`Trace`), in the style of optimistix's solver objects: hashable (a static argument of
jit), every field declared with `option(default, check)`, whose converter validates and
canonicalises the value when the object is built (cross-field rules in
`__check_init__`), raising a `ValueError` that names the argument and its valid range
before any jitted work (docs/input_contract.md). An unknown option is a `ValueError`
naming the known ones.

Acceptance: a lane is FOUND when `|f| <= tol` for the signed sine `f` (seed 001 eq. 21),
the sine of the angle between the refracted direction and `w_L`. `f` lies in `[-1, 1]`,
so a `tol` of 1 or more accepts every point: `tol` must lie in `(0, 1)`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp

from ..runtime.arguments import check_choice
from ..runtime.lane_solver import SCHEDULERS

__all__ = ["SolverOptions", "default_tol", "option", "scheduler_option"]


def default_tol(dtype) -> float:
    """Default acceptance `|f| <= tol`: 1e-10 in float64, 1e-5 in float32 (the float32
    audit's noise floor of `f` is about 1e-6, docs/conic.md)."""
    return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 1e-5


def option(default, check: Callable[[Any], Any]) -> Any:
    """A solver option: its default and `check(value)`, which returns the canonical value or
    raises a `ValueError` (the `runtime.arguments` checks). Static: part of jit's key."""
    return eqx.field(default=default, converter=check, static=True)


def scheduler_option() -> Any:
    """The `scheduler` option of the lane solvers: how the runtime schedules their lanes
    (`runtime.lane_solver.SCHEDULERS`: "pool", the default, or "chunked")."""
    return option("pool", lambda v: check_choice("scheduler", v, SCHEDULERS))


class _KnownOptions(type(eqx.Module)):  # type: ignore[misc]
    """Metaclass of the solver objects: an unknown or surplus argument is a `ValueError`
    naming the known options, as `solve(method="walk", foo=1)` says (a dataclass
    constructor would raise Python's `TypeError`)."""

    def __call__(cls, *args, **kwargs):
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(kwargs) - set(known))
        if unknown:
            raise ValueError(f"unknown {cls.method or cls.__name__} option(s) {unknown}; known: {known}")
        if len(args) > len(known):
            raise ValueError(f"{cls.__name__} takes at most {len(known)} options ({known}), got {len(args)} "
                             "positional arguments")
        return super().__call__(*args, **kwargs)


class SolverOptions(eqx.Module, metaclass=_KnownOptions):
    """Base of the solver objects: `method` names it for `solve(method=...)`; the fields in
    `traced` are passed to jit as arrays (a sweep over them compiles once), the rest are
    static."""

    method: ClassVar[str] = ""
    traced: ClassVar[tuple[str, ...]] = ()
    #: Options that only the host reads (what `solve` does around the compiled program):
    #: left out of `static`, so they compile nothing.
    host: ClassVar[tuple[str, ...]] = ()

    def with_options(self, **changes):
        """A copy with the options `changes` replaced (validated like the original)."""
        return dataclasses.replace(self, **changes)

    def static(self):
        """The options with the traced fields at their defaults: the hashable part jit
        compiles for (the program reads the traced values from its array arguments; the
        host options are not the program's)."""
        return self.with_options(**{f.name: f.default for f in dataclasses.fields(self)
                                    if f.name in self.traced + self.host})

    #: Whether `solve` runs this solver in blocks of lanes (`solve_block`: the walk and
    #: Newton) or on the whole batch at once (`solve_whole`: `Exhaustive`, `Trace`).
    in_blocks: ClassVar[bool] = True

    #: Whether `solve` may settle a lane on a flat surface in closed form (docs/features.md).
    flat_closed_form: ClassVar[bool] = False

    def solve_block(self, mesh, P, L, eta, start, lane_id):
        """The solver on one block of lanes (`solve` runs every batch in blocks of one size):
        a `Solution`. Only the block solvers (walk, Newton) have one; `solve` runs
        `Exhaustive` and `Trace` whole (`solve_whole`)."""
        raise TypeError(f"{type(self).__name__} is not solved in blocks (solve_whole)")

    def every_path(self) -> bool:
        """Whether `solve` returns every path per receiver (an `ExhaustiveSolution`)."""
        return False

    def check_dtype(self, dtype) -> None:
        """A `ValueError` where this solver cannot run in `dtype` (default: every dtype)."""
        del dtype

    def solve_whole(self, prep, P, L, eta, start):
        """The result of a solver that runs on the whole batch at once (`in_blocks` False),
        given the prepared surface `prep` (local frame), validated lanes and their start
        points `(face, barycentric, found)`."""
        raise TypeError(f"{type(self).__name__} is solved in blocks (solve_block)")

    def fallbacks(self, dtype) -> tuple[SolverOptions, ...]:
        """The solvers that retry, in turn, the lanes this one ends without a path (none)."""
        del dtype
        return ()

    def tolerance(self, dtype) -> float:
        tol = getattr(self, "tol", None)
        return default_tol(dtype) if tol is None else tol
