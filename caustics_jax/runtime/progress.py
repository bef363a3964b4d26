"""Progress bars for long runs (tqdm), drawn only on a terminal.

`progress(iterable, desc=...)` is `tqdm.tqdm` with `disable=None`: tqdm then draws on
stderr only when stderr is a terminal, so pipes, CI logs, pytest's captured output and
Jupyter kernels (whose stderr is not a terminal) stay quiet, and stdout keeps only
tables and results. `CAUSTICS_JAX_PROGRESS=0` switches bars off everywhere,
`CAUSTICS_JAX_PROGRESS=1` forces them on (e.g. to watch a run in a notebook); tqdm's own
`TQDM_DISABLE=1` works too.

The long runs that use it: `caustics-jax compare`/`demo` (one step per configuration and
dtype), `caustics-jax export` (one per kernel), `photon_irradiance` (one per chunk of
photons), the stress suite (`experiments/stability.py`, one per category) and the
scaling study (`experiments/scaling.py`, one per tessellation and dtype).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable

from tqdm import tqdm

ENV = "CAUSTICS_JAX_PROGRESS"


def enabled() -> bool | None:
    """tqdm's `disable` argument, negated: True/False when `CAUSTICS_JAX_PROGRESS` forces
    bars on/off, None to let tqdm decide (on when stderr is a terminal)."""
    value = os.environ.get(ENV, "").strip().lower()
    if value in ("0", "false", "no", "off"):
        return False
    if value in ("1", "true", "yes", "on"):
        return True
    return None


def _disable() -> bool | None:
    on = enabled()
    if on is None:
        # tqdm's disable=None tests the stream it writes to; say so explicitly for stderr
        # replaced by an object without isatty (some notebook front ends, loggers).
        isatty = getattr(sys.stderr, "isatty", None)
        return None if isatty is not None else True
    return not on


def progress(iterable: Iterable | None = None, *, desc: str | None = None, total: int | None = None,
             unit: str = "it", leave: bool = False, unit_scale: bool = False) -> tqdm:
    """A tqdm bar over `iterable` (or a manual one with `total` and `.update(n)`), on a
    terminal only (module docstring). Use as `for x in progress(xs, desc="export"): ...`
    or `with progress(total=n, desc="photons") as bar: ... bar.update(k)`."""
    return tqdm(iterable, desc=desc, total=total, unit=unit, unit_scale=unit_scale, leave=leave, disable=_disable(),
                dynamic_ncols=True, file=sys.stderr)
