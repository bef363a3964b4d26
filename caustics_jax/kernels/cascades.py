"""Cascaded caustic maps of seed 004 (eq. 1-7, Alg. 1; math.md §8).

Level `c` of `N` renders the water surface from the light with an orthographic
projection `s^c` times wider than level 0, at the same `W x H` resolution. The centre
`W/s x H/s` texels of level `c` are already covered by level `c - 1`, so Alg. 1 gives
level `c > 0` only the ring around that hole: `W H (1 - 1/s^2)` threads (eq. 4).

Alg. 1 as printed does not map threads one-to-one onto that ring. Three lines are
fixed here and each fix is pinned by `tests/kernels/test_kernels_cascades.py`:

- line 24 `LocalTid - Region1` -> `LocalTid - Region0` (side bands start at Region0);
- line 26 `NewTid.x > DeltaX` -> `>=` (column DeltaX is the hole's first column);
- line 33 `LocalTid - Region0` -> `LocalTid - Region1` (top band starts at Region1).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..runtime.kernel_contract import float_inputs, in_domain
from ._util import as_float, check_last_axis, concrete, float_dtype, safe_div, static_int, static_real

#: Largest thread id of a dispatch: the GLSL port's `int tid` (and Alg. 1's arithmetic) is 32-bit.
MAX_THREADS = 2**31 - 1


@float_inputs("o", "l_dir", params=("z_near", "z_far"), bounds={"z_near": (None, None), "z_far": (None, None)})
def light_position(
    o: Float[Array, "*batch 3"], l_dir: Float[Array, "*batch 3"], z_near, z_far
) -> Float[Array, "*batch 3"]:
    """Light position for the cascade views (seed 004 eq. 1): `o - l_dir (z_near + z_far)`.

    The prose says "an amount equal to the distance between the near and far planes",
    which would be `z_far - z_near`; the equation (implemented) backs off further, so the
    whole frustum is in front of the light for any `z_near >= 0`.
    """
    check_last_axis(o, "o", 3)
    check_last_axis(l_dir, "l_dir", 3)
    dtype = float_dtype(o, l_dir)
    back = as_float(z_near, dtype) + as_float(z_far, dtype)
    return jnp.asarray(o, dtype) - jnp.asarray(l_dir, dtype) * jnp.asarray(back)[..., None]


@float_inputs(params=("width", "height", "near", "far", "s", "level"), dtype_arg="dtype", nonnegative=("level",),
              whole=("level",), positive=("width", "height"),
              bounds={"near": (None, None), "far": (None, None), "s": (1, None)})
def cascade_projection(
    width, height, near, far, s, level, dtype=jnp.float32
) -> Float[Array, "4 4"]:
    """Orthographic light projection of cascade `level` (seed 004 eq. 2), row-vector form.

    `[x y z 1] @ P` maps `x in [-w s^i/2, w s^i/2]` to `[-1, 1]` (same for `y`) and
    `z in [near, far]` to `[0, 1]` (Direct3D convention, as the paper's DXR renderer).
    The printed bottom row reads `(far - near)/(far - near)` in the `z` column, which
    would map `near` to `near/(far - near) + 1`; the D3D matrix has `-near/(far - near)`
    there, which is what we use.

    All six parameters may be traced. Outside jit, `far <= near`, a non-positive size, a
    level that is negative or not whole (0.5 had given an extent of `s^0.5`), non-finite
    planes and an extent `max(w, h) s^level` beyond the dtype are refused; inside jit
    (unchecked) such entries are 0, never inf.
    """
    n, f = concrete(near), concrete(far)
    if n is not None and f is not None and np.any(f <= n):
        raise ValueError(f"cascade_projection: far must exceed near (in {jnp.dtype(dtype).name}), "
                         f"got near={n}, far={f}")
    w, h = concrete(width), concrete(height)
    if w is not None and h is not None:
        _check_power_fits("cascade_projection", "the extent max(width, height) s^level",
                          np.maximum(w, h), s, level, 1, dtype)
    level = as_float(level, dtype)
    scale = jnp.where(in_domain(level, lo=0, whole=True), as_float(s, dtype) ** level, 0)
    depth = as_float(far, dtype) - as_float(near, dtype)
    zero = jnp.zeros((), dtype)
    one = jnp.ones((), dtype)
    rows = [
        [safe_div(2, as_float(width, dtype) * scale), zero, zero, zero],
        [zero, safe_div(2, as_float(height, dtype) * scale), zero, zero],
        [zero, zero, safe_div(1, jnp.maximum(depth, 0)), zero],
        [zero, zero, safe_div(-as_float(near, dtype), jnp.maximum(depth, 0)), one],
    ]
    return jnp.stack([jnp.stack(r) for r in rows])


def _check_power_fits(fn_name, what, factor, s, level, power, dtype) -> None:
    """A ValueError naming `level` when a concrete `factor s^(power level)` exceeds the
    largest finite number of `dtype` (compared in logarithms, which cannot overflow)."""
    s, level = concrete(s), concrete(level)
    if s is None or level is None or np.size(level) == 0 or np.size(s) == 0:
        return
    s = np.asarray(s, np.float64)
    top = float(np.max(level))
    log_max = np.log(float(jnp.finfo(dtype).max))
    with np.errstate(divide="ignore"):
        grows = np.log(np.asarray(factor, np.float64)) + power * top * np.log(s)
    if np.any(grows > log_max):
        s_max = float(np.max(s))
        largest = int(np.floor((log_max - float(np.max(np.log(factor)))) / (power * np.log(s_max))))
        raise ValueError(f"{fn_name}: level {top:g} makes {what} overflow {jnp.dtype(dtype).name} "
                         f"(largest {float(jnp.finfo(dtype).max):.4g}); with s = {s_max:g} the level must "
                         f"be at most {largest}")


def ccm0_size(r_width, r_height, p) -> int:
    """Innermost caustic-map size from light range and precision (seed 004 eq. 3).

    256, 512, 1024 or 2048 (square) as `max(r.width, r.height) / p` is below 256, 512,
    1024, or not. Static configuration, so plain Python.
    """
    r_width, r_height, p = (static_real("ccm0_size", n, v, 0, lo_open=True) for n, v in
                            (("r_width", r_width), ("r_height", r_height), ("p", p)))
    ratio = max(r_width, r_height) / p
    for size in (256, 512, 1024):
        if ratio < size:
            return size
    return 2048


def cascade_deltas(ccm0_x: int, ccm0_y: int, s: int) -> tuple[int, int]:
    """Ring thickness `(DeltaX, DeltaY)` (seed 004 eq. 6): `ccm0 (1 - 1/s) / 2`.

    Raises ValueError unless they are whole texels, which Alg. 1's integer arithmetic
    needs (e.g. power-of-two maps with `s` a power of two).
    """
    ccm0_x = static_int("cascade_deltas", "ccm0_x", ccm0_x, 1, 2**16)
    ccm0_y = static_int("cascade_deltas", "ccm0_y", ccm0_y, 1, 2**16)
    s = static_int("cascade_deltas", "s", s, 2, 2**16)
    dx, dy = ccm0_x * (s - 1) / (2 * s), ccm0_y * (s - 1) / (2 * s)
    if dx != int(dx) or dy != int(dy) or ccm0_x % s or ccm0_y % s:
        raise ValueError(f"ccm0 {ccm0_x}x{ccm0_y} with s={s} gives fractional texels")
    return int(dx), int(dy)


def cascade_thread_counts(ccm0_x: int, ccm0_y: int, s: int, n_levels: int) -> tuple[int, ...]:
    """Threads per level (seed 004 eq. 4): `W H` for level 0, `W H (1 - 1/s^2)` after.

    Eq. 4 multiplies the map *size* by `(1 - 1/s^2)`; read as a thread count (an area) it
    is exactly the ring `W H - (W/s)(H/s)`. Applied to each of `.x` and `.y`, as Alg. 1's
    `ccm[i].x x ccm[i].y` suggests, it would give `W H (1 - 1/s^2)^2`, too few threads.
    The total (eq. 5) is `sum(...)`; eq. 5 sums to `N` where levels run `0..N-1`.
    """
    cascade_deltas(ccm0_x, ccm0_y, s)
    n_levels = static_int("cascade_thread_counts", "n_levels", n_levels, 1, 64)
    ring = ccm0_x * ccm0_y - (ccm0_x // s) * (ccm0_y // s)
    return (ccm0_x * ccm0_y,) + (ring,) * (n_levels - 1)


@float_inputs(params=("s",), ints=("level",), dtype_arg="dtype", nonnegative=("level",), bounds={"s": (1, None)})
def cascade_intensity_scale(
    level: Int[Array, "*batch"], s, dtype=jnp.float32
) -> Float[Array, "*batch"]:
    """Light intensity scale of a cascade level (seed 004 eq. 7): `L = s^(2c)`.

    A level-`c` texel covers `s^(2c)` level-0 texels, so this keeps the flux per unit
    area the same on every level. Alg. 3 lines 4-6 loop `for i = 0 to c`, which would
    give `s^(2(c+1))`; the test of flux conservation settles on eq. 7.

    A negative level, or one whose scale overflows `dtype` (float32, s = 2: above 63), is
    refused outside jit; inside jit (unchecked) its scale is 0, like a masked lane.
    """
    _check_power_fits("cascade_intensity_scale", "s^(2 level)", 1.0, s, level, 2, dtype)
    s, c = as_float(s, dtype), jnp.asarray(level).astype(dtype)
    fits = jnp.isfinite(s ** (2 * c)) & (c >= 0)  # a negative level had scaled by s^-2c
    return jnp.where(fits, s ** jnp.where(fits, 2 * c, 0), 0)


@float_inputs(ints=("tid",))
def cascade_dispatch(
    tid: Int[Array, "*batch"], ccm0_x: int, ccm0_y: int, s: int, n_levels: int
) -> tuple[Int[Array, "*batch 2"], Int[Array, "*batch"], Bool[Array, "*batch"]]:
    """Dispatch thread id to `(texel, level, valid)` (seed 004 Alg. 1, three lines fixed).

    Threads `0 .. W H - 1` fill level 0 row by row. Each later level gets
    `W H (1 - 1/s^2)` threads laid out as the bottom band (`Region0 = W DeltaY`
    threads), the left and right bands (`2 DeltaX (H - 2 DeltaY)`, up to `Region1`) and
    the top band. `valid` is False past the last level (texel and level are then 0).

    `ccm0_x`, `ccm0_y`, `s`, `n_levels` are static configuration (Python ints). Thread ids
    are 32-bit on the GPU: a configuration of more than `2^31 - 1` threads is refused, and
    `valid` is decided on `tid` as given (an int64 `2^33 + 1` is past the end, not 1; with
    x64 off, where JAX would wrap it to int32, a concrete one is a `ValueError`).
    """
    W = static_int("cascade_dispatch", "ccm0_x", ccm0_x, 1, 2**16)
    H = static_int("cascade_dispatch", "ccm0_y", ccm0_y, 1, 2**16)
    s = static_int("cascade_dispatch", "s", s, 2, 2**16)
    n_levels = static_int("cascade_dispatch", "n_levels", n_levels, 1, 64)
    dx, dy = cascade_deltas(W, H, s)
    counts = cascade_thread_counts(W, H, s, n_levels)
    if sum(counts) > MAX_THREADS:
        raise ValueError(f"cascade_dispatch: {W}x{H} maps with s={s} and {n_levels} levels need "
                         f"{sum(counts)} threads, beyond int32 thread ids (2^31 - 1 = {MAX_THREADS})")
    tid = jnp.asarray(tid)
    tid = tid.astype(jnp.promote_types(tid.dtype, jnp.int32))  # room for the bounds below
    valid = (tid >= 0) & (tid < sum(counts))
    tid = jnp.where(valid, tid, 0).astype(jnp.int32)
    ring = counts[-1] if n_levels > 1 else 1
    region0 = W * dy
    region1 = region0 + 2 * dx * (H - 2 * dy)

    beyond = jnp.maximum(tid - W * H, 0)
    level = jnp.where(tid < W * H, 0, 1 + beyond // ring)
    local = beyond % ring
    side = local - region0  # line 24 fixed: Region0, not Region1
    x_side = side % (2 * dx)
    x_side = jnp.where(x_side >= dx, x_side + (W - 2 * dx), x_side)  # line 26 fixed: >=
    top = local - region1  # line 33 fixed: Region1, not Region0
    x = jnp.where(
        tid < W * H,
        tid % W,
        jnp.where(local < region0, local % W, jnp.where(local < region1, x_side, top % W)),
    )
    y = jnp.where(
        tid < W * H,
        tid // W,
        jnp.where(
            local < region0,
            local // W,
            jnp.where(local < region1, dy + side // (2 * dx), (H - dy) + top // W),
        ),
    )
    texel = jnp.stack([jnp.where(valid, x, 0), jnp.where(valid, y, 0)], axis=-1)
    return texel, jnp.where(valid, level, 0), valid
