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
measurements. Booleans of one shape are stored together, up to 32 as the bits of one
word: a reduce-rooted kernel each would compute the comparisons they share once per
boolean, one word computes them once (the walk's refinement step: 62-63 against 39 us
per 256 lanes). On other backends it costs one integer add per element (not measured
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


def _stored_booleans(flags: list) -> list:
    """Boolean arrays of one shape stored together: element-wise, the bits of up to 32 of
    them form a uint32 word (one element-wise chain of shifts and ors), each word is
    stored once, and the booleans are read back from the words. One kernel then computes
    all the decisions of a word, sharing the comparisons they have in common, where one
    stored leaf each is one kernel each, and each of those recomputes the shared chain."""
    out = []
    for lo in range(0, len(flags), 32):
        group = flags[lo:lo + 32]
        if len(group) == 1:  # alone: stored as it is
            out.append(_stored_leaf(group[0]))
            continue
        word = group[0].astype(jnp.uint32)
        for j, f in enumerate(group[1:], start=1):
            word = word | (f.astype(jnp.uint32) << jnp.uint32(j))
        word = _stored_leaf(word)
        out += [(word >> jnp.uint32(j)) & jnp.uint32(1) != 0 for j in range(len(group))]
    return out


def stored(tree):
    """`tree` unchanged, bit for bit, with each leaf computed once by XLA:CPU (module
    docstring); the boolean leaves of one shape are stored together, as the bits of
    shared words (`_stored_booleans`)."""
    leaves, treedef = jax.tree.flatten(tree)
    leaves = [jnp.asarray(x) for x in leaves]
    out = [x if x.dtype == jnp.bool_ else _stored_leaf(x) for x in leaves]
    shapes = dict.fromkeys(x.shape for x in leaves if x.dtype == jnp.bool_)
    for shape in shapes:  # the booleans of each shape together
        at = [i for i, x in enumerate(leaves) if x.dtype == jnp.bool_ and x.shape == shape]
        for i, b in zip(at, _stored_booleans([leaves[i] for i in at]), strict=True):
            out[i] = b
    return jax.tree.unflatten(treedef, out)
