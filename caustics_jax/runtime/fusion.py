"""Values a lane program computes once: the XLA:CPU fusion workaround, in one place.

XLA's CPU fusion copies a chain of cheap element-wise operations (compares, selects,
adds) into every kernel that reads its result. A solver step whose ~25 state fields all
depend on the same decisions (found? bracketed? which exit?) then recomputes those
decisions in each field's kernel: the walk's crossing step compiled to 7,309 fused
instructions at 512 lanes for a formula count of 890 FLOPs (docs/solvers.md "Formula
count"). `jax.lax.optimization_barrier` does not stop it
(XLA's CPU pipeline removes barriers before fusion); a reduction does, since a reduce
is the root of its kernel and its consumers read the stored result.

`stored(tree)` passes every leaf through such a reduction, exactly: the leaf's bits as
an unsigned integer summed with zero (integer addition, so every float, `-0.0` and NaN
included, comes back bit for bit). Call it on the values many outputs share, right where
they are decided (`solvers.walk_steps`); docs/solvers.md "Stored decisions" has the
measurements. On other backends it costs one integer add per element (not measured
there).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["stored"]

_UINT = {1: jnp.uint8, 2: jnp.uint16, 4: jnp.uint32, 8: jnp.uint64}


def _stored_leaf(x):
    x = jnp.asarray(x)
    if x.dtype == jnp.bool_:
        bits = x.astype(jnp.uint8)
    else:
        bits = jax.lax.bitcast_convert_type(x, _UINT[x.dtype.itemsize])
    kept = jnp.sum(jnp.stack([bits, jnp.zeros_like(bits)], -1), axis=-1, dtype=bits.dtype)
    if x.dtype == jnp.bool_:
        return kept != 0
    return jax.lax.bitcast_convert_type(kept, x.dtype)


def stored(tree):
    """`tree` unchanged, bit for bit, with each leaf computed once by XLA:CPU (module
    docstring)."""
    return jax.tree.map(_stored_leaf, tree)
