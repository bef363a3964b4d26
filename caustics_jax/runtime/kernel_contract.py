"""The input contract of the public kernels (docs/input_contract.md "Kernels"): the
`float_inputs` decorator that casts and checks a kernel's arguments at its entry, with the
integer, shape and domain checks it applies.

The dtype rules it follows are `precision`'s (`real_input_dtype`, `result_float_dtype`).
"""

from __future__ import annotations

import functools
import inspect

import jax
import jax.numpy as jnp
import numpy as np

from .arguments import check_fits, interval
from .precision import check_float_dtype, dtype_of, real_input_dtype, result_float_dtype


def _check_integer(name: str, x):
    """`x` unchanged when it holds integers; `ValueError` naming `name` otherwise (bool too)."""
    if isinstance(x, bool | np.bool_):
        raise ValueError(f"{name} must hold integers, got the bool {x!r}")
    if isinstance(x, int):
        return x
    try:
        dtype = dtype_of(x)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must hold integers, got {type(x).__name__} ({exc})") from None
    if dtype == np.bool_ or not jnp.issubdtype(dtype, jnp.integer):
        raise ValueError(f"{name} must hold integers, got dtype {dtype}")
    return x


def _python_ints_beyond_numpy(x) -> bool:
    """Whether `x` holds only Python ints, some beyond every numpy integer (`[2**70]`:
    numpy makes it an object array, which `_check_integer` would call "not integers")."""
    try:
        v = np.asarray(x)
    except (TypeError, ValueError):
        return False
    return v.dtype == object and v.size > 0 and all(
        isinstance(e, int) and not isinstance(e, bool) for e in v.reshape(-1))


def as_integer_array(name: str, x, *, unsigned: bool = False):
    """`x` as a JAX integer array, refusing with a ValueError naming `name` what is not
    integers and concrete values that do not fit the dtype JAX gives them: int32 with x64
    off (int64 on), uint32 for 32-bit words (`unsigned`, a `UInt32` annotation).

    `jnp.asarray` refuses a Python int out of range (OverflowError) but wraps a numpy one:
    `np.int64(2**32 + 1)` had become index 1 and `np.uint64(2**32 + 5)` the code 5. A
    tracer, or a JAX array already of a fitting dtype, passes as it is.
    """
    kind = "32-bit words" if unsigned else "indices"
    if isinstance(x, jax.core.Tracer) or (
            isinstance(x, jax.Array) and (not unsigned or jnp.issubdtype(x.dtype, jnp.unsignedinteger))):
        return _check_integer(name, x)  # already in a JAX dtype: nothing can wrap
    dtype = jnp.dtype("uint32") if unsigned else None
    if _python_ints_beyond_numpy(x):
        shown = (dtype or jnp.dtype(jax.dtypes.canonicalize_dtype(np.int64))).name
        raise ValueError(f"{name} must hold integers that fit {shown} ({kind}), got {x!r}")
    v = np.asarray(_check_integer(name, x))
    dtype = dtype or jnp.dtype(jax.dtypes.canonicalize_dtype(v.dtype))
    info = np.iinfo(dtype)
    bad = (v < info.min) | (v > info.max)
    if np.any(bad):
        raise ValueError(f"{name} must hold integers that fit {dtype.name} ({kind}, in [{info.min}, "
                         f"{info.max}]), got {v[bad].reshape(-1)[:3].tolist()}")
    return jnp.asarray(v, dtype)


def _unsigned(annotation) -> bool:
    """Whether a jaxtyping annotation allows unsigned integers only (`UInt32[Array, ...]`)."""
    dtypes = getattr(annotation, "dtypes", None)
    return isinstance(dtypes, list | tuple) and bool(dtypes) and all(str(d).startswith("uint") for d in dtypes)


def _dims(annotation):
    """Trailing-shape spec of a jaxtyping annotation (`Float[Array, "*batch 3"]`), or None."""
    dim_str = getattr(annotation, "dim_str", None)
    if not isinstance(dim_str, str):
        return None
    return dim_str.split()


def _check_shape(fn_name: str, name: str, shape, dims) -> tuple | None:
    """Check `shape` against jaxtyping dims; return the `*batch` part (or None)."""
    variadic = [i for i, d in enumerate(dims) if d.startswith("*")]
    fixed = [d for d in dims if not d.startswith("*")]
    want = " ".join(dims)
    if not variadic:
        ok = len(shape) == len(dims) and all(
            not d.isdigit() or int(d) == s for d, s in zip(dims, shape, strict=False))
        if not ok:
            raise ValueError(f"{fn_name}: {name} must have shape ({want}), got {tuple(shape)}")
        return None
    v = variadic[0]
    head, tail = dims[:v], dims[v + 1:]
    ok = len(shape) >= len(fixed)
    if ok:
        ok = all(not d.isdigit() or int(d) == s for d, s in zip(head, shape[:len(head)], strict=False))
        ok = ok and all(not d.isdigit() or int(d) == s
                        for d, s in zip(tail, shape[len(shape) - len(tail):], strict=False))
    if not ok:
        raise ValueError(f"{fn_name}: {name} must have shape ({want}), got {tuple(shape)}")
    return tuple(shape[len(head):len(shape) - len(tail)]) if dims[v] == "*batch" else None


# What a domain's name means in a message (docs/input_contract.md "Kernels").
_DOMAIN_HINTS = {"eta": " (eta_in / eta_out, water 1.333)", "edge": " (edge k joins vertices k and k + 1 mod 3)",
                 "level": " (a cascade level c)"}


def _number(x) -> str:
    """A bound as written: whole numbers in full (16777215, not 1.67772e+07), others `:g`."""
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def _domain_words(lo, hi, strict: bool, whole: bool, integer: bool, hi_strict: bool = False) -> str:
    """`finite and > 0`, `finite, whole and >= 0`, `in [0, 2]`, `in (0, 1)` (an integer
    argument is finite and whole)."""
    if lo is not None and hi is not None:
        bound = ["in " + interval(lo, hi, strict, hi_strict, number=_number)]
    elif lo is not None:
        bound = [f"{'>' if strict else '>='} {_number(lo)}"]
    else:
        bound = [f"{'<' if hi_strict else '<='} {_number(hi)}"] if hi is not None else []
    parts = ([] if integer else ["finite"] + (["whole"] if whole else [])) + bound
    return ", ".join(parts[:-1]) + " and " + parts[-1] if len(parts) > 1 else parts[0]


def check_domain(fn_name: str, name: str, value, *, lo=None, hi=None, strict: bool = False,
                 hi_strict: bool = False, whole: bool = False, integer: bool = False, dtype=None) -> None:
    """Refuse a concrete argument outside its domain with a ValueError naming `fn_name` and
    `name`: not finite, below `lo` (at `lo` too when `strict`), above `hi` (at `hi` too when
    `hi_strict`), or (`whole`) not a whole number; a tracer (inside jit) passes unchecked
    (the kernel uses `in_domain`). `integer`: an integer argument (the message leaves out
    "finite").

    With `dtype`, the float dtype the kernel casts the value to: a finite value must stay
    finite in it, and a positive one (`lo=0, strict`: a scale, a bandwidth, an index
    ratio) must be a normal number of it. XLA flushes subnormal numbers to zero, so
    `1 / eps` would be inf and `t / t_max` NaN for a value that passed a plain `> 0`
    test (float32 `t_max = 1e-45`); inside jit such a lane fails `in_domain` the same way.
    """
    if isinstance(value, jax.core.Tracer):
        return
    v = np.asarray(value)
    if v.size == 0:
        return
    v64 = v.astype(np.float64)
    bad = ~in_domain(v64, lo=lo, hi=hi, strict=strict, hi_strict=hi_strict, whole=whole, xp=np)
    if np.any(bad):
        shown = v[bad].reshape(-1)[:3].tolist()
        words = _domain_words(lo, hi, strict, whole, integer, hi_strict)
        raise ValueError(f"{fn_name}: {name} must be {words}, got {shown}{_DOMAIN_HINTS.get(name, '')}")
    if dtype is not None and jnp.issubdtype(dtype, jnp.floating):
        check_fits(f"{fn_name}: {name}", v64, jnp.dtype(dtype), positive=lo == 0 and strict,
                   whose="the kernel's dtype")
        # and as the kernel sees it: float32 rounds 3.14159265 up onto an open bound pi
        cast = v64.astype(jnp.dtype(dtype)).astype(np.float64)
        bad = ~in_domain(cast, lo=lo, hi=hi, strict=strict, hi_strict=hi_strict, whole=whole, xp=np)
        if np.any(bad):
            words = _domain_words(lo, hi, strict, whole, integer, hi_strict)
            raise ValueError(f"{fn_name}: {name} must be {words} in {jnp.dtype(dtype).name}, got "
                             f"{v[bad].reshape(-1)[:3].tolist()}, which rounds to "
                             f"{cast[bad].reshape(-1)[:3].tolist()}{_DOMAIN_HINTS.get(name, '')}")


def in_domain(x, *, lo=None, hi=None, strict: bool = False, hi_strict: bool = False, whole: bool = False,
              xp=jnp):
    """Where `x` lies in the domain of `check_domain` (finite, `>= lo` or `> lo`, `<= hi` or
    `< hi`, whole): the mask a kernel with a validity output applies to a traced parameter."""
    ok = xp.isfinite(x)
    if lo is not None:
        ok = ok & ((x > lo) if strict else (x >= lo))
    if hi is not None:
        ok = ok & ((x < hi) if hi_strict else (x <= hi))
    if whole:
        ok = ok & (xp.floor(x) == x)
    return ok


def _domains(positive, nonnegative, whole, bounds, below) -> dict:
    """`name -> check_domain keywords` from `float_inputs`' declarations."""
    spec: dict[str, dict] = {n: {"lo": 0, "strict": True} for n in positive}
    for n in nonnegative:
        spec.setdefault(n, {})["lo"] = 0
    for n, (lo, hi) in bounds.items():
        spec.setdefault(n, {}).update(lo=lo, hi=hi)
    for n, hi in below.items():
        spec.setdefault(n, {}).update(hi=hi, hi_strict=True)
    for n in whole:
        spec.setdefault(n, {})["whole"] = True
    return spec


def float_inputs(*arrays: str, params: tuple[str, ...] = (), ints: tuple[str, ...] = (),
                 dtype_arg: str | None = None, positive: tuple[str, ...] = (),
                 nonnegative: tuple[str, ...] = (), whole: tuple[str, ...] = (),
                 bounds: dict[str, tuple[float | None, float | None]] | None = None,
                 below: dict[str, float] | None = None):
    """Decorator: the input contract of a public kernel, applied at its entry.

    `arrays` name the float data arguments (they set the dtype), `params` the float
    parameters (cast to it), `ints` the integer arguments (indices, ids), by the rules
    above; `dtype_arg` names an explicit `dtype=` argument that sets the result dtype
    instead. Shapes given as jaxtyping annotations (`Float[Array, "*batch 3"]`) are
    checked, and the `*batch` shapes must broadcast. `positive` and `nonnegative` name
    params with a physical domain (an index ratio `eta > 0`, an extinction `sigma_t >= 0`),
    `whole` params that count (a cascade level), `bounds` maps a param or an integer
    argument to its closed range `(lo, hi)` (an edge in `[0, 2]`; `None`: unbounded on
    that side, `(None, None)`: finite only), `below` to an open upper bound (an angle
    `< pi`, `gamma < 1`). Domains may name arrays, params and integer arguments. Concrete
    values outside, not finite, overflowing the result dtype or (`positive`) subnormal in
    it are refused (`check_domain`).
    Integer arguments must fit the dtype JAX gives them (`as_integer_array`; uint32 where
    annotated `UInt32`). Violations raise `ValueError` naming the function and argument;
    `None` arguments are left alone. Works on concrete arrays and on tracers (inside jit it
    only casts: a kernel with a validity output marks such lanes invalid itself with
    `in_domain`, the others document what they do, docs/input_contract.md).
    """
    domains = _domains(positive, nonnegative, whole, bounds or {}, below or {})

    def decorate(fn):
        sig = inspect.signature(fn)
        try:
            hints = inspect.signature(getattr(fn, "__wrapped__", fn), eval_str=True).parameters
        except Exception:  # noqa: BLE001  (unresolvable annotation: no shape checks)
            hints = {}
        dims = {n: _dims(hints[n].annotation) for n in (*arrays, *params, *ints) if n in hints}
        for n in (*arrays, *params, *ints, *([dtype_arg] if dtype_arg else [])):
            if n not in sig.parameters:
                raise TypeError(f"float_inputs: {fn.__qualname__} has no argument {n!r}")
        for n in domains:
            if n not in (*arrays, *params, *ints):
                raise TypeError(f"float_inputs: {fn.__qualname__}: {n!r} has a domain but is not an argument")
        unsigned = {n for n in ints if n in hints and _unsigned(hints[n].annotation)}
        fn_name = fn.__name__

        def result_dtype(a):
            """The kernel's float dtype: `dtype_arg`'s, else by the rules from the arrays."""
            given = [(n, a[n]) for n in arrays if a[n] is not None]
            if dtype_arg is None:
                return result_float_dtype(*((f"{fn_name}: {n}", x) for n, x in given))
            for n, x in given:
                real_input_dtype(f"{fn_name}: {n}", x)
            return check_float_dtype(a[dtype_arg])

        def batch_of(n, x):
            """`(n, *batch shape)` of argument `n` checked against its annotation, or None."""
            if not dims.get(n):
                return None
            batch = _check_shape(fn_name, n, x.shape, dims[n])
            return None if batch is None else (n, batch)

        def cast(a, dtype):
            """Cast and check every declared argument in place; their `*batch` shapes."""
            batches = []
            for n in (*arrays, *params):
                if a[n] is None:
                    continue
                if n in params:
                    real_input_dtype(f"{fn_name}: {n}", a[n])
                if n in domains:
                    check_domain(fn_name, n, a[n], dtype=dtype, **domains[n])
                a[n] = jnp.asarray(a[n], dtype)
                batches.append(batch_of(n, a[n]))
            for n in ints:
                if a[n] is None:
                    continue
                a[n] = as_integer_array(f"{fn_name}: {n}", a[n], unsigned=n in unsigned)
                if n in domains:
                    check_domain(fn_name, n, a[n], integer=True, **domains[n])
                batches.append(batch_of(n, a[n]))
            return [b for b in batches if b is not None]

        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            bound = sig.bind(*args, **kwargs)
            bound.apply_defaults()
            a = bound.arguments
            for n in (*arrays, *params, *ints):  # None only where it is the documented default
                if a[n] is None and sig.parameters[n].default is not None:
                    raise ValueError(f"{fn_name}: {n} must be a real number or an array of real numbers, got None")
            batches = cast(a, result_dtype(a))
            if len(batches) > 1:
                try:
                    np.broadcast_shapes(*(b for _, b in batches))
                except ValueError:
                    shown = ", ".join(f"{n} {b}" for n, b in batches)
                    raise ValueError(f"{fn_name}: the batch shapes of {shown} do not broadcast") from None
            try:
                return fn(*bound.args, **bound.kwargs)
            except TypeError as exc:
                if "incompatible shapes" not in str(exc):
                    raise
                shapes = ", ".join(f"{n} {tuple(jnp.shape(a[n]))}" for n in (*arrays, *params, *ints)
                                   if a[n] is not None)
                raise ValueError(f"{fn_name}: input shapes do not broadcast ({shapes})") from None

        wrapper.input_contract = {"arrays": arrays, "params": params, "ints": ints,
                                  "dtype_arg": dtype_arg, "positive": positive, "nonnegative": nonnegative,
                                  "whole": whole, "bounds": dict(bounds or {}), "below": dict(below or {})}
        return wrapper

    return decorate
