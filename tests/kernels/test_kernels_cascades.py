"""Cascaded caustic maps (seed 004 eq. 1-7, Alg. 1): projection extents, ring mapping, flux."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax.kernels import (
    cascade_deltas,
    cascade_dispatch,
    cascade_intensity_scale,
    cascade_projection,
    cascade_thread_counts,
    ccm0_size,
    light_position,
)

DTYPES = [jnp.float32, jnp.float64]
# (W, H, s, N): power-of-two maps and scales, the configurations Alg. 1's integer
# arithmetic supports; small enough to enumerate every thread.
CONFIGS = [(16, 16, 2, 3), (32, 16, 2, 4), (64, 32, 4, 3), (16, 32, 4, 2), (24, 24, 2, 3)]


def alg1_transcribed(tid, ccm, s, line24="Region1", line26=">", line33="Region0"):
    """Seed 004 Alg. 1 line by line, integer GPU arithmetic; lines 24, 26, 33 as printed by default.

    One line is always fixed: line 16 loops `i = 0 to N - 1`, whose last `bound[i + 1]`
    is one past the array (docs/kernels.md); the loop stops at `N - 2`, which changes
    nothing for `tid` below the total thread count (beyond it, None). `%` is Python's
    non-negative modulo, also on the negative `LocalTid` of line 24 as printed.

    `ccm` lists (x, y) thread extents per level as Alg. 1 indexes them: `ccm[i].x *
    ccm[i].y` must be the level's thread count, so levels > 0 are given as (count, 1).
    Returns (x, y, c).
    """
    W, H = ccm[0]
    DeltaX = int(0.5 * W * (1.0 - 1.0 / s))
    DeltaY = int(0.5 * H * (1.0 - 1.0 / s))
    if tid < W * H:
        return tid % W, tid // W, 0
    Region0 = W * DeltaY
    Region1 = Region0 + 2 * DeltaX * (H - 2 * DeltaY)
    bound = [W * H]
    for i in range(1, len(ccm)):
        bound.append(bound[i - 1] + ccm[i][0] * ccm[i][1])
    for i in range(len(ccm) - 1):
        if tid < bound[i + 1]:
            c = i + 1
            LocalTid = tid - bound[i]
            if LocalTid < Region0:
                return LocalTid % W, LocalTid // W, c
            if LocalTid < Region1:
                LocalTid -= Region1 if line24 == "Region1" else Region0
                x = LocalTid % (2 * DeltaX)
                if (x > DeltaX) if line26 == ">" else (x >= DeltaX):
                    x += W - 2 * DeltaX
                # C-style division truncates toward zero (Python's // floors)
                return x, DeltaY + int(LocalTid / (2 * DeltaX)), c
            LocalTid -= Region0 if line33 == "Region0" else Region1
            return LocalTid % W, (H - DeltaY) + LocalTid // W, c
    return None


def ring_texels(W, H, s):
    """Texels of a level not covered by the previous one, from the eq. 2 extents alone.

    Texel centre u = (x + 0.5)/W - 0.5 in units of this level's width; the previous level
    spans |u| < 1/(2s). A texel is covered when its centre lies inside in both axes.
    """
    x, y = np.meshgrid(np.arange(W), np.arange(H), indexing="ij")
    covered = (np.abs((x + 0.5) / W - 0.5) < 0.5 / s) & (np.abs((y + 0.5) / H - 0.5) < 0.5 / s)
    return {(int(a), int(b)) for a, b in zip(x[~covered], y[~covered], strict=True)}


def _mapping_is_one_to_one_onto_rings(mapping, W, H, s, N):
    """For every level: its threads hit distinct texels, exactly the ring (all for level 0)."""
    counts = cascade_thread_counts(W, H, s, N)
    start = 0
    for level, count in enumerate(counts):
        texels = [mapping(t) for t in range(start, start + count)]
        start += count
        if any(t is None or t[2] != level for t in texels):
            return False
        got = {(int(x), int(y)) for x, y, _ in texels}
        want = ring_texels(W, H, s) if level else {(x, y) for x in range(W) for y in range(H)}
        if len(got) != count or got != want:
            return False
    return True


@pytest.mark.parametrize("W,H,s,N", CONFIGS)
def test_dispatch_maps_each_level_one_to_one_onto_its_ring(W, H, s, N):
    total = sum(cascade_thread_counts(W, H, s, N))
    texel, level, valid = jax.jit(cascade_dispatch, static_argnums=(1, 2, 3, 4))(
        jnp.arange(total), W, H, s, N
    )
    assert bool(valid.all())
    texel, level = np.asarray(texel), np.asarray(level)
    assert _mapping_is_one_to_one_onto_rings(
        lambda t: (texel[t, 0], texel[t, 1], level[t]), W, H, s, N
    )
    _, _, past = cascade_dispatch(jnp.asarray([total, -1]), W, H, s, N)
    assert not bool(past.any())


@pytest.mark.parametrize("W,H,s,N", CONFIGS)
def test_corrected_transcription_of_alg1_equals_the_kernel(W, H, s, N):
    counts = cascade_thread_counts(W, H, s, N)
    ccm = [(W, H)] + [(c, 1) for c in counts[1:]]
    texel, level, _ = cascade_dispatch(jnp.arange(sum(counts)), W, H, s, N)
    fixed = [alg1_transcribed(t, ccm, s, "Region0", ">=", "Region1") for t in range(sum(counts))]
    np.testing.assert_array_equal(np.asarray(fixed), np.c_[np.asarray(texel), np.asarray(level)])


@pytest.mark.parametrize("W,H,s,N", CONFIGS)
@pytest.mark.parametrize(
    "printed",
    [
        dict(line24="Region1", line26=">", line33="Region0"),  # Alg. 1 exactly as printed
        dict(line24="Region1", line26=">=", line33="Region1"),  # only line 24 as printed
        dict(line24="Region0", line26=">", line33="Region1"),  # only line 26 as printed
        dict(line24="Region0", line26=">=", line33="Region0"),  # only line 33 as printed
    ],
)
def test_alg1_as_printed_is_not_one_to_one_and_each_printed_line_breaks_it(W, H, s, N, printed):
    counts = cascade_thread_counts(W, H, s, N)
    ccm = [(W, H)] + [(c, 1) for c in counts[1:]]
    mapping = lambda t: alg1_transcribed(t, ccm, s, **printed)  # noqa: E731
    assert not _mapping_is_one_to_one_onto_rings(mapping, W, H, s, N)


@pytest.mark.parametrize("W,H,s,N", CONFIGS)
def test_eq4_thread_count_is_the_ring_area_and_its_componentwise_reading_is_short(W, H, s, N):
    counts = cascade_thread_counts(W, H, s, N)
    assert counts[0] == W * H
    assert all(c == len(ring_texels(W, H, s)) == W * H * (1 - 1 / s**2) for c in counts[1:])
    # Eq. 4 applied to each of ccm0.x and ccm0.y, multiplied as Alg. 1 does:
    assert W * (1 - 1 / s**2) * H * (1 - 1 / s**2) < counts[1] if N > 1 else True
    dx, dy = cascade_deltas(W, H, s)
    assert (dx, dy) == (W * (s - 1) // (2 * s), H * (s - 1) // (2 * s))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("W,H,s,N", CONFIGS)
def test_eq7_scale_conserves_flux_over_the_outermost_extent(dtype, W, H, s, N):
    """Each thread carries flux over one of its level's texels (s^2c level-0 texels):
    summed, the levels must tile the outermost extent W H s^(2(N-1)) exactly once."""
    counts = np.asarray(cascade_thread_counts(W, H, s, N), np.float64)
    scale = np.asarray(cascade_intensity_scale(jnp.arange(N), s, dtype))
    assert scale.dtype == dtype
    outer = W * H * float(s) ** (2 * (N - 1))
    assert np.sum(counts * scale) == pytest.approx(outer, rel=1e-6)
    # Alg. 3 lines 4-6 (`for i = 0 to c: L *= s^2`) scale by s^(2(c+1)): s^2 too bright.
    alg3 = float(s) ** (2 * (np.arange(N) + 1))
    assert np.sum(counts * alg3) == pytest.approx(outer * s**2)


@pytest.mark.parametrize("dtype", DTYPES)
@given(
    w=st.floats(1, 1e4),
    h=st.floats(1, 1e4),
    near=st.floats(0, 10),
    depth=st.floats(0.1, 1e3),
    s=st.sampled_from([2, 3, 4]),
    level=st.integers(0, 4),
)
def test_projection_maps_the_level_extent_to_the_clip_cube(dtype, w, h, near, depth, s, level):
    P = np.asarray(cascade_projection(w, h, near, near + depth, s, level, dtype))
    assert P.dtype == dtype
    half_w, half_h = w * s**level / 2, h * s**level / 2
    corners = np.array(
        [[-half_w, -half_h, near, 1], [half_w, half_h, near + depth, 1], [0, 0, near, 1]]
    )
    clip = corners @ P.astype(np.float64)
    rtol = 1e-5 if dtype == jnp.float32 else 1e-12  # a handful of float32 roundings
    np.testing.assert_allclose(clip[:, :3], [[-1, -1, 0], [1, 1, 1], [0, 0, 0]], atol=rtol)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1))
def test_light_position_lies_behind_the_eye_by_near_plus_far(dtype, seed):
    rng = np.random.default_rng(seed)
    o = rng.normal(size=(256, 3)) * 100
    l_dir = rng.normal(size=(256, 3))
    l_dir /= np.linalg.norm(l_dir, axis=-1, keepdims=True)
    near, far = rng.uniform(0, 1, 256), rng.uniform(10, 1000, 256)
    pos = np.asarray(light_position(jnp.asarray(o, dtype), jnp.asarray(l_dir, dtype), near, far))
    assert pos.dtype == dtype
    back = o - pos
    tol = 1e-4 if dtype == jnp.float32 else 1e-9  # relative to |pos| ~ 1e3
    np.testing.assert_allclose(np.linalg.norm(back, axis=-1), near + far, rtol=tol)
    np.testing.assert_allclose(np.sum(back * l_dir, -1), near + far, rtol=tol)


def test_ccm0_size_thresholds_and_bad_configurations_raise():
    assert [ccm0_size(r, r, 1.0) for r in (255, 256, 511, 512, 1023, 1024, 5000)] == [
        256,
        512,
        512,
        1024,
        1024,
        2048,
        2048,
    ]
    with pytest.raises(ValueError):
        cascade_deltas(20, 20, 3)
    with pytest.raises(ValueError):
        cascade_projection(1.0, 1.0, 5.0, 1.0, 2, 0)


@pytest.mark.parametrize("dtype", DTYPES)
def test_projection_traces_inside_a_users_jit(dtype):
    """Its far > near check had called np.asarray on the tracers (TracerArrayConversionError).
    Inside jit, unchecked, far <= near or a zero width give a finite matrix (0 there)."""
    args = (3.0, 2.0, 0.5, 10.0, 2.0, 1.0)
    P = jax.jit(lambda *a: cascade_projection(*a, dtype=dtype))(*args)
    np.testing.assert_array_equal(np.asarray(P), np.asarray(cascade_projection(*args, dtype=dtype)))
    bad = jax.jit(lambda *a: cascade_projection(*a, dtype=dtype))(0.0, 2.0, 5.0, 5.0, 2.0, 1.0)
    assert bool(jnp.all(jnp.isfinite(bad)))


@pytest.mark.parametrize("dtype", DTYPES)
def test_scales_the_dtype_cannot_hold_are_refused_and_masked_inside_jit(dtype):
    """s^(2c) of eq. 7 and the extent w s^c of eq. 2 overflowed to inf / a zero row."""
    big = 100 if dtype == jnp.float32 else 600  # 2^200 > float32 max, 2^1200 > float64 max
    with pytest.raises(ValueError, match="level"):
        cascade_intensity_scale(np.array([0, big]), 2, dtype)
    with pytest.raises(ValueError, match="level"):
        cascade_projection(1.0, 1.0, 0.0, 1.0, 2.0, 2 * big, dtype)
    # the largest level that fits is accepted, and exact
    top = (np.finfo(dtype).maxexp - 1) // 2  # 2^(2 top) <= 2^(maxexp - 1), below the largest float
    assert float(cascade_intensity_scale(np.array([top]), 2, dtype)[0]) == 2.0 ** (2 * top)
    inside = jax.jit(lambda c: cascade_intensity_scale(c, 2, dtype))(jnp.asarray([1, big]))
    np.testing.assert_array_equal(np.asarray(inside), [4.0, 0.0])


def test_dispatch_refuses_configurations_past_int32_thread_ids():
    """32768^2 maps with 3 levels have 2.7e9 threads: an OverflowError had escaped."""
    with pytest.raises(ValueError, match="int32"):
        cascade_dispatch(np.array([0]), 32768, 32768, 2, 3)
    texel, level, valid = cascade_dispatch(np.array([0, 2**31 - 1]), 32768, 32768, 2, 2)
    assert list(np.asarray(valid)) == [True, False]


def test_dispatch_marks_thread_ids_past_int32_invalid_without_wrapping():
    """An int64 tid = 2^33 + 1 had wrapped to 1: texel (1, 0), valid."""
    tid = np.array([2**33 + 1, 2**32, -(2**32) + 5, 27, 28], np.int64)  # 28 threads in 4x4, s=2, N=2
    texel, level, valid = cascade_dispatch(tid, 4, 4, 2, 2)
    assert list(np.asarray(valid)) == [False, False, False, True, False]
    assert not np.asarray(texel)[[0, 1, 2, 4]].any() and not np.asarray(level)[[0, 1, 2, 4]].any()


def test_static_configuration_given_a_tracer_is_a_value_error_naming_it():
    for name, fn in (("ccm0_x", lambda v: cascade_dispatch(jnp.arange(4), v, 4, 2, 2)),
                     ("n_levels", lambda v: cascade_dispatch(jnp.arange(4), 4, 4, 2, v))):
        with pytest.raises(ValueError, match=f"{name}.*static"):
            jax.jit(fn)(4 if name == "ccm0_x" else 2)
