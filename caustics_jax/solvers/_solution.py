"""The result type shared by every solver, and its named status codes."""

from __future__ import annotations

import enum

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int


class Status(enum.IntEnum):
    """Why a lane ended. `Status.explain(code)` gives the message; arrays hold the int value."""

    FOUND = 0
    NO_CROSSING = 1
    TOTAL_INTERNAL_REFLECTION = 2
    LEFT_MESH = 3
    MAX_STEPS = 4
    UNRESOLVED_ELLIPSE = 5
    DEGENERATE = 6
    LOST_CURVE = 7
    NOT_CONVERGED = 8
    NO_SOLUTION = 9

    @property
    def message(self) -> str:
        return _MESSAGES[self]

    @classmethod
    def explain(cls, code: int) -> str:
        return f"{cls(int(code)).name}: {cls(int(code)).message}"


_MESSAGES = {
    Status.FOUND: "a refracted path was found; its residual is within tolerance",
    Status.NO_CROSSING: "the segment P -> L does not cross the surface: no start point M0",
    Status.TOTAL_INTERNAL_REFLECTION: (
        "the search reached a point where light from P is totally internally reflected"),
    Status.LEFT_MESH: "the search crossed a boundary edge of the surface",
    Status.MAX_STEPS: "the iteration cap was reached before convergence",
    Status.UNRESOLVED_ELLIPSE: (
        "the curve is an ellipse inside the first triangle and f did not change sign on it"),
    Status.DEGENERATE: (
        "degenerate input: singular conic at the start point, or P/L on the surface"),
    Status.LOST_CURVE: "the curve has no exit from the current triangle (tangency or rounding)",
    Status.NOT_CONVERGED: "the iteration stopped (bracket or step too small) above tolerance",
    Status.NO_SOLUTION: ("no refraction point: none on the whole mesh (exhaustive reference) or on the traced "
                         "curve (solutions=\"all\" with the walk)"),
}


class Solution(eqx.Module):
    """Per-lane result of `caustics_jax.solve`.

    Attributes:
        point: `(N, 3)` refraction point `M` on the surface.
        triangle: `(N,)` face index of `M` (-1 where no start point exists).
        barycentric: `(N, 2)` `(a, b)` of `M` in that face.
        found: `(N,)` True exactly where `status == Status.FOUND`.
        status: `(N,)` int32 `Status` code.
        iterations: `(N,)` solver iterations (triangle crossings plus refinement steps).
        residual: `(N,)` signed sine (seed 001 eq. 21) at `point`, with the "plane" sign
            (`signed_sine(..., orientation="plane")`; the default "tangent" sign can be the
            opposite: only `abs(residual)` is comparable across orientations).
        crossed: `(N,)` triangles entered after the start triangle.
        start_point: `(N, 3)` the start point `M0`.
    """

    point: Float[Array, "N 3"]
    triangle: Int[Array, " N"]
    barycentric: Float[Array, "N 2"]
    found: Bool[Array, " N"]
    status: Int[Array, " N"]
    iterations: Int[Array, " N"]
    residual: Float[Array, " N"]
    crossed: Int[Array, " N"]
    start_point: Float[Array, "N 3"]

    def summary(self) -> dict[str, int]:
        """Lane counts per status name (host-side)."""
        import numpy as np

        codes, counts = np.unique(np.asarray(self.status), return_counts=True)
        return {Status(int(c)).name: int(n) for c, n in zip(codes, counts, strict=True)}


def confirm_found(status, residual, tol):
    """`status` with `FOUND` kept only where the reported `|residual| <= tol`, else
    `NOT_CONVERGED` (inside jit).

    A solver accepts a point when `|f| <= tol` inside its loop; the reported residual is `f`
    evaluated again at the returned point in a batch of another vector width, where XLA may
    round it differently (a float32 lane accepted at `|f| = 9.99e-6` was reported at
    `1.002e-5` with `tol = 1e-5`). `found` must mean `|residual| <= tol` exactly
    (DESIGN.md's contract), so a lane on that rounding edge is reported as not converged.
    """
    return jnp.where((status == Status.FOUND) & ~(jnp.abs(residual) <= tol), Status.NOT_CONVERGED,
                     status).astype(jnp.int32)
