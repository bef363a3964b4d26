"""The adaptive photon budget of seed 003 ("Adaptive sampling", Fig. 6), in light space.

Seed 003 keeps feedback buffers in light-view space: each stored photon adds its
screen-space footprint area to the texel it was emitted through, and the next frame's
photons are allocated from them ("high density and closeup regions receive more photons
with smaller size"), the previous frame's buffer mixed in for temporal stability. The
testbed has no camera, so the footprint is taken on the receiver: a photon landing in a
receiver cell holding `h` photons stands for `cell_area / h` of it (the caller bins these
per texel, `experiments/budget.py`), and a texel's `footprint` is the receiver area its
photons cover. Allocating in proportion to it (`gamma = 1`) gives every part of the receiver
the same photon density, the seed's target; `gamma = 0` is uniform in light space over
the texels that reach the receiver, and `gamma` between trades the two (docs/claims.md
"Adaptive photon budget" measures which minimises which error). The history is mixed in by
seed 000 eq. 2's EMA (`kernels.temporal_ema`).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..runtime.kernel_contract import float_inputs
from ._util import as_float, float_dtype

#: Share of the budget spread uniformly over every texel, so that none goes unsampled (a
#: texel whose photons all missed the receiver last frame may reach it in this one).
BUDGET_FLOOR = 0.25


@float_inputs("footprint", params=("total", "gamma", "floor"), nonnegative=("total", "gamma"),
              bounds={"floor": (0, 1)})
def photon_budget(footprint: Float[Array, "*texels"], total, gamma=1.0, floor=BUDGET_FLOOR) -> Float[Array, "*texels"]:
    """Expected photons per light-space texel for the next frame (seed 003 Fig. 6).

    `n = total (floor / T + (1 - floor) w / sum(w))`, `w = footprint^gamma` where the
    footprint is positive (0 elsewhere), `T` the number of texels (every axis of
    `footprint` counts). Sums to `total`; with no positive footprint the whole budget is
    uniform. A NaN or negative footprint counts as 0. Rounding to whole photons is the
    caller's (a texel with `n >= 1` photons, each standing for `1/n` of its area, keeps
    the estimate unbiased).
    """
    dtype = float_dtype(footprint)
    s = jnp.asarray(footprint, dtype)
    gamma, floor, total = as_float(gamma, dtype), as_float(floor, dtype), as_float(total, dtype)
    positive = s > 0
    w = jnp.where(positive, jnp.where(positive, s, 1) ** gamma, 0)
    w_sum = jnp.sum(w)
    size = max(s.size, 1)  # (an empty buffer allocates nothing)
    share = jnp.where(w_sum > 0, w / jnp.where(w_sum > 0, w_sum, 1), 1 / size)
    floor = jnp.where(w_sum > 0, floor, 1)
    return total * (floor / size + (1 - floor) * share)
