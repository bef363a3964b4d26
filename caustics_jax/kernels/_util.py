"""Private helpers shared by the kernel modules: dtype handling, boundary checks, safe math."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


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


def check(x, name: str, *, lower=None, upper=None, strict=False, finite=True) -> None:
    """Raise ValueError naming `name` when a concrete `x` is out of range or not finite."""
    a = concrete(x)
    if a is None or a.size == 0:
        return
    if finite and not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    if lower is not None and (np.any(a <= lower) if strict else np.any(a < lower)):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {lower}, got min {a.min()}")
    if upper is not None and np.any(a > upper):
        raise ValueError(f"{name} must be <= {upper}, got max {a.max()}")


def check_last_axis(x, name: str, size: int) -> None:
    shape = np.shape(x)
    if len(shape) == 0 or shape[-1] != size:
        raise ValueError(f"{name} must have last axis of size {size}, got shape {shape}")


def safe_div(num, den):
    """`num / den`, and 0 (value and gradient finite) where `den == 0`."""
    ok = den != 0
    return jnp.where(ok, num / jnp.where(ok, den, 1), 0)


def safe_sqrt(x):
    """sqrt of `max(x, 0)` with a finite gradient at and below zero."""
    ok = x > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, x, 1)), 0)
