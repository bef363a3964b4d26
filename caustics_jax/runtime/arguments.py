"""Checks of API arguments, shared by every public entry point (docs/input_contract.md).

Each check raises `ValueError` naming the argument and its valid range, on the host,
before any jitted work, and returns the value in a canonical Python/numpy form. They sit
below every layer (numpy only), so meshes, scenes, solvers, transport and the CLI all
use the same ones: an option is refused with the same words wherever it is given.

Real numbers are Python `int`/`float`, numpy integer/float scalars or 0-d arrays, and
concrete 0-d jax arrays; `bool` is never a number here (`True` as a tolerance is a bug
in the caller), complex numbers and strings never are.
"""

from __future__ import annotations

import math
import numbers
import os
import sys
import warnings

import numpy as np

#: The package's directory: frames inside it are not the user's (`warn_user`).
_PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep

#: Largest iteration cap (the counters are int32).
MAX_INT32 = 2**31 - 1


def _real_dtype(dtype) -> bool:
    dtype = np.dtype(dtype)
    return dtype != np.bool_ and (np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating))


def is_real_scalar(value) -> bool:
    """True for one real number (see the module docstring); False for bool, complex, str,
    arrays of more than one element and tracers."""
    if isinstance(value, bool | np.bool_):
        return False
    if isinstance(value, numbers.Real):
        return True
    dtype, ndim = getattr(value, "dtype", None), getattr(value, "ndim", None)
    if dtype is None or ndim != 0:
        return False
    try:
        if not _real_dtype(dtype):
            return False
        float(value)  # a tracer refuses here: not a host value
    except Exception:  # noqa: BLE001  (jax dtypes numpy does not know, tracers)
        return False
    return True


def check_int(name: str, value, lo: int, hi: int = MAX_INT32) -> int:
    """An integer (not a bool) in `[lo, hi]`; returns it as an int."""
    ok = not isinstance(value, bool | np.bool_) and (
        isinstance(value, numbers.Integral)
        or (getattr(value, "ndim", None) == 0 and np.issubdtype(getattr(value, "dtype", np.float64), np.integer)))
    if not ok or not lo <= int(value) <= hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def check_real(name: str, value, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False,
               hi_open: bool = False) -> float:
    """A finite real number in `[lo, hi]` (open ends with `lo_open`/`hi_open`); returns a float."""
    ok = is_real_scalar(value) and math.isfinite(float(value))
    if ok:
        v = float(value)
        ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        raise ValueError(f"{name} must be a finite real number in {interval(lo, hi, lo_open, hi_open)}, "
                         f"got {value!r}")
    return float(value)


def interval(lo, hi, lo_open: bool = False, hi_open: bool = False, number=str) -> str:
    """`[lo, hi]`, `(lo, hi)`, `[0, inf)` as a message writes it (an infinite end is open);
    `number` formats each end."""
    return (f"{'(' if lo_open or lo == -math.inf else '['}{number(lo)}, {number(hi)}"
            f"{')' if hi_open or hi == math.inf else ']'}")


def check_tol(name: str, value, *, optional: bool = True):
    """A finite real in `(0, 1)` (or None when `optional`); returns it as a float.

    Acceptance is `|f| <= tol` on the signed sine `f` (seed 001 eq. 21), which lies in
    `[-1, 1]`: a `tol` of 1 or more accepts every point.
    """
    if value is None and optional:
        return None
    if not is_real_scalar(value) or not math.isfinite(float(value)) or not 0 < float(value) < 1:
        raise ValueError(
            f"{name} must be a finite real number in (0, 1) (|signed sine| <= {name} accepts a point; "
            f"the sine is at most 1), got {value!r}")
    return float(value)


def check_choice(name: str, value, choices) -> str:
    """One of `choices` (strings)."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def check_bool(name: str, value) -> bool:
    """True or False (Python or numpy bool; not 0/1, not a string)."""
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_eta(eta, name: str = "eta") -> float:
    """The index ratio `eta_in / eta_out` (math.md §1): one finite positive real number."""
    if not is_real_scalar(eta) or not math.isfinite(float(eta)) or float(eta) <= 0:
        raise ValueError(
            f"{name} must be one finite positive real number (eta_in / eta_out, water 1.333), got {eta!r}")
    return float(eta)


def real_array(name: str, value, *, dtype=np.float64) -> np.ndarray:
    """`value` as a numpy array of real numbers (integers promoted to `dtype`); refuses
    bool, complex, strings, objects and ragged input with a `ValueError` naming `name`."""
    if value is None:
        raise ValueError(f"{name} must be a real number or an array of real numbers, got None")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be an array of real numbers: {exc}") from None
    if not _real_dtype(arr.dtype):
        raise ValueError(f"{name} must hold real numbers (integer or float), got dtype {arr.dtype}")
    return arr.astype(dtype)


def check_points(name: str, value, dtype) -> np.ndarray:
    """`value` as a float64 numpy array of shape `(..., 3)`: real numbers, finite, and
    finite after the cast to `dtype` (no float32 overflow)."""
    X = real_array(name, value)
    if X.ndim == 0 or X.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) (or broadcast to it), got {X.shape}")
    # One pass decides the common case: a largest magnitude below `dtype`'s largest finite
    # number is finite (NaN propagates through the max) and casts to a finite number.
    if X.size == 0 or float(np.max(np.abs(X))) < float(np.finfo(dtype).max):
        return X
    with np.errstate(over="ignore"):
        bad = ~np.all(np.isfinite(X) & np.isfinite(X.astype(dtype)), axis=-1)
    if np.any(bad):
        rows = np.nonzero(bad.reshape(-1))[0][:10].tolist()
        raise ValueError(f"{name} has NaN or Inf coordinates, or coordinates that overflow "
                         f"{np.dtype(dtype).name}, at rows {rows}")
    return X


def check_fits(name: str, value, dtype, *, positive: bool = False, whose: str = "the mesh's dtype"):
    """`value` (real numbers already checked finite in float64) stays finite when cast to
    `dtype`, the computation's dtype: a float32 mesh refuses `eta=1e39` as it refuses
    coordinates that overflow (`check_points`). `positive`: a value known to be `> 0`
    (an index ratio, a scale something is divided by) must also be a normal number of
    `dtype`, since XLA flushes smaller ones to zero (float32 `eta = 1e-40`). Returns
    `value` unchanged."""
    v = np.asarray(value, np.float64)
    with np.errstate(over="ignore", under="ignore"):
        cast = v.astype(dtype)
    info = np.finfo(dtype)
    bad = ~np.isfinite(cast)
    if np.any(bad):
        raise ValueError(f"{name} overflows {np.dtype(dtype).name}, {whose} (largest "
                         f"{float(info.max):.4g}), got {_shown(value, v, bad)}")
    bad = np.abs(cast) < info.tiny
    if positive and np.any(bad):
        raise ValueError(f"{name} must be at least {float(info.tiny):.4g}, the smallest normal "
                         f"{np.dtype(dtype).name} ({whose}; XLA flushes smaller numbers to zero), "
                         f"got {_shown(value, v, bad)}")
    return value


def _shown(value, v: np.ndarray, bad: np.ndarray):
    """`value` itself when it is a Python number, else its first three entries where `bad`."""
    return repr(value) if isinstance(value, numbers.Real) else v[bad].reshape(-1)[:3].tolist()


def check_tol_resolves(name: str, tol, dtype) -> None:
    """A `ValueError` when an acceptance `tol` on the signed sine lies below `dtype`'s
    machine epsilon: the sine is a difference of unit vectors, rounded to about `eps`, so
    no point can be certified there (float32 `tol=1e-30` ended lanes NOT_CONVERGED or,
    wrongly, TOTAL_INTERNAL_REFLECTION). `None` (the dtype's default) passes."""
    if tol is None:
        return
    eps = float(np.finfo(dtype).eps)
    if tol < eps:
        raise ValueError(f"{name}={tol!r} is below {np.dtype(dtype).name}'s resolution of the signed sine "
                         f"(eps {eps:.3g}): no point can be certified; use {name} >= {eps:.3g} or a float64 mesh")


def scale_range(dtype) -> tuple[float, float]:
    """`(smallest extent, largest coordinate)` of a scene the solvers resolve in `dtype`
    (`check_scene_scale`): `tiny^(1/5)` and `max^(1/4) / 8` of the dtype, for the quartic
    products of lengths the solvers form (the edge quadratics' discriminants, `D`'s products
    of four lengths) and the fifth powers of their ratios. float32: 2.6e-8 and 5.4e8 m;
    float64: 2.9e-62 and 1.4e76 m. The solvers resolve a scene somewhat beyond both ends;
    the D factor (`ray_differential_D`) overflows sooner than they do, and the factor 8
    keeps it inside the band (docs/input_contract.md, "Scale" and "Measurements behind the
    code")."""
    info = np.finfo(dtype)
    return float(info.tiny) ** 0.2, float(info.max) ** 0.25 / 8


def check_scene_scale(vertices: np.ndarray, points: tuple, dtype, lights: tuple = ()) -> None:
    """A `ValueError` when the scene lies outside `scale_range(dtype)`: its largest
    coordinate (mesh vertices and every point of `points`) above the limit, or the extent of
    the mesh (its bounding box's largest side) below it; or lights of `lights` so far that
    the products of their distance and the scene's overflow. Rescale the scene (metres to
    kilometres, say) or use float64."""
    lo, hi = scale_range(dtype)
    name = np.dtype(dtype).name
    big = max([float(np.max(np.abs(vertices), initial=0.0))]
              + [float(np.max(np.abs(X), initial=0.0)) for X in points])
    if big > hi:
        raise ValueError(f"the scene's coordinates reach {big:.3g}, beyond what {name} resolves ({hi:.3g}: "
                         f"quartic products of lengths overflow); rescale the scene or use float64")
    # The conic's products hold two lengths of the scene and two of `L - P` (seed 001
    # eq. 10-12): with the light's coordinates `far`, `big^2 far^2 <= hi^4`, which for a
    # light among the scene's coordinates is the bound above.
    far = max([float(np.max(np.abs(X), initial=0.0)) for X in lights], default=0.0)
    if far > big and big * far > hi * hi:
        raise ValueError(f"the light's coordinates reach {far:.3g} in a scene reaching {big:.3g}, beyond what "
                         f"{name} resolves (product {big * far:.3g} > {hi * hi:.3g}); pass a far light as "
                         f"caustics_jax.Directional(direction), rescale the scene or use float64")
    extent = float(np.max(np.ptp(vertices, axis=0))) if vertices.size else 0.0
    if 0 < extent < lo:
        raise ValueError(f"the mesh spans {extent:.3g}, below what {name} resolves ({lo:.3g}: products of "
                         f"lengths underflow); rescale the scene or use float64")


def check_dtype(name: str, value) -> np.dtype:
    """A dtype-like naming float32 or float64 (not yet checked against x64; see
    `precision.check_float_dtype`)."""
    try:
        dtype = np.dtype(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 'float32' or 'float64', got {value!r}") from None
    if dtype not in (np.dtype("float32"), np.dtype("float64")):
        raise ValueError(f"{name} must be 'float32' or 'float64', got {value!r}")
    return dtype


def warn_user(message: str, category: type[Warning] = UserWarning) -> None:
    """`warnings.warn` attributed to the user's line: the first caller outside the package,
    however deep inside it the warning is raised (a fixed `stacklevel` points into the
    package when the same check runs under `solve`, `prepare` or `start_points`)."""
    frame, level = sys._getframe(1), 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE_DIR):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)
