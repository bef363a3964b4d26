"""Kernel arguments outside their domain (docs/input_contract.md "Kernels"): a concrete one is a
ValueError naming the kernel and the argument, a traced one an invalid lane with finite values
(or the documented clip), never a wrong result marked valid.

Three classes, each found by review with a result the kernel had marked valid or returned
silently: integer arrays wrapped to int32 before any check (x64 off), directions of a length
other than 1 or none, and parameters whose natural domain was not declared.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import caustics_jax as cj
import caustics_jax.kernels as K
from caustics_jax.math.conic import EDGE_TOL_MAX

DTYPES = [jnp.float32, jnp.float64]
_Z = np.array([0.0, 0.0, 1.0])
_MESH = cj.SurfaceMesh.from_arrays(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]]),
                                   np.array([[0, 1, 2], [1, 3, 2]]), dtype="float32")
_P3 = np.zeros((1, 3))

# --------------------------------------------------------------------------- integers (x64 off)
# Each had been wrapped modulo 2^32 by `jnp.asarray` and used: decoded as 5, dispatched as
# thread 1 (valid), read as edge 1, face 1, material 0, level 0.
WRAPPED = {
    "fixed_point_decode uint64": lambda: K.fixed_point_decode(np.array([2**32 + 5], np.uint64)),
    "fixed_point_accumulate": lambda: K.fixed_point_accumulate(np.array([1.0, 2.0]), np.array([2**32, 0]), 1),
    "cascade_dispatch": lambda: K.cascade_dispatch(np.array([2**32 + 1]), 256, 256, 2, 3),
    "cascade_intensity_scale": lambda: K.cascade_intensity_scale(np.array([2**32]), 2.0),
    "reuse_accepted": lambda: K.reuse_accepted(_P3, _Z, 0, _P3, _Z, np.array([2**32]), np.ones(1)),
    "gather_previous": lambda: K.gather_previous(_P3, _Z[None], np.array([2**32]), np.ones(1), _P3, _Z[None],
                                                 np.array([0]), np.ones(1), np.ones(1)),
    "edge_barycentric": lambda: cj.edge_barycentric(np.array([2**32 + 1]), np.array([0.3])),
    "cross_edge face": lambda: cj.cross_edge(_MESH, np.array([2**32 + 1]), np.array([0]), np.array([0.5])),
    "cross_edge edge": lambda: cj.cross_edge(_MESH, np.array([0]), np.array([2**32 + 1]), np.array([0.5])),
}


@pytest.mark.parametrize("name", list(WRAPPED))
def test_a_numpy_integer_beyond_int32_is_refused_not_wrapped(name):
    with cj.precision("float32"), pytest.raises(ValueError, match=r"must hold integers that fit u?int32"):
        WRAPPED[name]()


def test_a_32_bit_word_given_as_int64_decodes_and_a_negative_one_is_refused():
    """`fixed_point_decode` takes uint32 words (its `UInt32` annotation): int64 3e9 is a code
    (it had wrapped to a negative int32 and been refused), -1 is not."""
    with cj.precision("float32"):
        got = K.fixed_point_decode(np.array([3_000_000_000], np.int64))
        np.testing.assert_allclose(np.asarray(got), [3_000_000_000 * 2.0**-28], rtol=1e-7)
        with pytest.raises(ValueError, match="code must hold integers that fit uint32"):
            K.fixed_point_decode(np.array([-1], np.int64))


# --------------------------------------------------------------------------- directions


def _scene(dtype):
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    V = c([[-1, -1, 0], [3, -1, 0], [-1, 3, 0]])
    N = c(np.tile(_Z, (3, 1)))
    return c, V, N


def _normal_kernels(dtype):
    """The four kernels that take a receiver normal, as `normal -> (value, valid)`."""
    c, V, N = _scene(dtype)
    L, X, rp = c([0, 0, 3]), c([1, 1, 1]), c([0, 0, -2])
    l_dir = c(np.array([0.1, 0, -1]) / np.sqrt(1.01))  # a unit vector, as Alg. 2 takes it
    tri = (c([0, 0, 0]), c([0.01, 0, 0]), c([0, 0.01, 0]), c(_Z), c(_Z), c(_Z), l_dir)
    return {
        "path_irradiance": lambda n: cj.path_irradiance(V, N, c([-1, -1, -2]), c([-0.5, -1, 3]), c([0, 0]),
                                                        1.333, 1.0, n),
        "texel_jacobian": lambda n: (lambda out: (out[0], out[-1]))(cj.texel_jacobian(V, N, L, X, 1.333, rp, n)),
        "photon_differential_irradiance": lambda n: (
            lambda out: (out[0], out[-1]))(cj.photon_differential_irradiance(V, N, L, X, 1.333, 1.0, rp, n)),
        "compression_ratio_exact": lambda n: cj.compression_ratio_exact(*tri, rp, n),
    }


NORMAL_KERNELS = list(_normal_kernels(jnp.float32))
# lengths whose squares leave the dtype: safe_normalize had made them the zero vector
LENGTHS = {jnp.float32: (1e20, 1e-20), jnp.float64: (1e160, 1e-160)}


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("kernel", NORMAL_KERNELS)
def test_a_receiver_normal_of_any_finite_length_is_its_direction(kernel, dtype):
    """float32 1e20 and 1e-20 had given path_irradiance E = 0 valid, the others invalid lanes."""
    fn = _normal_kernels(dtype)[kernel]
    want, ok = fn(jnp.asarray(_Z, dtype))
    assert bool(ok)
    for length in LENGTHS[dtype]:
        got, ok = fn(jnp.asarray(_Z * length, dtype))
        assert bool(ok), length
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-6)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("kernel", ["path_irradiance", "texel_jacobian"])  # (the other two did this already)
@pytest.mark.parametrize("traced", [False, True])
def test_a_zero_or_infinite_receiver_normal_is_an_invalid_lane(kernel, dtype, traced):
    """path_irradiance had given E = 0 valid for a zero normal, texel_jacobian NaN for an infinite one."""
    fn = _normal_kernels(dtype)[kernel]
    call = jax.jit(fn) if traced else fn
    for bad in ([0.0, 0, 0], [0.0, 0, np.inf], [np.nan, 0, 1]):
        value, ok = call(jnp.asarray(bad, dtype))
        assert not bool(ok) and np.all(np.isfinite(np.asarray(value))), (bad, value)


def _alg2(dtype, **changes):
    """compression_ratio's arguments for a flat texel under light from above, with `changes`."""
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    args = dict(x00=c([0, 0, 0]), x10=c([0.01, 0, 0]), x01=c([0, 0.01, 0]), n00=c(_Z),
                n10=c(np.array([0.05, 0, 1]) / np.sqrt(1.0025)),
                n01=c(_Z), l_dir=c(np.array([0.3, 0, -1]) / np.sqrt(1.09)), t_hit=c(2.0))
    return {**args, **{k: c(v) if k in args else v for k, v in changes.items()}}


NOT_A_DIRECTION = {  # each had given sigma = 1 (or 0) marked valid
    "zero normals": dict(n00=[0, 0, 0.0], n10=[0, 0, 0.0], n01=[0, 0, 0.0]),
    "one zero normal": dict(n10=[0, 0, 0.0]),
    "light going up": dict(l_dir=[0, 0, 1.0]),
    "zero light direction": dict(l_dir=[0, 0, 0.0]),
    "a normal facing away": dict(n01=[0, 0, -1.0]),
    "t_hit = inf": dict(t_hit=np.inf),
}


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("case", list(NOT_A_DIRECTION))
def test_compression_ratio_marks_lanes_without_light_directions_invalid(case, dtype):
    args = _alg2(dtype, **NOT_A_DIRECTION[case])
    for mode in ("refract", "reflect"):
        sigma, ok = cj.compression_ratio(**args, mode=mode)
        assert not bool(ok) and float(sigma) == 0.0, mode
        if case != "t_hit = inf":
            rp, up = jnp.asarray([0, 0, -2.0 if mode == "refract" else 2.0], dtype), jnp.asarray(_Z, dtype)
            ratio, ok = cj.compression_ratio_exact(*(args[k] for k in list(args)[:7]), rp, up, mode=mode)
            assert not bool(ok) and float(ratio) == 0.0, mode


@pytest.mark.parametrize("dtype", DTYPES)
def test_compression_ratio_refuses_directions_that_are_not_unit_vectors(dtype):
    """Alg. 2 takes unit vectors: normals and light directions of length 2 and 3 had been
    used as unit vectors by GLSL's refract (a different sigma, valid). They mark the lane
    invalid; unit vectors rounded to float32 stay valid in float64 too."""
    want, ok = cj.compression_ratio(**_alg2(dtype))
    assert bool(ok)
    a = _alg2(dtype)
    for k in ("n00", "n10", "n01", "l_dir"):
        sigma, ok = cj.compression_ratio(**{**a, k: (2 if k.startswith("n") else 3) * a[k]})
        assert not bool(ok) and float(sigma) == 0.0, k
    rounded = {k: jnp.asarray(jnp.asarray(a[k], jnp.float32), dtype) for k in ("n00", "n10", "n01", "l_dir")}
    got, ok = cj.compression_ratio(**{**a, **rounded})
    assert bool(ok)
    np.testing.assert_allclose(float(got), float(want), rtol=1e-5)


# --------------------------------------------------------------------------- parameters
REFUSED = {  # kernel call with a concrete parameter outside its domain -> the message
    "compression_ratio level 0.5": (lambda: cj.compression_ratio(**_alg2(jnp.float64), level=0.5),
                                    "compression_ratio: level must be finite, whole and >= 0"),
    "compression_ratio level -3": (lambda: cj.compression_ratio(**_alg2(jnp.float64), level=-3),
                                   "compression_ratio: level must be finite, whole and >= 0"),
    "compression_ratio scale 0.5": (lambda: cj.compression_ratio(**_alg2(jnp.float64), scale=0.5),
                                    "compression_ratio: scale must be finite and >= 1"),
    "edge_intersections tol 1e6": (lambda: cj.edge_intersections(np.ones(6), tol=1e6),
                                   r"edge_intersections: tol must be finite and in \[0, 0.01\]"),
    "edge_intersections tol -1": (lambda: cj.edge_intersections(np.ones(6), tol=-1.0), "tol must be"),
    "edge_intersections tol nan": (lambda: cj.edge_intersections(np.ones(6), tol=np.nan), "tol must be"),
    "edge_barycentric edge 7": (lambda: cj.edge_barycentric(np.array([7]), np.array([0.3])),
                                r"edge_barycentric: edge must be in \[-1, 2\]"),
    "edge_barycentric edge -2": (lambda: cj.edge_barycentric(-2, 0.3), r"edge must be in \[-1, 2\]"),
    "cascade_projection level 0.5": (lambda: K.cascade_projection(512, 512, 1.5, 10.0, 2, 0.5),
                                     "cascade_projection: level must be finite, whole"),
    "cascade_projection near nan": (lambda: K.cascade_projection(512, 512, np.nan, 10.0, 2, 1),
                                    "cascade_projection: near must be finite"),
    "cascade_projection far inf": (lambda: K.cascade_projection(512, 512, 1.5, np.inf, 2, 1),
                                   "cascade_projection: far must be finite"),
    "light_position z_near inf": (lambda: K.light_position(np.zeros(3), -_Z, np.inf, 10.0),
                                  "light_position: z_near must be finite"),
    "luminance negative weight": (lambda: K.luminance(np.ones(3), (-1.0, 1.0, 1.0)),
                                  "luminance: weights must be finite and >= 0"),
    "ray_cone_propagate surface_spread nan": (
        lambda: K.ray_cone_propagate(np.array(0.0), np.array(1.0), np.array(3.0), np.nan),
        "ray_cone_propagate: surface_spread must be finite"),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_concrete_parameter_outside_its_domain_is_refused_naming_it(case):
    call, message = REFUSED[case]
    with pytest.raises(ValueError, match=message):
        call()


def _lane(dtype, name):
    """`value -> (result, valid)` of a kernel with a validity output, `name` traced."""
    c, V, N = _scene(dtype)
    L, X, rp = c([0, 0, 3]), c([1, 1, 1]), c([0, 0, -2])
    P, Lp, ab = c([-1, -1, -2]), c([-0.5, -1, 3]), c([0, 0])
    l_dir = c(np.array([0.1, 0, -1]) / np.sqrt(1.01))  # a unit vector, as Alg. 2 takes it
    tri = (c([0, 0, 0]), c([0.01, 0, 0]), c([0, 0.01, 0]), c(_Z), c(_Z), c(_Z), l_dir)
    return {
        "path_irradiance intensity": lambda v: cj.path_irradiance(V, N, P, Lp, ab, 1.333, v, c(_Z)),
        "path_irradiance sigma_t": lambda v: cj.path_irradiance(V, N, P, Lp, ab, 1.333, 1.0, c(_Z), v),
        "photon_differential_irradiance intensity": lambda v: (lambda o: (o[0], o[-1]))(
            cj.photon_differential_irradiance(V, N, L, X, 1.333, v, rp, c(_Z))),
        "photon_differential_irradiance sigma_t": lambda v: (lambda o: (o[0], o[-1]))(
            cj.photon_differential_irradiance(V, N, L, X, 1.333, 1.0, rp, c(_Z), v)),
        "compression_ratio eta": lambda v: cj.compression_ratio(**_alg2(dtype), eta=v),
        "compression_ratio level": lambda v: cj.compression_ratio(**_alg2(dtype), level=v),
        "compression_ratio scale": lambda v: cj.compression_ratio(**_alg2(dtype), scale=v),
        "compression_ratio_exact eta": lambda v: cj.compression_ratio_exact(*tri, rp, c(_Z), eta=v),
    }[name]


TRACED = {  # traced values outside the domain (each had given a valid lane), and one inside
    "path_irradiance intensity": ([np.inf], 1.0),
    "path_irradiance sigma_t": ([np.inf], 0.5),
    "photon_differential_irradiance intensity": ([np.inf], 1.0),
    "photon_differential_irradiance sigma_t": ([np.inf], 0.5),
    "compression_ratio eta": ([np.inf], 1.333),
    "compression_ratio level": ([-3.0, 0.5, np.inf], 2.0),
    "compression_ratio scale": ([0.5, 0.0, np.inf], 2.0),
    "compression_ratio_exact eta": ([np.inf], 1.333),
}


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", list(TRACED))
def test_a_traced_parameter_outside_its_domain_is_an_invalid_finite_lane(name, dtype):
    bad, good = TRACED[name]
    values = jnp.asarray([good, *bad], dtype)
    value, ok = jax.jit(jax.vmap(_lane(dtype, name)))(values)
    assert list(np.asarray(ok)) == [True] + [False] * len(bad)
    assert np.all(np.isfinite(np.asarray(value))) and not np.asarray(value)[1:].any()


def test_inside_jit_edge_gives_edge_2_and_tol_is_clipped_into_its_range():
    """Inside jit an edge outside [0, 2] gives edge 2's point (unchecked, finite); tol 1e6 had
    made every root of the edges' lines valid, -1 and NaN none."""
    bary = jax.jit(cj.edge_barycentric)
    # -1 is cross_edge's "no edge" on a boundary: accepted on the host too (edge 2's point)
    np.testing.assert_array_equal(np.asarray(cj.edge_barycentric(-1, 0.3)), np.asarray(cj.edge_barycentric(2, 0.3)))
    for edge, like in ((7, 2), (-1, 2), (3, 2)):
        np.testing.assert_array_equal(np.asarray(bary(edge, 0.3)), np.asarray(cj.edge_barycentric(like, 0.3)))
    coef = np.array([1.0, 1, 0, -3, -3, 2])  # circle through the edges' lines well outside [0, 1]
    roots = jax.jit(lambda tol: cj.edge_intersections(coef, tol=tol))
    for tol, like in ((1e6, EDGE_TOL_MAX), (-1.0, 0.0), (np.nan, None)):
        for got, want in zip(roots(tol), cj.edge_intersections(coef, tol=like), strict=True):
            np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


def test_inside_jit_a_negative_or_fractional_level_has_no_scale():
    """cascade_intensity_scale at level -1 had given s^-2 (0.25), cascade_projection at level 0.5
    the extent s^0.5."""
    scale = jax.jit(lambda c: K.cascade_intensity_scale(c, 2.0))
    assert float(scale(-1)) == 0.0 and float(scale(2)) == 16.0
    P = jax.jit(lambda c: K.cascade_projection(512, 512, 1.5, 10.0, 2.0, c))
    assert float(P(0.5)[0, 0]) == 0.0 and float(P(-1.0)[1, 1]) == 0.0
    np.testing.assert_allclose(float(P(1.0)[0, 0]), 2 / 1024)


# --------------------------------------------------------------------------- one domain check
# Every declared domain, on arrays and parameters alike, goes through `kernel_contract.check_domain`
# (the kernels' own range checks, which named no kernel, are gone). In the kernel's dtype a
# declared value must fit, and a positive one must be a normal number: float32 `refract` had
# run with eta = 1e-40 (flushed to zero by XLA) and eta = 1e39 (inf, T = 0) without a word.
_ONE = np.array(1.0)
DECLARED = {
    "bilateral_weight delta": (lambda: K.bilateral_weight(_ONE, _ONE, np.zeros(3), np.ones(3), -_ONE, 0.1),
                               "bilateral_weight: delta must be finite and > 0"),
    "ray_cone_radius width": (lambda: K.ray_cone_radius(-_ONE), "ray_cone_radius: width must be finite and >= 0"),
    "pixel_spread_angle fov_y": (lambda: K.pixel_spread_angle(np.array(np.pi), 1080),
                                 r"pixel_spread_angle: fov_y must be finite and in \(0, 3.14159\)"),
    "ray_cone_propagate spread": (lambda: K.ray_cone_propagate(_ONE, np.array(4.0), _ONE),
                                  r"ray_cone_propagate: spread must be finite and in \[0, 3.14159\)"),
    "intensity_attenuation gamma": (lambda: K.intensity_attenuation(_ONE, 10.0, 1.0),
                                    r"intensity_attenuation: gamma must be finite and in \(0, 1\)"),
    "temporal_ema alpha": (lambda: K.temporal_ema(np.ones(3), np.ones(3), 2.0),
                           r"temporal_ema: alpha must be finite and in \[0, 1\]"),
    "fixed_point_encode x": (lambda: K.fixed_point_encode(np.array([-1.0])), "fixed_point_encode: x must be"),
    "fixed_point_accumulate segment_ids": (lambda: K.fixed_point_accumulate(np.array([1.0]), np.array([5]), 2),
                                           r"fixed_point_accumulate: segment_ids must be in \[0, 1\]"),
    "sprite_size sigma": (lambda: K.sprite_size(4.0, 4.0, 256, 256, 1.0, -_ONE), "sprite_size: sigma must be"),
    "cascade_projection width": (lambda: K.cascade_projection(0, 512, 1.5, 10.0, 2, 1),
                                 "cascade_projection: width must be finite and > 0"),
    "cascade_intensity_scale s": (lambda: K.cascade_intensity_scale(1, 0.5),
                                  "cascade_intensity_scale: s must be finite and >= 1"),
    "fresnel_reflect_approx f_frac": (lambda: K.fresnel_reflect_approx(-_Z, _Z, 2.0),
                                      r"fresnel_reflect_approx: f_frac must be finite and in \[0, 1\]"),
    "ray_cone_propagate spread rounding onto pi": (
        lambda: K.ray_cone_propagate(_ONE.astype(np.float32), np.array(3.14159265), _ONE.astype(np.float32)),
        r"spread must be finite and in \[0, 3.14159\) in float32, got \[3.14159265\], which rounds to"),
    "intensity_attenuation gamma rounding onto 1": (lambda: K.intensity_attenuation(_ONE, 10.0, 1 - 1e-9),
                                                    r"gamma must be finite and in \(0, 1\) in float32"),
    "fixed_point_accumulate whole bound": (
        lambda: K.fixed_point_accumulate(np.array([1.0]), np.array([2**24]), 2**24),
        r"segment_ids must be in \[0, 16777215\]"),
    "refract eta subnormal": (lambda: cj.refract(-_Z.astype(np.float32), _Z.astype(np.float32), 1e-40),
                              "refract: eta must be at least 1.175e-38, the smallest normal float32"),
    "refract eta overflow": (lambda: cj.refract(-_Z.astype(np.float32), _Z.astype(np.float32), 1e39),
                             r"refract: eta overflows float32, the kernel.s dtype"),
    "bilateral_weight eps subnormal": (
        lambda: K.bilateral_weight(*(np.asarray(x, np.float32) for x in (1.0, 1.0, np.zeros(3), np.ones(3), 1.0)),
                                   1e-40),
        "bilateral_weight: eps must be at least 1.175e-38, the smallest normal float32"),
    "compression_ratio eta subnormal": (lambda: cj.compression_ratio(**_alg2(jnp.float32), eta=1e-40),
                                        "compression_ratio: eta must be at least 1.175e-38"),
}


@pytest.mark.parametrize("case", list(DECLARED))
def test_a_declared_domain_is_checked_once_naming_the_kernel(case):
    call, message = DECLARED[case]
    with cj.precision("float32"), pytest.raises(ValueError, match=message):
        call()


def test_a_positive_parameter_normal_in_float64_is_accepted_there():
    """1e-40 is subnormal in float32 only: float64 `refract` takes it, float32 refuses it."""
    with cj.precision("float64"):
        T = cj.refract(-_Z, _Z, 1e-40)
    np.testing.assert_allclose(np.asarray(T), -_Z)
    with cj.precision("float32"), pytest.raises(ValueError, match="smallest normal float32"):
        cj.refract(-_Z.astype(np.float32), _Z.astype(np.float32), 1e-40)
