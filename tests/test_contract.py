"""The input contract (docs/input_contract.md): kernels promote integer, half and mixed
input by one rule and refuse bool and complex; every API option is refused with a
ValueError naming it, before any jitted work; zero lanes give empty results everywhere."""

import importlib
import inspect

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import caustics_jax as cj
import caustics_jax.kernels as K
import caustics_jax.transport as T
from caustics_jax import scenes
from caustics_jax.accel import occlusion
from caustics_jax.accel.bvh import first_hit_bvh
from caustics_jax.accel.face_cells import bin_faces, first_hit_cells
from caustics_jax.app import compare
from caustics_jax.runtime import arguments
from caustics_jax.solvers import _solve
from caustics_jax.transport.visibility import path_visible

start_points_module = importlib.import_module("caustics_jax.accel.start_points")  # (cj.start_points is the function)

# --------------------------------------------------------------------------- kernels
# One example per public kernel, arrays integer-valued where the kernel takes float data, so
# the same numbers can be passed as integers. Python floats are parameters (eta, ...): the
# contract says integer arrays must never truncate them.
_V = np.array([[-1, -1, 0], [3, -1, 0], [-1, 3, 0]], float)
_N_FLAT = np.tile([0.0, 0.0, 1.0], (3, 1))
_N_CURVED = np.array([[0, 0, 1], [1, 0, 2], [0, 1, 2]], float)
_Z = np.array([0.0, 0.0, 1.0])
_X = np.array([1.0, 0.0, 0.0])
_COEF = np.array([1, 2, 0, -1, -1, 0], float)
_P, _L = np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 3.0])
_P2, _L2 = np.array([-1.0, -1.0, -2.0]), np.array([-1.0, -1.0, 3.0])
_AB = np.array([1.0, 1.0])
_IMG = np.arange(48.0).reshape(4, 4, 3) % 5, np.arange(16.0).reshape(4, 4) % 3, np.arange(48.0).reshape(4, 4, 3)

KERNELS = {
    "refract": (cj.refract, (_X, _Z, 1.333)),
    "reflect": (cj.reflect, (np.array([1.0, 0, -1]), _Z)),
    "fresnel_reflectance": (cj.fresnel_reflectance, (np.array(1.0), 1.333)),
    "fresnel_transmittance": (cj.fresnel_transmittance, (np.array(1.0), 1.333)),
    "safe_normalize": (cj.safe_normalize, (np.array([3.0, 4, 0]),)),
    "barycentric_point": (cj.barycentric_point, (_V, _AB)),
    "edge_barycentric": (cj.edge_barycentric, (np.array(1), np.array(1.0))),
    "interpolated_normal": (cj.interpolated_normal, (_N_CURVED, _AB)),
    "conic_coefficients": (cj.conic_coefficients, (_V, _N_CURVED, _P, _L)),
    "conic_tangent": (cj.conic_tangent, (_COEF, _AB)),
    "conic_value": (cj.conic_value, (_COEF, _AB)),
    "edge_intersections": (cj.edge_intersections, (_COEF,)),
    "solve_quadratic": (cj.solve_quadratic, (np.array(1.0), np.array(-3.0), np.array(2.0))),
    "tangent_to_world": (cj.tangent_to_world, (_V, np.array([1.0, -1]))),
    "signed_sine": (cj.signed_sine, (_V, _N_CURVED, _P, _L, _AB, 1.333)),
    "signed_sine_and_status": (cj.signed_sine_and_status, (_V, _N_CURVED, _P, _L, _AB, 1.333)),
    "half_vector_residual": (cj.half_vector_residual, (_V, _N_CURVED, _P, _L, _AB, 1.333)),
    "angle_difference_residual": (cj.angle_difference_residual, (_V, _N_CURVED, _P, _L, _AB, 1.333)),
    "ray_differential_D": (cj.ray_differential_D, (_V, _N_FLAT, _P2, _L2, np.zeros(2), 1.333)),
    "autodiff_D": (cj.autodiff_D, (_V, _N_FLAT, _P2, _L2, np.zeros(2), 1.333)),
    "path_irradiance": (cj.path_irradiance, (_V, _N_FLAT, _P2, _L2, np.zeros(2), 1.333, 1.0, _Z)),
    "compression_ratio": (cj.compression_ratio, (np.zeros(3), _X, np.array([0.0, 1, 0]), _Z, _Z, _Z,
                                                 -_Z, np.array(2.0))),
    "compression_ratio_exact": (cj.compression_ratio_exact, (np.zeros(3), _X, np.array([0.0, 1, 0]), _Z, _Z, _Z,
                                                             -_Z, np.array([0.0, 0, -2]), _Z)),
    "footprint_ellipse": (cj.footprint_ellipse, (np.array([2.0, 0]), np.array([1.0, 1]))),
    "texel_jacobian": (cj.texel_jacobian, (_V, _N_FLAT, np.array([0.0, 0, 3]), np.array([1.0, 1, 1]), 1.333,
                                           np.array([0.0, 0, -2]), _Z)),
    "photon_differential_irradiance": (cj.photon_differential_irradiance,
                                       (_V, _N_FLAT, np.array([0.0, 0, 3]), np.array([1.0, 1, 1]), 1.333, 1.0,
                                        np.array([0.0, 0, -2]), _Z)),
    "cross_edge": (lambda face, edge, t: cj.cross_edge(_MESH, face, edge, t), (np.array(0), np.array(1),
                                                                               np.array(0.0))),
    "kernels.intensity_attenuation": (K.intensity_attenuation, (np.array([0.0, 1, 2, 5]), 10.0)),
    "kernels.fresnel_reflect_approx": (K.fresnel_reflect_approx, (np.array([1.0, 0, -1]), _Z, 0.02)),
    "kernels.fresnel_refract_approx": (K.fresnel_refract_approx, (np.array([1.0, 0, -1]), _Z, 0.02)),
    "kernels.ray_intensity": (K.ray_intensity, (np.array(2.0), np.array(1.0), np.array(1.0))),
    "kernels.throughput": (K.throughput, (np.array([1.0, 0.0]), np.array([1.0, 2.0]), 0.75, 0.1)),
    "kernels.photon_budget": (K.photon_budget, (np.array([0.0, 1.0, 4.0]), 100.0)),
    "kernels.energy_cull": (K.energy_cull, (np.array([2.0, 0.0]), np.array([1.0, 1.0]))),
    "kernels.photon_cull": (K.photon_cull, (np.array([1.0, 2.0]), np.array([1.0, 0.0]), np.array([1.0, 1.0]),
                                            np.array([0.0, 1.0]))),
    "kernels.throughput_cull": (K.throughput_cull, (np.array([1.0, 1.0]), np.array([1.0, 2.0]),
                                                    np.array([0.0, 1.0]), 0.75, 0.1)),
    "kernels.bilateral_weight": (K.bilateral_weight, (np.array(1.0), np.array(2.0), _X, np.zeros(3), np.array(3.0))),
    "kernels.luminance": (K.luminance, (np.array([1.0, 2, 3]),)),
    "kernels.adaptive_kernel_params": (K.adaptive_kernel_params, (np.array([0.0, 1, 5]), 20.0)),
    "kernels.denoise_subpass": (K.denoise_subpass, (*_IMG, 10.0)),
    "kernels.bilateral_denoise": (K.bilateral_denoise, (*_IMG, 10.0)),
    "kernels.light_position": (K.light_position, (np.zeros(3), -_Z, 1.5, 10.0)),
    "kernels.cascade_projection": (K.cascade_projection, (512, 512, 1.5, 10.0, 2, 1)),
    "kernels.cascade_intensity_scale": (K.cascade_intensity_scale, (np.array([0, 1, 2]), 2)),
    "kernels.cascade_dispatch": (K.cascade_dispatch, (np.array([0, 5, 20]), 8, 8, 2, 2)),
    "kernels.pixel_spread_angle": (K.pixel_spread_angle, (np.array(1.0), 1080)),
    "kernels.ray_cone_propagate": (K.ray_cone_propagate, (np.array(0.0), np.array(1.0), np.array(3.0))),
    "kernels.ray_cone_radius": (K.ray_cone_radius, (np.array(0.0),)),
    "kernels.pixel_footprint_radius": (K.pixel_footprint_radius, (np.array(1.0), np.array(1.0), np.array(1.0))),
    "kernels.cylinder_aabb": (K.cylinder_aabb, (np.zeros(3), _Z, np.array(1.0))),
    "kernels.in_cylinder": (K.in_cylinder, (np.zeros(3), np.zeros(3), _Z, np.array(1.0))),
    "kernels.reuse_accepted": (K.reuse_accepted, (np.zeros(3), _Z, np.array(1), np.zeros(3), _Z, np.array(1),
                                                  np.array(1.0))),
    "kernels.reuse_weight": (K.reuse_weight, (_X, np.zeros(3), np.array(2.0))),
    "kernels.resolve": (K.resolve, (np.array(1.0), np.array(2.0), np.array(1.0))),
    "kernels.temporal_ema": (K.temporal_ema, (np.array(1.0), np.array(2.0))),
    "kernels.gather_previous": (K.gather_previous, (np.zeros((2, 3)), np.tile(_Z, (2, 1)), np.array([1, 1]),
                                                    np.ones(2), np.zeros((2, 3)), np.tile(_Z, (2, 1)),
                                                    np.array([1, 1]), np.ones(2), np.array([3.0, 5.0]))),
    "kernels.fixed_point_encode": (K.fixed_point_encode, (np.array([1.0, 2.0]),)),
    "kernels.fixed_point_decode": (K.fixed_point_decode, (np.array([2**28, 2**29], np.uint32),)),
    "kernels.fixed_point_accumulate": (K.fixed_point_accumulate, (np.array([1.0, 2.0]),)),
    "kernels.projected_photon_position": (K.projected_photon_position, (np.zeros(3), np.array([1.0, 0, -2]), -_Z)),
    "kernels.ray_plane_intersection": (K.ray_plane_intersection, (np.zeros(3), -_Z, np.array([0.0, 0, -2]), _Z)),
    "kernels.sprite_basis": (K.sprite_basis, (np.array([1.0, 0, -1]), _Z)),
    "kernels.sprite_corners": (K.sprite_corners, (np.zeros(3), np.array(2.0), np.array(1.0), _X,
                                                  np.array([0.0, 1, 0]))),
    "kernels.sprite_foreshortening": (K.sprite_foreshortening, (-_Z, _Z)),
    "kernels.sprite_intensity": (K.sprite_intensity, (np.array(1.0), np.array(1.0), np.array(2.0))),
    "kernels.sprite_size": (K.sprite_size, (4.0, 4.0, 256, 256, 1.0, np.array(2.0))),
    "kernels.schlick_f0": (K.schlick_f0, (np.array(2.0),)),
    "transport.triangle_area": (T.triangle_area, (np.zeros(3), _X, np.array([0.0, 2, 0]))),
}
# Public callables that are not array kernels: static configuration (Python numbers in and
# out), checked by their own ValueErrors.
STATIC = {"ccm0_size", "cascade_deltas", "cascade_thread_counts"}
_MESH = cj.SurfaceMesh.from_arrays(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]]),
                                   np.array([[0, 1, 2], [1, 3, 2]]), dtype="float64")


# Public functions of `caustics_jax.transport` that are host-level (they take a mesh, a
# grid, a generator), not array kernels: each validates its own arguments (tests in
# tests/transport and below).
TRANSPORT_HOST = {"irradiance", "photon_irradiance", "trace_photons", "sms_biased", "sms_unbiased", "splat_footprints",
                  "path_visible", "surface_hits", "surface_starts"}


def _public_kernels():
    names = {n for n in cj.__all__ if hasattr(getattr(cj, n), "input_contract")}
    names |= {f"kernels.{n}" for n in K.__all__
              if inspect.isfunction(getattr(K, n)) and n not in STATIC}
    names |= {n if n in cj.__all__ else f"transport.{n}" for n in T.__all__
              if inspect.isfunction(getattr(T, n)) and n not in TRANSPORT_HOST}
    return names | {"cross_edge"}


def _kernel(name):
    module, _, short = name.rpartition(".")
    return getattr({"kernels": K, "transport": T, "": cj}[module], short)


def test_every_public_kernel_has_a_contract_and_a_case_here():
    assert _public_kernels() == set(KERNELS), "add the kernel to KERNELS (and decorate it with float_inputs)"
    for name in KERNELS:
        if name != "kernels.schlick_f0":  # Python float for a Python number, else the contract
            assert hasattr(_kernel(name), "input_contract"), name


def _data_args(name):
    """Indices of the example's float array arguments (the ones a caller passes as data)."""
    _, args = KERNELS[name]
    return [i for i, a in enumerate(args) if isinstance(a, np.ndarray) and a.dtype.kind == "f"]


def _leaves(out):
    return [np.asarray(x) for x in jax.tree.leaves(out)]


def _call(name, args):
    fn, _ = KERNELS[name]
    return _leaves(fn(*args))


def _with(name, convert):
    _, args = KERNELS[name]
    data = _data_args(name)
    return [convert(a) if i in data else a for i, a in enumerate(args)]


# Kernels whose result dtype is fixed by something else than their array inputs.
FIXED_DTYPE = {"cross_edge": np.float64}  # the mesh's dtype


def _assert_same(got, want, dtype, name=None):
    dtype = FIXED_DTYPE.get(name, dtype)
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        if w.dtype.kind == "f":
            assert g.dtype == dtype, f"result dtype {g.dtype}, expected {dtype}"
        np.testing.assert_array_equal(g, w)


@pytest.mark.parametrize("name", sorted(KERNELS))
def test_integer_half_and_mixed_input_give_the_float_result(name):
    """Integers are values (they take the float dtype: float64 here, x64 being on), half
    precision computes in float32, float32 with float64 gives float64; parameters keep
    their value (never truncated by an integer array). Results equal the float input's
    exactly: the cast is exact and the arithmetic the same."""
    if not _data_args(name):
        pytest.skip("no float data argument (static parameters only)")
    f64 = _call(name, _with(name, lambda a: a.astype(np.float64)))
    ints = _call(name, _with(name, lambda a: a.astype(np.int32)))
    _assert_same(ints, f64, np.float64, name)
    first = _data_args(name)[0]
    mixed = [a.astype(np.int64) if i in _data_args(name) and i != first else a
             for i, a in enumerate(_with(name, lambda a: a.astype(np.float64)))]
    _assert_same(_call(name, mixed), f64, np.float64, name)
    half = _with(name, lambda a: a.astype(np.float16))
    f32 = _call(name, [a.astype(np.float32) if i in _data_args(name) else a for i, a in enumerate(half)])
    _assert_same(_call(name, half), f32, np.float32, name)


def test_bfloat16_is_half_precision_too():
    # (one kernel: bfloat16 takes the same branch of the rule as float16)
    x = jnp.asarray([0.25, 1.0], jnp.bfloat16)
    got = cj.fresnel_reflectance(x, 1.333)
    assert got.dtype == jnp.float32
    np.testing.assert_array_equal(got, cj.fresnel_reflectance(np.asarray(x, np.float32), 1.333))


@pytest.mark.parametrize("name", sorted(KERNELS))
@pytest.mark.parametrize("kind", ["bool", "complex"])
def test_bool_and_complex_input_is_refused_naming_the_function(name, kind):
    fn, args = KERNELS[name]
    targets = [i for i, a in enumerate(args) if isinstance(a, np.ndarray)]
    if not targets:
        pytest.skip("no array argument")
    bad = list(args)
    bad[targets[0]] = args[targets[0]].astype(bool if kind == "bool" else np.complex64)
    with pytest.raises(ValueError, match=kind if kind == "bool" else "complex|integers"):
        fn(*bad)


@pytest.mark.parametrize("name", sorted(n for n in KERNELS if not n.startswith("kernels.") or n in {
    "kernels.fresnel_reflect_approx", "kernels.sprite_basis", "kernels.cylinder_aabb", "kernels.ray_plane_intersection",
    "kernels.light_position", "kernels.reuse_weight", "kernels.projected_photon_position"}))
def test_a_wrong_trailing_axis_or_unbroadcastable_batch_is_a_value_error(name):
    fn, args = KERNELS[name]
    vec = [i for i, a in enumerate(args) if isinstance(a, np.ndarray) and a.ndim >= 1 and a.shape[-1] == 3]
    if not vec:
        pytest.skip("no (..., 3) argument")
    bad = list(args)
    bad[vec[0]] = args[vec[0]][..., :2]
    with pytest.raises(ValueError):
        fn(*bad)
    arrays = [i for i, a in enumerate(args) if isinstance(a, np.ndarray)]
    if len(arrays) >= 2:
        bad = list(args)
        bad[arrays[0]] = np.stack([args[arrays[0]]] * 2)
        bad[arrays[1]] = np.stack([args[arrays[1]]] * 3)
        with pytest.raises(ValueError, match="broadcast"):
            fn(*bad)


@pytest.mark.parametrize("name", sorted(n for n in KERNELS if n not in {
    "kernels.denoise_subpass", "kernels.bilateral_denoise", "kernels.gather_previous", "kernels.fixed_point_accumulate",
    "kernels.cascade_projection", "kernels.cascade_dispatch", "kernels.sprite_size", "edge_intersections"}))
def test_an_empty_batch_gives_an_empty_result(name):
    fn, args = KERNELS[name]
    empty = [np.zeros((0, *a.shape), a.dtype) if isinstance(a, np.ndarray) else a for a in args]
    for out in _leaves(fn(*empty)):
        assert out.shape[:1] == (0,)


# Physical parameters of the transport kernels: their domain is declared in the contract
# (`float_inputs(positive=..., nonnegative=...)`), concrete values outside it are refused.
DOMAINS = {"eta": "positive", "intensity": "nonnegative", "sigma_t": "nonnegative"}


def _domain_cases():
    for name in sorted(KERNELS):
        fn, _ = KERNELS[name]
        contract = getattr(fn, "input_contract", None)
        for param in (contract or {}).get("params", ()):
            if param in DOMAINS:
                yield name, param


def test_every_eta_intensity_and_sigma_t_parameter_declares_its_domain():
    cases = list(_domain_cases())
    assert len(cases) >= 15, cases
    for name, param in cases:
        contract = KERNELS[name][0].input_contract
        assert param in contract[DOMAINS[param]], f"{name}: {param} must be declared {DOMAINS[param]}"


@pytest.mark.parametrize("name, param", list(_domain_cases()), ids=lambda x: str(x))
def test_a_parameter_outside_its_physical_domain_is_refused_naming_it(name, param):
    """eta <= 0 gave ray_differential_D valid lanes (D 4.0 at eta 0), a negative sigma_t an
    amplified irradiance, a negative intensity a negative one, all marked valid."""
    fn, args = KERNELS[name]
    index = list(inspect.signature(fn).parameters).index(param)
    bad_values = [-1.0, float("nan"), float("inf"), np.array([1.0, -2.0])]
    if DOMAINS[param] == "positive":
        bad_values.append(0.0)
    for bad in bad_values:
        call, kwargs = list(args), {}
        if index < len(args):
            call[index] = bad
        else:
            kwargs[param] = bad
        with pytest.raises(ValueError, match=rf"{name.split('.')[-1]}: {param} must be finite and"):
            fn(*call, **kwargs)


@pytest.mark.parametrize("name", ["ray_differential_D", "path_irradiance", "texel_jacobian",
                                  "photon_differential_irradiance", "compression_ratio",
                                  "compression_ratio_exact"])
def test_a_traced_parameter_outside_its_domain_gives_invalid_finite_lanes(name):
    """Inside jit the values are unknown at the boundary: the kernel marks those lanes invalid
    (its last output) with finite values, and keeps a valid lane valid."""
    fn, args = KERNELS[name]
    params = list(inspect.signature(fn).parameters)
    for param in [p for p in fn.input_contract["params"] if p in DOMAINS]:
        index = params.index(param)
        good = args[index] if index < len(args) else inspect.signature(fn).parameters[param].default
        values = jnp.asarray([good, -1.0, float("nan")] + ([0.0] if DOMAINS[param] == "positive" else []))

        def lane(v, param=param, index=index):
            call, kwargs = list(args), {}
            if index < len(args):
                call[index] = v
            else:
                kwargs[param] = v
            return fn(*call, **kwargs)

        out = _leaves(jax.jit(jax.vmap(lane))(values))
        valid = out[-1]
        assert valid.dtype == bool and valid[0] and not valid[1:].any(), (param, valid)
        for leaf in out:
            assert np.all(np.isfinite(leaf)), (param, leaf)


def test_integer_arrays_never_truncate_eta_the_issue_examples():
    # Float input: a ray along +x onto a +z normal is grazing, and eta > 1 makes it TIR:
    # k = 1 - eta^2 (1 - 0) < 0, so refract returns the zero vector (GLSL semantics).
    np.testing.assert_array_equal(cj.refract(np.array([1, 0, 0]), np.array([0, 0, 1]), 1.333), np.zeros(3))
    # Normal incidence: R = ((eta - 1) / (eta + 1))^2 = (0.333 / 2.333)^2 = 0.020373...
    np.testing.assert_allclose(cj.fresnel_reflectance(np.array(1), 1.333), (0.333 / 2.333) ** 2, rtol=1e-12)
    # An integer eta is a value too, and float32 data keep a float64 eta from promoting.
    assert cj.refract(np.array([0, 0, -1.0], np.float32), np.array([0, 0, 1.0], np.float32),
                      np.float64(1.333)).dtype == np.float32


def test_float16_is_computed_in_float32_where_float16_itself_would_overflow():
    # 4.28 fixed point scales by 2^28: in float16 that overflows (max 65504) to a wrong code.
    assert K.fixed_point_encode(np.array([1.0], np.float16))[0] == 2**28


# --------------------------------------------------------------------------- options


@pytest.fixture(scope="module")
def pool():
    sc = scenes.wavy_pool(512, dtype="float32")
    P = np.asarray(sc.receivers[:8])
    return sc.surface, P, np.asarray(sc.lights.endpoint(sc.receivers[:8]))


@pytest.fixture
def no_jit_work(monkeypatch):
    """Fail if a solve gets as far as running lanes: refusals must come first."""
    def boom(*a, **k):
        raise AssertionError("jitted work started before the argument was refused")

    monkeypatch.setattr(_solve, "_solve_blocks", boom)
    for whole in (cj.Exhaustive, cj.Trace):  # the solvers run on the whole batch
        monkeypatch.setattr(whole, "solve_whole", boom)


BAD_OPTIONS = [
    ("walk", "tol", v) for v in (10, 1.0, 0.0, -1e-3, float("nan"), "1e-3", True, 1e-3j, np.array([1e-3]))
] + [
    (m, name, v) for m, name in (("walk", "max_steps"), ("walk", "ellipse_samples"), ("newton", "max_patches"),
                                 ("newton", "inner_steps"), ("newton", "n_starts"))
    for v in (2**40, 0, -1, 1.5, True, "10", float("nan"))
] + [
    ("walk", "bracket", "x"), ("newton", "solver", "x"), ("newton", "constraint", None), ("newton", "seed", -1),
    ("newton", "tol", 2.0), ("exhaustive", "iters", 0), ("exhaustive", "chunk", 0), ("exhaustive", "dedupe", -1.0),
    ("exhaustive", "dedupe", float("nan")), ("exhaustive", "return_all", "yes"), ("exhaustive", "cull", 1),
    ("exhaustive", "tol", 0.0),
]


@pytest.mark.parametrize("method, name, value", BAD_OPTIONS, ids=lambda x: repr(x)[:20])
def test_a_bad_solver_option_is_a_value_error_naming_it_before_any_work(pool, no_jit_work, method, name, value):
    mesh, P, L = pool
    with pytest.raises(ValueError, match=name):
        cj.solve(mesh, P, L, method=method, **{name: value})


@pytest.mark.parametrize("eta", [-1.0, 0.0, float("nan"), float("inf"), 1.3 + 0j, np.array([1.3, 1.3]), "1.3",
                                 True, None])
def test_eta_must_be_one_finite_positive_real(pool, no_jit_work, eta):
    mesh, P, L = pool
    with pytest.raises(ValueError, match="eta"):
        cj.solve(mesh, P, L, eta=eta)
    with pytest.raises(ValueError, match="eta"):
        cj.irradiance(mesh, P, L, eta=eta, intensity=1.0, receiver_normal=[0, 0, 1])


def test_numpy_and_jax_scalars_are_accepted_as_options():
    assert cj.Walk(tol=np.float32(1e-4), max_steps=np.int64(100)).max_steps == 100
    assert cj.Walk(tol=jnp.asarray(1e-4)).tol == pytest.approx(1e-4)
    assert cj.Newton(seed=np.uint8(3)).seed == 3


@pytest.mark.parametrize("start, match", [
    ("abc", "start must"),
    ((np.zeros(3, int), np.zeros((3, 2)), np.ones(3, bool)), r"for the\s+8 lanes"),
    ((np.zeros(8), np.zeros((8, 2)), np.ones(8, bool)), "face must hold integers"),
    ((np.zeros(8, int), np.zeros((8, 2)), np.ones(8)), "found booleans"),
    ((np.full(8, 10**6), np.zeros((8, 2)), np.ones(8, bool)), r"face must lie in \[0, "),
    ((np.zeros(8, int), np.full((8, 2), np.nan), np.ones(8, bool)), "barycentric must hold finite"),
])
def test_a_bad_start_is_a_value_error(pool, no_jit_work, start, match):
    mesh, P, L = pool
    with pytest.raises(ValueError, match=match):
        cj.solve(mesh, P, L, start=start)


@pytest.mark.parametrize("P, match", [
    (lambda P: P.astype(bool), "P must hold real"), (lambda P: P.astype(complex), "P must hold real"),
    (lambda P: "abc", "P must hold real"), (lambda P: None, "P must"), (lambda P: P[:, :2], r"P must have shape"),
    (lambda P: np.where(np.arange(8)[:, None] == 2, np.nan, P), r"P has NaN.*rows \[2\]"),
    (lambda P: P.astype(np.float64) * 1e39, "overflow float32"),
])
def test_bad_points_are_refused_by_solve_irradiance_and_start_points(pool, no_jit_work, P, match):
    mesh, P0, L = pool
    with pytest.raises(ValueError, match=match):
        cj.solve(mesh, P(P0), L)
    with pytest.raises(ValueError, match=match):
        cj.irradiance(mesh, P(P0), L, intensity=1.0, receiver_normal=[0, 0, 1])
    if match.startswith("P must hold"):
        with pytest.raises(ValueError, match=match):
            cj.start_points(mesh, P(P0), L)


@pytest.mark.parametrize("kwargs, match", [
    (dict(intensity=-1.0), "intensity"), (dict(intensity=float("nan")), "intensity"), (dict(intensity=1j), "intensity"),
    (dict(intensity="1"), "intensity"), (dict(intensity=True), "intensity"), (dict(intensity=np.ones(3)), "intensity"),
    (dict(intensity=None), "intensity"), (dict(sigma_t=-1.0), "sigma_t"), (dict(sigma_t="x"), "sigma_t"),
    (dict(sigma_t=np.ones(8)), "sigma_t"), (dict(sigma_t=1j), "sigma_t"), (dict(sigma_t=None), "sigma_t"),
    (dict(receiver_normal=[0, 0, 0]), "receiver_normal"), (dict(receiver_normal=[np.nan, 0, 1]), "receiver_normal"),
    (dict(receiver_normal=[0, 1]), "receiver_normal"), (dict(receiver_normal="up"), "receiver_normal"),
    (dict(receiver_normal=[0, 0, 1j]), "receiver_normal"),
    (dict(receiver_normal=[True, False, True]), "receiver_normal"),
    (dict(receiver_normal=np.ones((3, 3))), "receiver_normal"), (dict(all_paths="yes"), "all_paths"),
    (dict(all_paths=None), "all_paths"), (dict(return_solution=1), "return_solution"),
    (dict(features="x"), "features"), (dict(method="x"), "method"), (dict(tol=10), "tol"),
])
def test_a_bad_irradiance_argument_is_a_value_error_naming_it(pool, no_jit_work, kwargs, match):
    mesh, P, L = pool
    args = dict(intensity=1.0, receiver_normal=[0, 0, 1]) | kwargs
    with pytest.raises(ValueError, match=match):
        cj.irradiance(mesh, P, L, **args)


@pytest.mark.parametrize("kwargs, match", [
    (dict(eta=1e39), "eta overflows float32"), (dict(intensity=1e39), "intensity overflows float32"),
    (dict(eta=1e-40), "eta must be at least 1.175e-38, the smallest normal float32"),
    (dict(sigma_t=1e39), "sigma_t overflows float32"), (dict(tol=1e-30), "below float32's resolution"),
    (dict(tol=1e-8), "below float32's resolution"), (dict(method="trace"), "returns every path"),
    (dict(method=cj.Trace()), "returns every path"), (dict(method="exhaustive", return_all=True), "returns every path"),
])
def test_values_the_mesh_dtype_cannot_hold_or_resolve_are_refused(pool, no_jit_work, kwargs, match):
    """Scalars are checked against the dtype they are cast to (float32 `eta=1e39` had run
    as inf and ended every lane LEFT_MESH, `eta=1e-40` as 0, flushed by XLA), a `tol` below
    the dtype's epsilon can certify no point, and `irradiance` refuses a solver returning
    every path without `all_paths`."""
    mesh, P, L = pool
    irr = dict(intensity=1.0, receiver_normal=[0, 0, 1]) | kwargs
    with pytest.raises(ValueError, match=match):
        cj.irradiance(mesh, P, L, **irr)
    solve_kwargs = {k: v for k, v in kwargs.items() if k not in ("intensity", "sigma_t")}
    if solve_kwargs and "method" not in solve_kwargs:
        with pytest.raises(ValueError, match=match):
            cj.solve(mesh, P, L, **solve_kwargs)


def test_exhaustive_on_float32_names_the_dtype_not_its_tolerance(pool, no_jit_work):
    """The exhaustive reference's float64 tolerance (1e-9) is below float32's epsilon: the
    dtype is the problem, and the message says so (the tol check had answered first)."""
    mesh, P, L = pool
    for call in (lambda: cj.solve(mesh, P, L, method="exhaustive"), lambda: cj.solve(mesh, P[:0], L[:0],
                 method="exhaustive"),
                 lambda: cj.irradiance(mesh, P, L, intensity=1.0, receiver_normal=[0, 0, 1], method="exhaustive",
                                       all_paths=True)):
        with pytest.raises(ValueError, match="float64 reference"):
            call()


@pytest.mark.parametrize("kwargs, match", [
    (dict(method=cj.Walk(), all_paths=True), "a Walk object returns one path"),
    (dict(method="walk", all_paths=True, solutions="all"), "leave solutions out"),
])
def test_all_paths_refuses_a_single_path_object_and_a_second_solutions(pool, no_jit_work, kwargs, match):
    mesh, P, L = pool
    with pytest.raises(ValueError, match=match):
        cj.irradiance(mesh, P, L, intensity=1.0, receiver_normal=[0, 0, 1], **kwargs)


def test_every_path_on_a_scaled_float32_pool_counts_each_path_once(pool):
    """`Trace`'s default dedupe radius follows the mesh's largest coordinate: on the pool
    scaled by 1e3 a fixed 1e-4 m had kept float32 duplicates 1.7e-4 m apart (irradiance
    with all_paths twice the single path on 8 of 16 lanes)."""
    mesh, P, L = pool
    V, F, N = (np.asarray(x, np.float64) for x in (mesh.vertices, mesh.faces, mesh.normals))
    s = 1e3
    big = cj.SurfaceMesh.from_arrays(V * s, F.astype(int), N, dtype="float32")
    res = cj.solve(big, P * s, L * s, solutions="all")
    unit = cj.solve(mesh, P, L, solutions="all")
    np.testing.assert_array_equal(np.asarray(res.count), np.asarray(unit.count))


def test_a_float32_tol_at_its_epsilon_is_accepted():
    arguments.check_tol_resolves("tol", float(np.finfo(np.float32).eps), np.float32)
    arguments.check_tol_resolves("tol", 1e-12, np.float64)


@pytest.mark.parametrize("scale, match", [(1e9, "beyond what float32 resolves"), (1e-9, "below what float32 resolves")])
def test_a_scene_outside_the_dtype_scale_band_is_refused(pool, no_jit_work, scale, match):
    """`arguments.scale_range`: float32 scenes scaled by 1e10 had read TOTAL_INTERNAL_REFLECTION
    and by 1e-9 DEGENERATE; the band's ends are refused, naming the limit."""
    mesh, P, L = pool
    V, F, N = (np.asarray(x, np.float64) for x in (mesh.vertices, mesh.faces, mesh.normals))
    big = cj.SurfaceMesh.from_arrays(V * scale, F.astype(int), N, dtype="float32")
    with pytest.raises(ValueError, match=match):
        cj.solve(big, P * scale, L * scale)
    with pytest.raises(ValueError, match=match):
        cj.irradiance(big, P * scale, L * scale, intensity=1.0, receiver_normal=[0, 0, 1])


def test_scale_range_is_the_quartic_band_of_each_dtype():
    lo32, hi32 = arguments.scale_range(np.float32)
    lo64, hi64 = arguments.scale_range(np.float64)
    assert 2.5e-8 < lo32 < 2.7e-8 and 5.3e8 < hi32 < 5.4e8
    assert lo64 < 1e-60 and hi64 > 1e76
    # the quartic of the largest coordinate stays 8^4 below the dtype's largest number
    assert float(np.float32(hi32)) ** 4 * 8**4 <= float(np.finfo(np.float32).max) * 1.0001


@pytest.mark.parametrize("scale", [1e-7, 1e8])
def test_a_float32_scene_inside_the_scale_band_solves_as_at_unit_scale(pool, scale):
    """Measured band (docs/input_contract.md "Scale"): the walk finds the same lanes and
    points (relative to the scene size) at scales 1e-7 and 1e8 as at 1."""
    mesh, P, L = pool
    V, F, N = (np.asarray(x, np.float64) for x in (mesh.vertices, mesh.faces, mesh.normals))
    scaled = cj.SurfaceMesh.from_arrays(V * scale, F.astype(int), N, dtype="float32")
    ref, got = cj.solve(mesh, P, L), cj.solve(scaled, P * scale, L * scale)
    np.testing.assert_array_equal(np.asarray(got.status), np.asarray(ref.status))
    found = np.asarray(ref.found)
    np.testing.assert_allclose(np.asarray(got.point)[found] / scale, np.asarray(ref.point)[found], atol=2e-5)


def test_a_start_off_its_face_is_refused(pool, no_jit_work):
    """A barycentric outside the closed face is not on the face's conic: `(5, 5)` had given
    FOUND on 3 of 16 lanes and wrong TIR / LEFT_MESH statuses on the rest."""
    mesh, P, L = pool
    sp = cj.start_points(mesh, P, L)
    ab = np.asarray(sp.barycentric).copy()
    ab[3] = (0.7, 0.5)
    with pytest.raises(ValueError, match=r"closed face .* at lanes \[3\]"):
        cj.solve(mesh, P, L, start=(np.asarray(sp.face), ab, np.asarray(sp.found)))


@pytest.mark.parametrize("length", [1e-20, 1e-3, 1e20, 1e39])
def test_a_receiver_normal_of_any_finite_length_gives_the_unit_normal_result(pool, length):
    mesh, P, L = pool
    want = np.asarray(cj.irradiance(mesh, P, L, intensity=1.0, receiver_normal=[0.0, 0.6, 0.8]))
    got = np.asarray(cj.irradiance(mesh, P, L, intensity=1.0, receiver_normal=[0.0, 0.6 * length, 0.8 * length]))
    assert np.all(want > 0)
    np.testing.assert_allclose(got, want, rtol=1e-6)


def test_light_endpoint_checks_its_light_index_and_points():
    sc = scenes.wavy_pool(8, n_receivers=2)
    P = np.asarray(sc.receivers)
    with pytest.raises(ValueError, match="k must be an integer"):
        sc.lights.endpoint(P, 5)
    with pytest.raises(ValueError, match="k must be an integer"):
        sc.lights.endpoint(P, -1)
    with pytest.raises(ValueError, match=r"P must have shape \(\.\.\., 3\)"):
        sc.lights.endpoint(P[:, :2])
    np.testing.assert_array_equal(np.asarray(sc.lights.endpoint(P.tolist())), np.asarray(sc.lights.endpoint(P)))


def test_photon_irradiance_takes_a_prepared_surface_as_solve_does(pool):
    mesh, _, _ = pool
    args = dict(intensity=1.0, receiver=cj.ReceiverGrid(-1.0, -2, 2, -2, 2, 4, 4), n_photons=256, seed=3)
    L = np.array([0.4, -0.3, 3.0])
    got = cj.photon_irradiance(cj.prepare(mesh), L, **args)
    want = cj.photon_irradiance(mesh, L, **args)
    assert got.n_photons == 256 and np.array_equal(got.irradiance, want.irradiance)


@pytest.mark.parametrize("kwargs, match", [
    (dict(n_photons=-5), "n_photons"), (dict(n_photons=1.5), "n_photons"), (dict(n_photons="10"), "n_photons"),
    (dict(n_photons=True), "n_photons"), (dict(n_photons=2**40), "n_photons"), (dict(chunk=0), "chunk"),
    (dict(chunk=1.5), "chunk"), (dict(seed=-1), "seed"), (dict(seed="x"), "seed"), (dict(intensity=-1.0), "intensity"),
    (dict(intensity=1j), "intensity"), (dict(eta=-1.0), "eta"), (dict(eta=np.ones(3)), "eta"),
    (dict(sigma_t=float("nan")), "sigma_t"), (dict(receiver=(-1.0, -2, 2)), "receiver"),
    (dict(receiver="grid"), "receiver"), (dict(receiver=(-1.0, 2, -2, -2, 2, 8, 8)), "receiver"),
    (dict(receiver=(-1.0, -2, 2, -2, 2, 8.5, 8)), "receiver.nx"),
    (dict(receiver=(1.0, -2, 2, -2, 2, 8, 8)), "receiver"),
    (dict(receiver=None), "receiver"), (dict(L=np.array([0, 0, -5.0])), "L"), (dict(L=np.zeros(2)), "L"),
    (dict(L=np.array([0, np.nan, 3])), "L"), (dict(L="x"), "L"), (dict(L=np.ones(3, bool)), "L"),
    (dict(progress=1), "progress"), (dict(eta=1e39), "eta overflows float32"),
    (dict(eta=1e-40), "eta must be at least"),
    (dict(intensity=1e39), "intensity overflows float32"), (dict(sigma_t=1e39), "sigma_t overflows float32"),
])
def test_a_bad_photon_irradiance_argument_is_a_value_error_naming_it(pool, kwargs, match):
    mesh, _, _ = pool
    args = dict(L=np.array([0.4, -0.3, 3.0]), intensity=1.0, receiver=cj.ReceiverGrid(-1.0, -2, 2, -2, 2, 8, 8),
                n_photons=4096, chunk=4096) | kwargs
    L = args.pop("L")
    with pytest.raises(ValueError, match=match):
        cj.photon_irradiance(mesh, L, **args)


@pytest.mark.parametrize("fn", [
    lambda m: cj.solve(m, np.zeros((1, 3)), np.ones((1, 3))), lambda m: cj.start_points(m, np.zeros(3), np.ones(3)),
    lambda m: cj.features(m), lambda m: cj.prepare(m),
    lambda m: cj.irradiance(m, np.zeros(3), np.ones(3), intensity=1.0, receiver_normal=[0, 0, 1]),
    lambda m: cj.photon_irradiance(m, np.ones(3), intensity=1.0, receiver=(-1, -1, 1, -1, 1, 2, 2), n_photons=8),
])
@pytest.mark.parametrize("mesh", ["mesh", None, np.zeros((3, 3))])
def test_a_mesh_that_is_not_a_surface_mesh_is_a_value_error(fn, mesh):
    with pytest.raises(ValueError, match="mesh"):
        fn(mesh)


@pytest.mark.parametrize("lights", ["x", [np.nan, 0, 1], [0, 0, 1j], [True, True, True], [0, 1]])
def test_features_refuses_bad_lights(pool, lights):
    with pytest.raises(ValueError, match="lights"):
        cj.features(pool[0], lights)


_GENERATORS = ["flat_pool", "wavy_pool", "lagoon"]
BAD_SCENE_ARGS = [(g, k, v) for g in _GENERATORS for k, vs in {
    "n_triangles": (-1, 0, 1, 100.5, "100", True, 2**40),
    "seed": (-1, 1.5, "x", 2**70, True),
    "dtype": ("float16", "int32", "x", "complex64"),
    "n_receivers": (-1, 0, 2.5, "x", 2**20),
    "light": ("x", None, 1),
    "light_position": ((0, np.nan, 3), (0, 0, 0), (0, 3), "x", (0, 0, -5)),
    "depth": (-1.0, 0.0, float("nan"), "x"),
}.items() for v in vs] + [(g, k, v) for g in ("wavy_pool", "lagoon") for k, vs in {
    "amplitude": (-0.1, float("nan"), float("inf"), "x", 10.0),
    "n_waves": (0, -1, 2.5, "x"),
    "wavelength": ((0.0, 1.0), (2.0, 1.0), (-1.0, 1.0), 1.0, (np.nan, 1.0), "x"),
    "time": (float("nan"),),
}.items() for v in vs] + [(g, k, v) for g in ("flat_pool", "wavy_pool") for k, vs in {
    "half_size": (-1.0, 0.0, float("nan"), "x"), "receiver_jitter": (-1.0, float("nan"), "x", 2.0),
}.items() for v in vs] + [("wavy_pool", "choppiness", v) for v in (1.0, -0.1, float("nan"), "x")] + [
    ("lagoon", "size", v) for v in ((-6.0, 4.0), (0.0, 4.0), (np.nan, 4.0), 6.0, "x")] + [
    ("lagoon", "floor_relief", v) for v in (-0.1, float("nan"), "x", 1.0)]


@pytest.mark.parametrize("gen, name, value", BAD_SCENE_ARGS, ids=lambda x: repr(x)[:20])
def test_a_bad_scene_argument_is_a_value_error_naming_it(gen, name, value):
    fn = getattr(scenes, gen)
    args = {"n_triangles": 64} | {name: value}
    with pytest.raises(ValueError, match=name):
        fn(**args)


@pytest.mark.parametrize("kwargs", [dict(n=-1), dict(n=1.5), dict(n="x"), dict(n=True), dict(n=2**40),
                                    dict(n_triangles=0), dict(n_triangles="x"), dict(eta=-1.0), dict(eta=float("nan")),
                                    dict(eta="x"), dict(repeats=0), dict(seed=-1), dict(seed=1.5), dict(ref_n=-1),
                                    dict(sweep_n=0), dict(dtypes="float32"), dict(dtypes=()), dict(configs="walk"),
                                    dict(configs=()), dict(sweep="no"), dict(scene=None)],
                         ids=lambda d: repr(d)[:24])
def test_a_bad_compare_config_is_a_value_error_naming_the_field(kwargs):
    (name,) = kwargs
    with pytest.raises(ValueError, match=name):
        compare.CompareConfig(**kwargs).validate()


# --------------------------------------------------------------------------- zero lanes


@pytest.mark.parametrize("method, extra", [("walk", {}), ("newton", {}), ("newton", {"n_starts": 4})])
@pytest.mark.parametrize("feats", ["auto", None])
def test_zero_lanes_give_an_empty_solution_on_every_path(pool, method, extra, feats):
    mesh, _, L = pool
    for L0 in (np.zeros((0, 3)), L[0]):
        sol = cj.solve(mesh, np.zeros((0, 3)), L0, method=method, features=feats, **extra)
        assert sol.point.shape == (0, 3) and sol.status.shape == (0,) and sol.found.shape == (0,)


@pytest.mark.parametrize("return_all", [False, True])
def test_zero_lanes_exhaustive_and_all_paths_irradiance(return_all):
    with cj.precision("float64"):
        mesh = scenes.wavy_pool(128, dtype="float64").surface
        sol = cj.solve(mesh, np.zeros((0, 3)), np.zeros((0, 3)), method="exhaustive", return_all=return_all)
        assert (sol.solution if return_all else sol).status.shape == (0,)
        E = cj.irradiance(mesh, np.zeros((0, 3)), np.zeros((0, 3)), method="exhaustive", all_paths=True,
                          intensity=1.0, receiver_normal=[0, 0, 1])
        assert np.shape(E) == (0,)


@pytest.mark.parametrize("feats", ["auto", None])
def test_zero_lanes_irradiance_start_points_and_photons(pool, feats):
    mesh, _, L = pool
    E, sol = cj.irradiance(mesh, np.zeros((0, 3)), L[0], intensity=1.0, receiver_normal=[0, 0, 1], features=feats,
                           return_solution=True)
    assert np.shape(E) == (0,) and sol.status.shape == (0,)
    for method in ("auto", "general"):
        sp = cj.start_points(mesh, np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), method=method)
        assert np.shape(sp.face) == (0,) and np.shape(sp.barycentric) == (0, 2)
    # No photons, or an empty receiver grid, estimates nothing: refused, not a map of zeros.
    grid = cj.ReceiverGrid(-1.0, -2, 2, -2, 2, 8, 8)
    with pytest.raises(ValueError, match=r"n_photons must be an integer in \[1,"):
        cj.photon_irradiance(mesh, L[0], intensity=1.0, receiver=grid, n_photons=0)
    for empty in (grid._replace(nx=0), grid._replace(ny=0)):
        with pytest.raises(ValueError, match=r"receiver\.n[xy] must be an integer in \[1,"):
            cj.photon_irradiance(mesh, L[0], intensity=1.0, receiver=empty, n_photons=16)


@pytest.mark.parametrize("call, match", [
    (lambda: K.ccm0_size(1j, 4.0, 0.01), "r_width"), (lambda: K.ccm0_size(4.0, 4.0, -1), "p must be"),
    (lambda: K.cascade_deltas(8, 8, 2.5), "s must be an integer"), (lambda: K.cascade_deltas("8", 8, 2), "ccm0_x"),
    (lambda: K.cascade_thread_counts(8, 8, 2, 2**40), "n_levels"),
    (lambda: K.cascade_dispatch(np.arange(4), 8, 8, None, 2), "s must be an integer"),
    (lambda: K.bilateral_denoise(*_IMG, 10.0, passes=2**40), "passes"),
    (lambda: K.denoise_subpass(*_IMG, 10.0, axis=True), "axis"),
    (lambda: K.fixed_point_accumulate(np.ones(3), num_segments=0), "num_segments"),
    (lambda: K.sprite_size("4", 4.0, 256, 256, 1.0, np.ones(2)), "r_width"),
    (lambda: K.sprite_size(4.0, 4.0, 1, 256, 1.0, np.ones(2)), "ccm0_x"),
    (lambda: K.schlick_f0(-1.0), "eta"), (lambda: K.schlick_f0(None), "eta"), (lambda: cj.refract(None, _Z, 1.3), "I"),
    (lambda: cj.precision(None).__enter__(), "precision"), (lambda: cj.precision("x").__enter__(), "precision"),
    (lambda: cj.enable_x64("no"), "enabled"), (lambda: cj.enable_x64(0), "enabled"),
    # solver objects: a ValueError naming the known options (Python's TypeError before)
    (lambda: cj.Walk(foo=1), r"unknown walk option\(s\) \['foo'\]; known: \['tol'"),
    (lambda: cj.Newton(solvr="newton"), r"unknown newton option\(s\) \['solvr'\]"),
    (lambda: cj.Exhaustive(1, 8, 1e-9, 8, 0.0, True, False, 9), "Exhaustive takes at most 7 options"),
    (lambda: cj.cross_edge("mesh", 0, 0, 0.5), "mesh"), (lambda: cj.cross_edge(_MESH, 2**40, 0, 0.5), "face"),
    (lambda: compare.CompareConfig(dtypes=None).validate(), "dtypes"),
    (lambda: cj.start_points(_MESH, 2**40, np.ones(3)), "shape"),
])
def test_static_configuration_and_missing_arrays_are_value_errors(call, match):
    """Static (Python) configuration is checked like options; `None` is refused unless it
    is the documented default (a huge `passes` would loop for ever instead)."""
    with pytest.raises(ValueError, match=match):
        call()


def _mesh_entry_points() -> dict[str, object]:
    """Every public function (of the package, `transport`, `start_points`, `occlusion`,
    `bvh`, `face_cells`) that takes a surface mesh as `mesh` or `surface`, by name."""
    found = {}
    for name in ("caustics_jax", "caustics_jax.transport", "caustics_jax.accel.start_points",
                 "caustics_jax.accel.occlusion", "caustics_jax.accel.bvh", "caustics_jax.accel.face_cells"):
        module = importlib.import_module(name)
        for attr in module.__all__:
            fn = getattr(module, attr)
            if callable(fn) and not isinstance(fn, type):
                params = inspect.signature(fn).parameters
                if {"mesh", "surface"} & set(params):
                    found[attr] = fn
    return found


def test_a_float64_mesh_used_with_x64_off_names_the_cause():
    """A float64 mesh built inside `precision("float64")` and used outside it: every entry
    point that takes a mesh says x64 is off (it had said "P is float32 but the mesh is
    float64" for float64 points, which JAX had silently made float32; README's second
    example did this; `cross_edge`, `features`, the start-point structures and
    `mesh.translated` had run on, casting some arrays and not others). The list of entry
    points is read from the modules, so a new one without a case here fails."""
    with cj.precision("float64"):
        scene = scenes.wavy_pool(128, dtype="float64")
        mesh = scene.surface
        P = np.asarray(scene.receivers[:4])
        L = np.asarray(scene.lights.endpoint(P))
        cells, bvh = start_points_module.build_accel(mesh), start_points_module.build_bvh(mesh)
    grid = cj.ReceiverGrid(-1.0, -2, 2, -2, 2, 4, 4)
    opts = dict(intensity=1.0, receiver_normal=[0, 0, 1], seed=0)
    cases = {
        "solve": lambda: cj.solve(mesh, P, L), "prepare": lambda: cj.prepare(mesh),
        "start_points": lambda: cj.start_points(mesh, P, L), "features": lambda: cj.features(mesh),
        "cross_edge": lambda: cj.cross_edge(mesh, 0, 0, 0.5),
        "irradiance": lambda: cj.irradiance(mesh, P, L, intensity=1.0, receiver_normal=[0, 0, 1]),
        "photon_irradiance": lambda: cj.photon_irradiance(mesh, L[0], intensity=1.0, receiver=grid, n_photons=16),
        "sms_biased": lambda: cj.sms_biased(mesh, P, L, k=2, **opts),
        "sms_unbiased": lambda: cj.sms_unbiased(mesh, P, L, **opts),
        "segment_blocked": lambda: occlusion.segment_blocked(mesh, P, L),
        "path_visible": lambda: path_visible(mesh, P, (P + L) / 2, L),
        "surface_hits": lambda: T.surface_hits(mesh, L[0], P),
        "trace_photons": lambda: T.trace_photons(mesh, L[0], P, intensity=1.0, area=1.0, receiver_z=-1.0),
        "surface_starts": lambda: T.surface_starts(mesh, 4, np.random.default_rng(0)),
        "build_accel": lambda: start_points_module.build_accel(mesh),
        "build_bvh": lambda: start_points_module.build_bvh(mesh), "bin_faces": lambda: bin_faces(mesh),
        "check_segments": lambda: start_points_module.check_segments(mesh, P, L),
        "first_crossing": lambda: start_points_module.first_crossing(mesh, P, L),
        "first_hit": lambda: start_points_module.first_hit(mesh, cells, P, L, widen=True),
        "grid_cells": lambda: start_points_module.grid_cells(mesh),
        "first_hit_bvh": lambda: first_hit_bvh(mesh, bvh, P, L, None, widen=True),
        "first_hit_cells": lambda: first_hit_cells(mesh, cells, P, L, None, widen=True),
        "translated": lambda: mesh.translated([1.0, 0.0, 0.0]),
    }
    assert set(_mesh_entry_points()) <= set(cases), set(_mesh_entry_points()) - set(cases)
    with cj.precision("float32"):
        for call in cases.values():
            with pytest.raises(ValueError, match="jax_enable_x64 is off"):
                call()


def _edited(mesh, field: str, value):
    return eqx.tree_at(lambda m: getattr(m, field), mesh, value)


@pytest.mark.parametrize("edit, match", [
    (lambda m: _edited(m, "vertices", m.vertices.at[40, 2].set(jnp.nan)),
     r"mesh.vertices contain NaN or Inf: rows \[40\]"),
    (lambda m: _edited(m, "normals", m.normals.at[3, 0].set(jnp.inf)), r"mesh.normals contain NaN or Inf: rows \[3\]"),
    (lambda m: _edited(m, "faces", m.faces.at[0, 0].set(10**6)), r"mesh.faces out of range \[0, 80\]: rows \[0\]"),
    (lambda m: _edited(m, "neighbors", m.neighbors.at[5, 1].set(-2)), r"mesh.neighbors out of range"),
    (lambda m: _edited(m, "faces", m.faces.astype(jnp.float32)), "mesh.faces must hold integer indices"),
    (lambda m: _edited(m, "vertices", m.vertices[:10]), r"mesh.normals must have shape \(10, 3\)"),
    (lambda m: _edited(m, "normals", m.normals.astype(jnp.float64)), "must share one float dtype"),
    (lambda m: _edited(m, "vertices", [[0.0, 0.0, 0.0]] * 81), "mesh.vertices must be a concrete array"),
])
def test_a_mesh_edited_after_construction_is_checked_once_before_use(edit, match):
    """`eqx.tree_at` (the way to animate a surface) bypasses the constructors' checks. A NaN
    height had been reported as "P has NaN or Inf", an out-of-range face index as an
    IndexError inside `features`. `prepare` (every solver entry) checks the arrays once per
    mesh object, `features` on every call."""
    mesh = edit(scenes.wavy_pool(128, dtype="float32").surface)
    P, L = np.array([[0.1, 0.2, -1.0]]), np.array([[0.4, -0.3, 3.0]])
    for call in (lambda: cj.solve(mesh, P, L), lambda: cj.features(mesh), lambda: cj.prepare(mesh),
                 lambda: cj.photon_irradiance(mesh, L[0], intensity=1.0, n_photons=16, chunk=16,
                                              receiver=cj.ReceiverGrid(-1.0, -1, 1, -1, 1, 4, 4))):
        with pytest.raises(ValueError, match=match):
            call()


def test_a_mesh_of_numpy_arrays_changed_in_place_is_analysed_again():
    """A numpy vertex array changed in place after a solve had left `prepare`'s cached
    analysis (bounds, start-point structure) stale: the moved pool found no start point
    where a fresh mesh with the same vertices found the path. Numpy-array meshes are now
    analysed on every call, and give what a JAX-array mesh gives."""
    m = scenes.wavy_pool(128, dtype="float32").surface
    V = np.array(m.vertices)
    mesh = eqx.tree_at(lambda q: q.vertices, m, V)
    P, L = np.array([[3.0, 3.0, -1.0]]), np.array([3.3, 2.7, 3.0])
    assert not np.asarray(cj.solve(mesh, P, L).found).any()  # the pool spans [-2, 2]: no crossing
    V[:, :2] += 3.0  # the same mesh object, moved in place (its grid too: prepare warns, bins the faces)
    with pytest.warns(UserWarning, match="off its regular grid"):
        moved = cj.solve(mesh, P, L)
    with pytest.warns(UserWarning, match="off its regular grid"):
        fresh = cj.solve(eqx.tree_at(lambda q: q.vertices, m, jnp.asarray(V)), P, L)
    assert np.asarray(fresh.found).all()
    np.testing.assert_array_equal(np.asarray(moved.status), np.asarray(fresh.status))
    np.testing.assert_array_equal(np.asarray(moved.point), np.asarray(fresh.point))


def test_warnings_about_the_input_point_at_the_callers_line():
    """Each warning about the user's input is attributed to the user's line
    (`arguments.warn_user`). With a fixed `stacklevel`, the stale-grid warning, raised in
    `prepare`'s analysis, pointed inside the package when `solve` or `start_points` ran it."""
    import warnings

    def user_warnings(fn):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fn()
        return [w for w in caught if issubclass(w.category, UserWarning)]

    sc = scenes.wavy_pool(128, dtype="float32")
    m = sc.surface
    V = np.array(m.vertices)
    V[:, :2] += 3.0  # xy moved without the grid: a stale grid
    P, L = np.array([[3.0, 3.0, -1.0]]), np.array([3.3, 2.7, 3.0])
    stale = lambda: eqx.tree_at(lambda q: q.vertices, m, jnp.asarray(V))  # noqa: E731  (a new mesh object each time)
    receivers = np.asarray(sc.receivers)[:64]
    lights = np.asarray(sc.lights.endpoint(receivers))
    flat = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    cases = {
        "solve, stale grid": lambda: cj.solve(stale(), P, L),
        "prepare, stale grid": lambda: cj.prepare(stale()),
        "start_points, stale grid": lambda: cj.start_points(stale(), P.astype(np.float32), L.astype(np.float32)),
        "from_arrays, wound clockwise": lambda: cj.SurfaceMesh.from_arrays(flat, np.array([[0, 2, 1], [1, 2, 3]])),
        "solve, P and L swapped": lambda: cj.solve(m, lights, receivers),
    }
    for name, call in cases.items():
        caught = user_warnings(call)
        assert caught, name
        assert [w.filename for w in caught] == [__file__] * len(caught), name
