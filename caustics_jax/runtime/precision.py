"""float64 on request: the package never flips `jax_enable_x64` as an import side effect."""

from __future__ import annotations

import contextlib

import jax
import jax.numpy as jnp
import numpy as np


def enable_x64(enabled: bool = True) -> None:
    """Turn 64-bit JAX types on (or off) process-wide. Call it once, before any array work.

    `enabled` is True or False (a string such as "no" is a `ValueError`: `bool("no")` is True)."""
    if not isinstance(enabled, bool | np.bool_):
        raise ValueError(f"enable_x64: enabled must be True or False, got {enabled!r}")
    jax.config.update("jax_enable_x64", bool(enabled))


@contextlib.contextmanager
def precision(dtype):
    """Context in which `dtype` ("float32" or "float64") is available and the default.

    >>> with precision("float64"):
    ...     x = jnp.zeros(3)  # float64 inside, float32 default outside
    """
    given = dtype
    try:
        dtype = jnp.dtype(dtype) if dtype is not None else None
    except (TypeError, ValueError):
        dtype = None
    if dtype is None or dtype not in (jnp.dtype("float32"), jnp.dtype("float64")):  # (np.dtype(None) is float64)
        raise ValueError(f"precision must be 'float32' or 'float64', got {given!r}")
    with jax.enable_x64(dtype == jnp.dtype("float64")):
        yield dtype


def check_float_dtype(dtype) -> jnp.dtype:
    """Validate a dtype argument at the API boundary, and that float64 is really on."""
    try:
        dtype = jnp.dtype(dtype)
    except (TypeError, ValueError):
        raise ValueError(f"dtype must be float32 or float64, got {dtype!r}") from None
    if dtype == jnp.dtype("float64") and not jax.config.jax_enable_x64:
        raise ValueError(
            "float64 requested but jax_enable_x64 is off: wrap the call in "
            "`caustics_jax.precision('float64')` or call `caustics_jax.enable_x64()` first"
        )
    if dtype not in (jnp.dtype("float32"), jnp.dtype("float64")):
        raise ValueError(f"dtype must be float32 or float64, got {dtype}")
    return dtype


def check_mesh_dtype(dtype, name: str = "mesh") -> None:
    """A `ValueError` when `name` (a mesh or another stored input) holds float64 while
    `jax_enable_x64` is off: it was built inside `precision("float64")` and is used outside
    it, where every new array (the points passed with it) is float32. Without this check
    the first error was a misleading "P is float32 but the mesh is float64"."""
    if jnp.dtype(dtype) == jnp.dtype("float64") and not jax.config.jax_enable_x64:
        raise ValueError(
            f"the {name} is float64 but jax_enable_x64 is off (was it built inside "
            "`caustics_jax.precision('float64')`?): use it inside that context too, call "
            f"`caustics_jax.enable_x64()`, or cast it to float32 ({name}.astype('float32'))"
        )


def default_float_dtype(like, dtype=None) -> jnp.dtype:
    """The float dtype of a new array: `dtype` when given (validated), float32 when `like`
    is float32 or a half precision (float16, bfloat16: computed in float32, as the
    kernels do), else float64 when x64 is on and float32 otherwise."""
    if dtype is not None:
        return check_float_dtype(dtype)
    in_dtype = getattr(like, "dtype", None)
    if in_dtype is not None and jnp.issubdtype(in_dtype, jnp.floating) and jnp.dtype(in_dtype).itemsize <= 4:
        return jnp.dtype("float32")
    return jnp.dtype("float64") if jax.config.jax_enable_x64 else jnp.dtype("float32")


# --------------------------------------------------------------------------- kernel input dtypes
# (docs/input_contract.md, "Kernels"). One rule for every public kernel, applied by
# `float_inputs` at its entry:
#
# - integers (and Python numbers) are values, not a precision: they take the float dtype
#   of the other inputs, or the default float (float64 under x64, else float32);
# - float16 / bfloat16 (and the float8 types) are computed in float32: the kernels'
#   thresholds are scaled to float32/float64 epsilons and nothing here is tuned for half
#   precision, so a half result would be silently wrong (e.g. 4.28 fixed point overflows
#   float16's 65504);
# - float32 and float64 promote as JAX does (float64 wins, when x64 is on);
# - parameters (`eta`, `t_max`, ...) follow the arrays' dtype and never set it, so a
#   float64 `eta` leaves a float32 kernel in float32 and an integer array never truncates
#   a parameter;
# - bool, complex and non-numeric input is refused with a ValueError naming the argument.

_HALF_KINDS = ("float16", "bfloat16")


def dtype_of(x):
    """dtype of an array-like, without copying jax arrays or tracers."""
    dtype = getattr(x, "dtype", None)
    if dtype is not None and not isinstance(x, type):
        return jnp.dtype(dtype)
    return np.asarray(x).dtype


def real_input_dtype(name: str, x):
    """The float dtype `x` asks for: None for integers and Python numbers (they take the
    dtype of the rest), float32 for half precisions, float32/float64 otherwise.

    Raises `ValueError` naming `name` for bool, complex and non-numeric input.
    """
    if isinstance(x, bool | np.bool_):
        raise ValueError(f"{name} must be a real number (or an array of them), got the bool {x!r}")
    if isinstance(x, int | float):
        return None
    try:
        dtype = dtype_of(x)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real number or an array of real numbers, got "
                         f"{type(x).__name__} ({exc})") from None
    if dtype == np.bool_:
        raise ValueError(f"{name} must hold real numbers, got dtype bool")
    if jnp.issubdtype(dtype, jnp.integer):
        return None
    if not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(f"{name} must hold real numbers (integer or float), got dtype {dtype}")
    if dtype.itemsize < 4 or dtype.name in _HALF_KINDS:
        return jnp.dtype("float32")
    if dtype.itemsize > 8:  # long double: the widest float JAX has
        dtype = jnp.dtype("float64")
    return jnp.dtype(jax.dtypes.canonicalize_dtype(dtype))


def result_float_dtype(*named) -> jnp.dtype:
    """Float dtype of a kernel's result from `(name, value)` pairs (rules above)."""
    dtypes = [d for d in (real_input_dtype(n, x) for n, x in named) if d is not None]
    if not dtypes:
        return jnp.dtype(jax.dtypes.canonicalize_dtype(jnp.float64))
    return jnp.dtype(jnp.result_type(*dtypes))


def as_float(*arrays, dtype=None):
    """`arrays` as jax arrays of one float dtype: `dtype` when given, else by the rules
    above (`result_float_dtype`). Returns a tuple (one array per argument)."""
    named = [(f"argument {i}", x) for i, x in enumerate(arrays)]
    if dtype is None:
        dtype = result_float_dtype(*named)
    else:
        for n, x in named:
            real_input_dtype(n, x)
    return tuple(jnp.asarray(x, dtype) for x in arrays)
