"""Progress lines and error summaries shared by the comparison job and the experiments."""

from __future__ import annotations

import sys

import numpy as np


def log(msg: str) -> None:
    """One progress line on stderr, flushed (stdout stays for tables and results)."""
    print(msg, file=sys.stderr, flush=True)


def stats(x) -> dict:
    """Median, 99th percentile and maximum of the finite values of `x`, and their count `n`.

    Non-finite values are left out (count them separately where they matter); with no
    finite value, the three statistics are NaN.
    """
    x = np.asarray(x, np.float64).ravel()
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"median": float("nan"), "p99": float("nan"), "max": float("nan"), "n": 0}
    return {"median": float(np.median(x)), "p99": float(np.quantile(x, 0.99)), "max": float(x.max()),
            "n": int(x.size)}
