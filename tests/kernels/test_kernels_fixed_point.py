"""4.28 fixed-point accumulation (seed 000 §3.2): quantisation, wrap-around, overflow."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax.kernels import fixed_point_accumulate, fixed_point_decode, fixed_point_encode
from caustics_jax.kernels.fixed_point import RESOLUTION

DTYPES = [jnp.float32, jnp.float64]
encode_j = jax.jit(fixed_point_encode)
accumulate_j = jax.jit(fixed_point_accumulate, static_argnames="num_segments")


def _values(seed, n, dtype, high=16.0):
    """Log-uniform values in [1e-9, high): flux contributions span many decades."""
    rng = np.random.default_rng(seed)
    x = np.exp(rng.uniform(np.log(1e-9), np.log(high), n))
    return np.minimum(x, np.nextafter(high, 0)).astype(dtype)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1))
def test_round_trip_error_is_at_most_half_a_quantisation_step(dtype, seed):
    x = _values(seed, 4096, dtype)
    code = encode_j(jnp.asarray(x))
    assert code.dtype == jnp.uint32
    back = np.asarray(fixed_point_decode(code, dtype))
    assert back.dtype == dtype
    err = np.abs(back.astype(np.float64) - x.astype(np.float64))
    assert err.max() <= RESOLUTION / 2
    if dtype == jnp.float32:
        # float32 values >= 2^-5 have a spacing >= 2^-28: they are exactly representable.
        assert np.all(err[x >= 2.0**-5] == 0)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1))
def test_encode_is_monotone_and_clips_at_the_top(dtype, seed):
    x = np.sort(_values(seed, 1024, dtype, high=20.0))
    code = np.asarray(encode_j(jnp.asarray(x))).astype(np.int64)
    assert np.all(np.diff(code) >= 0)
    assert np.all(code[x >= 16] == code.max())
    assert code.max() <= 2**32 - 1


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1), segments=st.integers(1, 8))
def test_accumulate_is_the_wrapped_32bit_integer_sum_in_any_order(dtype, seed, segments):
    rng = np.random.default_rng(seed)
    x = _values(seed, 2048, dtype, high=float(rng.choice([1e-3, 0.05, 1.0])))
    ids = rng.integers(0, segments, x.shape)
    out = accumulate_j(jnp.asarray(x), jnp.asarray(ids), num_segments=8)
    codes = np.asarray(encode_j(jnp.asarray(x))).astype(np.uint64)
    exact = np.array([codes[ids == s].sum() for s in range(8)], np.uint64)
    np.testing.assert_array_equal(np.asarray(out.code).astype(np.uint64), exact % 2**32)
    np.testing.assert_array_equal(np.asarray(out.overflow), exact >= 2**32)
    perm = rng.permutation(x.shape[0])
    again = accumulate_j(jnp.asarray(x[perm]), jnp.asarray(ids[perm]), num_segments=8)
    np.testing.assert_array_equal(np.asarray(again.code), np.asarray(out.code))


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=st.integers(0, 2**32 - 1))
def test_accumulated_value_is_within_n_half_steps_of_the_float64_sum(dtype, seed):
    x = _values(seed, 4096, dtype, high=1e-3)
    out = accumulate_j(jnp.asarray(x))
    assert out.value.dtype == dtype and not bool(out.overflow[0])
    exact = x.astype(np.float64).sum()
    # Each addend is off by at most half a step; decoding a code above 2^24 in float32
    # rounds once more, by at most half an ulp of the result.
    decode = np.spacing(np.float32(exact)) / 2 if dtype == jnp.float32 else 0
    bound = x.size * RESOLUTION / 2 + decode
    assert abs(float(out.value[0]) - exact) <= bound


@pytest.mark.parametrize("dtype", DTYPES)
def test_overflow_is_flagged_exactly_when_the_sum_reaches_sixteen(dtype):
    # 1 - 2^-20 is exact in float32, so the last addend is the largest float32 below 1 used.
    below = np.concatenate([np.ones(15), [1 - 2.0**-20]]).astype(dtype)
    at = np.ones(16, dtype)
    out_below = fixed_point_accumulate(jnp.asarray(below))
    out_at = fixed_point_accumulate(jnp.asarray(at))
    assert not bool(out_below.overflow[0])
    assert bool(out_at.overflow[0]) and int(out_at.code[0]) == 0  # 16 wraps to 0
    assert float(out_below.value[0]) == pytest.approx(16 - 2.0**-20, abs=1e-6)


def test_negative_values_and_bad_segments_raise():
    with pytest.raises(ValueError, match="x"):
        fixed_point_encode(jnp.asarray([0.1, -1e-3]))
    with pytest.raises(ValueError, match="segment_ids"):
        fixed_point_accumulate(jnp.ones(3), jnp.asarray([0, 1, 2]), num_segments=2)


def test_codes_outside_32_bits_are_refused_not_wrapped():
    """An int64 code 2^33 had decoded as 0, and -1 as 16 (wrapped to 2^32 - 1)."""
    for code in (np.array([2**33]), np.array([-1]), np.array([2**32])):
        with pytest.raises(ValueError, match="code"):
            fixed_point_decode(code)
    assert float(fixed_point_decode(np.array([2**32 - 1]))[0]) == pytest.approx(16.0)


def test_num_segments_given_a_tracer_is_a_value_error_naming_it():
    with pytest.raises(ValueError, match="num_segments.*static"):
        jax.jit(lambda k: fixed_point_accumulate(jnp.ones(3), jnp.zeros(3, jnp.int32), k))(2)
