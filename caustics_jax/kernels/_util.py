"""Private helpers shared by the kernel modules: dtype handling, boundary checks, safe math."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..runtime.arguments import check_int, check_real


def float_dtype(*xs):
    """Result float dtype of the array arguments; Python scalars stay weak and never promote."""
    dtype = jnp.result_type(*xs)
    return dtype if jnp.issubdtype(dtype, jnp.floating) else jnp.result_type(float)


def as_float(x, dtype):
    return jnp.asarray(x, dtype=dtype)


def concrete(x):
    """`x` as a NumPy array when it is known outside jit, else None (a tracer)."""
    if isinstance(x, jax.core.Tracer):
        return None
    return np.asarray(x)


def check_last_axis(x, name: str, size: int) -> None:
    shape = np.shape(x)
    if len(shape) == 0 or shape[-1] != size:
        raise ValueError(f"{name} must have last axis of size {size}, got shape {shape}")


def _refuse_tracer(fn_name: str, name: str, value) -> None:
    if isinstance(value, jax.core.Tracer):
        raise ValueError(f"{fn_name}: {name} is static configuration (a Python number), got a traced "
                         f"value; pass it as a static argument (jax.jit(..., static_argnames={name!r}))")


def static_int(fn_name: str, name: str, value, lo: int, hi: int) -> int:
    """`arguments.check_int` for a static argument (a map size, a count, an axis): a clear
    ValueError for a tracer, where `check_int` would fail inside `int()`."""
    _refuse_tracer(fn_name, name, value)
    return check_int(name, value, lo, hi)


def static_real(fn_name: str, name: str, value, lo: float, **kw) -> float:
    """`arguments.check_real` for a static argument, with a clear ValueError for a tracer."""
    _refuse_tracer(fn_name, name, value)
    return check_real(name, value, lo, **kw)


def tiny(dtype):
    """Smallest normal number of `dtype`: the floor for a positive scale inside jit."""
    return jnp.asarray(jnp.finfo(dtype).tiny, dtype)


def ratio_scale(v, s):
    """A common scale for a vector `v` (`*batch 3`) and a length `s` (`*batch`): the largest
    of `|v_i|` and `|s|` (1 where all are 0), outside the gradient.

    Kernels of `|v|^2 / s^2` (a bandwidth, a radius) depend on the ratio only; dividing both
    by this scale first keeps the squares in range where `v . v` or `s^2` alone would
    underflow (0/0) or overflow (inf/inf). The value does not depend on the scale, so
    stopping its gradient leaves the derivatives exact and finite.
    """
    m = jnp.maximum(jnp.max(jnp.abs(v), axis=-1), jnp.abs(s))
    return jax.lax.stop_gradient(jnp.where(m > 0, m, 1))


def tan_half(angle):
    """`tan(angle / 2)` for a cone's full angle, the angle clipped to `[0, pi)`.

    The largest half-angle kept is the dtype's float below `pi / 2` (float32's `pi / 2`
    rounds above it, where `tan` is negative), so the result is finite and non-negative:
    inside jit an angle of `pi` or more (not checked there) gives a very wide cone, never
    a negative width.
    """
    dtype = jnp.result_type(angle)
    half_max = jnp.nextafter(jnp.asarray(jnp.pi / 2, dtype), jnp.asarray(0, dtype))
    return jnp.tan(jnp.clip(angle / 2, 0, half_max))


def safe_div(num, den):
    """`num / den`, and 0 (value and gradient finite) where `den == 0`."""
    ok = den != 0
    return jnp.where(ok, num / jnp.where(ok, den, 1), 0)
