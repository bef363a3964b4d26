"""Fixed-point 4.28 accumulation with 32-bit integer atomics (seed 000 §3.2; math.md §8).

Seed 000 accumulates photon flux into each collection point with `InterlockedAdd` on a
32-bit unsigned integer holding 4 integer and 28 fractional bits. Integer addition is
associative (modulo 2^32), so the result does not depend on the order in which the GPU
threads land, unlike float32 atomics; the price is a quantisation step of 2^-28 per
addend and a hard ceiling of 16 on the sum, above which the hardware silently wraps.

`fixed_point_accumulate` reproduces the wrapped 32-bit result bit for bit and, which
the hardware cannot, reports the overflow.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, UInt32

from ..runtime.kernel_contract import check_domain, float_inputs
from ._util import static_int

FRACTION_BITS = 28
SCALE = 2**FRACTION_BITS
#: Largest representable value, (2^32 - 1) / 2^28, just below 16: the overflow bound.
MAX_VALUE = (2**32 - 1) / SCALE
#: Quantisation step of one addend, 2^-28; round-to-nearest keeps each error within half.
RESOLUTION = 1.0 / SCALE
# Byte-wise partial sums are exact while a segment receives at most 2^24 addends.
_MAX_ADDENDS = 2**24


class FixedPointSum(eqx.Module):
    """Per-segment result of `fixed_point_accumulate`.

    Attributes:
        code: the 32-bit word the GPU would hold after all atomic adds (wrapped mod 2^32).
        overflow: True where the exact sum of codes reached 2^32 (the hardware wrapped).
        value: `code` decoded to the input dtype (meaningless where `overflow`).
    """

    code: UInt32[Array, " segments"]
    overflow: Bool[Array, " segments"]
    value: Float[Array, " segments"]


@float_inputs("x", nonnegative=("x",))
def fixed_point_encode(x: Float[Array, "*batch"]) -> UInt32[Array, "*batch"]:
    """Float to unsigned 4.28 fixed point, round to nearest (seed 000 §3.2).

    Values are clipped to `[0, MAX_VALUE]`; negative input raises ValueError outside jit,
    since flux is non-negative and an unsigned word cannot hold it.
    """
    x = jnp.asarray(x)
    dtype = x.dtype if jnp.issubdtype(x.dtype, jnp.floating) else jnp.float32
    x = x.astype(dtype)
    # Scaling by 2^28 is exact in either precision. The ceiling is the largest float of
    # this dtype that still fits in 32 bits (2^32 - 256 in float32), so the cast is defined.
    ceiling = jnp.nextafter(jnp.asarray(2.0**32, dtype), jnp.asarray(0, dtype))
    scaled = jnp.clip(jnp.round(x * jnp.asarray(SCALE, dtype)), 0, ceiling)
    return scaled.astype(jnp.uint32)


@float_inputs(ints=("code",), dtype_arg="dtype")
def fixed_point_decode(code: UInt32[Array, "*batch"], dtype=jnp.float32) -> Float[Array, "*batch"]:
    """Unsigned 4.28 fixed point to float of `dtype` (seed 000 §3.2).

    `code` holds 32-bit words: outside jit a value outside `[0, 2^32 - 1]` is refused (the
    cast to `uint32` would wrap it: -1 decoded as 16).
    """
    code = jnp.asarray(code, dtype=jnp.uint32)
    return code.astype(dtype) * jnp.asarray(RESOLUTION, dtype)


@float_inputs("x", ints=("segment_ids",))
def fixed_point_accumulate(
    x: Float[Array, " n"],
    segment_ids: Int[Array, " n"] | None = None,
    num_segments: int = 1,
) -> FixedPointSum:
    """Sum of `x` per segment as 32-bit 4.28 integer atomics would leave it (seed 000 §3.2).

    Each value is encoded, then added into its segment's 32-bit word with wrap-around,
    exactly like `InterlockedAdd`; the result is independent of the order of `x`.
    Overflow (the exact integer sum reaching 2^32, i.e. a sum of 16 or more) is detected
    by summing the four bytes of every code separately, which is exact in 32-bit
    arithmetic for up to 2^24 addends per segment, and propagating the carries.
    """
    num_segments = static_int("fixed_point_accumulate", "num_segments", num_segments, 1, 2**24)
    x = jnp.asarray(x)
    if x.ndim != 1:
        raise ValueError(f"fixed_point_accumulate: x must be 1-D, got shape {x.shape}")
    if x.shape[0] > _MAX_ADDENDS:
        raise ValueError(f"fixed_point_accumulate: at most 2^24 addends supported, got {x.shape[0]}")
    if segment_ids is None:
        segment_ids = jnp.zeros(x.shape, jnp.int32)
    segment_ids = jnp.asarray(segment_ids)
    if segment_ids.shape != x.shape:
        raise ValueError(f"fixed_point_accumulate: segment_ids shape {segment_ids.shape} != x shape {x.shape}")
    check_domain("fixed_point_accumulate", "segment_ids", segment_ids, lo=0, hi=num_segments - 1, integer=True)
    codes = fixed_point_encode(x)

    def byte_sum(k):
        b = (codes >> jnp.uint32(8 * k)) & jnp.uint32(0xFF)
        return jax.ops.segment_sum(b, segment_ids, num_segments=num_segments)

    s0 = byte_sum(0)
    s1 = byte_sum(1) + (s0 >> 8)
    s2 = byte_sum(2) + (s1 >> 8)
    s3 = byte_sum(3) + (s2 >> 8)
    mask = jnp.uint32(0xFF)
    code = (
        ((s3 & mask) << 24) | ((s2 & mask) << 16) | ((s1 & mask) << 8) | (s0 & mask)
    ).astype(jnp.uint32)
    dtype = x.dtype if jnp.issubdtype(x.dtype, jnp.floating) else jnp.float32
    return FixedPointSum(code=code, overflow=s3 > mask, value=fixed_point_decode(code, dtype))
