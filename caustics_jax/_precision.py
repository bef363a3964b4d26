"""float64 on request: the package never flips `jax_enable_x64` as an import side effect."""

from __future__ import annotations

import contextlib

import jax
import jax.numpy as jnp


def enable_x64(enabled: bool = True) -> None:
    """Turn 64-bit JAX types on (or off) process-wide. Call it once, before any array work."""
    jax.config.update("jax_enable_x64", bool(enabled))


@contextlib.contextmanager
def precision(dtype):
    """Context in which `dtype` ("float32" or "float64") is available and the default.

    >>> with precision("float64"):
    ...     x = jnp.zeros(3)  # float64 inside, float32 default outside
    """
    dtype = jnp.dtype(dtype)
    if dtype not in (jnp.dtype("float32"), jnp.dtype("float64")):
        raise ValueError(f"precision must be float32 or float64, got {dtype}")
    with jax.enable_x64(dtype == jnp.dtype("float64")):
        yield dtype


def check_float_dtype(dtype) -> jnp.dtype:
    """Validate a dtype argument at the API boundary, and that float64 is really on."""
    dtype = jnp.dtype(dtype)
    if dtype == jnp.dtype("float64") and not jax.config.jax_enable_x64:
        raise ValueError(
            "float64 requested but jax_enable_x64 is off: wrap the call in "
            "`caustics_jax.precision('float64')` or call `caustics_jax.enable_x64()` first"
        )
    if dtype not in (jnp.dtype("float32"), jnp.dtype("float64")):
        raise ValueError(f"dtype must be float32 or float64, got {dtype}")
    return dtype


def default_float_dtype(like, dtype=None) -> jnp.dtype:
    """The float dtype of a new array: `dtype` when given (validated), float32 when `like`
    is float32, else float64 when x64 is on and float32 otherwise."""
    if dtype is not None:
        return check_float_dtype(dtype)
    in_dtype = getattr(like, "dtype", None)
    if in_dtype is not None and jnp.dtype(in_dtype) == jnp.dtype("float32"):
        return jnp.dtype("float32")
    return jnp.dtype("float64") if jax.config.jax_enable_x64 else jnp.dtype("float32")
