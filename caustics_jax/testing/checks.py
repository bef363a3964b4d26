"""Assertions every solver test shares."""

from __future__ import annotations

import numpy as np

from .oracle import inside_triangle


def assert_solution_sane(sol, tol: float, slack: float) -> None:
    """No NaN/Inf in any field, `found` exactly where `status == FOUND` (a named code),
    `|residual| <= tol` where found, and the returned barycentrics inside the face up to
    `slack`."""
    from ..solvers import Status

    for name in ("point", "barycentric", "residual", "start_point", "iterations", "crossed"):
        assert np.all(np.isfinite(np.asarray(getattr(sol, name)))), name
    status = np.asarray(sol.status)
    assert set(np.unique(status)) <= {s.value for s in Status}
    found = np.asarray(sol.found)
    np.testing.assert_array_equal(found, status == Status.FOUND)
    assert np.all(np.abs(np.asarray(sol.residual)[found]) <= tol)
    assert np.all(inside_triangle(np.asarray(sol.barycentric)[found], slack))


#: Fields two schedules of the same per-lane iteration must give exactly.
DISCRETE_FIELDS = ("status", "found", "triangle", "iterations", "crossed")


def lane_ulps(a, b) -> np.ndarray:
    """Per-lane distance of two float arrays `(N, ...)` in units of the dtype's epsilon at
    the lane's magnitude (its largest absolute entry in either, at least 1)."""
    a, b = np.asarray(a), np.asarray(b)
    eps = np.finfo(a.dtype).eps
    if a.size == 0:
        return np.zeros(len(a))
    lanes = a.reshape(len(a), -1), b.reshape(len(b), -1)
    scale = np.maximum(np.maximum(np.abs(lanes[0]).max(-1, initial=0), np.abs(lanes[1]).max(-1, initial=0)), 1.0)
    return np.abs(lanes[0] - lanes[1]).max(-1, initial=0) / (eps * scale)


def assert_same_lanes(a, b, fields, *, ulps: float = 64) -> None:
    """Two runs of the same per-lane arithmetic in differently shaped programs (the walk's
    slot pool against its chunked scheduler): discrete fields (`DISCRETE_FIELDS`) equal,
    float fields within `ulps` epsilons of each lane's magnitude (`lane_ulps`).

    Not bit-identity: XLA generates each program's kernels separately, and their vector
    code may contract or order operations differently: points, barycentrics and residuals
    of a lane may move by a few epsilons while its statuses and iteration counts stay the
    same. `ulps = 64` leaves a factor 7 over the largest such difference seen between the
    pool and the chunked scheduler (docs/solvers.md, "Measurements behind the code").
    Residuals (`f`, a sine of unit vectors) carry an absolute rounding of a few epsilons
    whatever their value, so they are compared at magnitude 1 too; a change of `found` or
    `status` is caught exactly. A NaN must be in both runs.
    """
    for name in fields:
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        if name in DISCRETE_FIELDS or not np.issubdtype(x.dtype, np.floating):
            np.testing.assert_array_equal(x, y, err_msg=name)
            continue
        assert x.shape == y.shape and x.dtype == y.dtype, (name, x.shape, y.shape, x.dtype, y.dtype)
        np.testing.assert_array_equal(np.isnan(x), np.isnan(y), err_msg=f"{name}: NaN in one run only")
        d = lane_ulps(np.nan_to_num(x), np.nan_to_num(y))
        bad = np.flatnonzero(~(d <= ulps))  # (inf - inf is NaN: a failure too)
        assert bad.size == 0, f"{name}: {bad.size} lanes differ by more than {ulps} eps of their magnitude " \
                              f"(lanes {bad[:5].tolist()}, {d[bad[:5]].round(1).tolist()} eps)"
