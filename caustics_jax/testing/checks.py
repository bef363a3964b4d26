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
