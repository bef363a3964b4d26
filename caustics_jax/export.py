"""Reference data for shader tests (DESIGN.md "Reference data for shader tests"; docs/export.md).

`export(out_dir)` writes, per kernel, `<kernel>.json` (the manifest) and `<kernel>.bin`
(little-endian std430 records), plus `caustics_records.h`, a C header with one struct
per record. Every record holds the kernel's inputs, rounded to float32, its outputs, the
float64 reference computed *from those rounded inputs* by the package's own kernel and
then rounded to float32, and a case tag (`random`, `planted`, `adversarial`).

Layout (std430, as GLSL lays out a `buffer` of structs): scalars 4 bytes, `vec2` 8,
`vec3` 16 (its fourth float is explicit padding, so nothing ever packs into it), `vec4`
16; arrays of scalars have stride 4, of `vec2` 8, of `vec3`/`vec4` 16; the record stride
is the struct size rounded up to its largest alignment. A reader needs nothing but the
manifest: each field gives `offset`, `dtype`, the logical `shape` and the padded
`storage_shape` (`read_records` is such a reader, in numpy).

Tolerances (per output field, `|gpu - ref| <= abs + rel * scale`, `scale` the largest
magnitude of the field in that record, or of the field named by `scale_field`) come from
measurements: the same kernel run in float32 (XLA on the CPU) on the same float32
inputs, its worst error over this export, and for the kernels that `experiments/
float32_audit.py` measured over 200k paths the audit's maximum where larger; times
`SAFETY`, plus the storage rounding of the reference (half a float32 ulp) and its own
float64 error budget (`F64_BUDGET`). Integer outputs (flags, counts, codes) must match
exactly.
"""

from __future__ import annotations

import dataclasses
import json
import zlib
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import testing
from ._precision import precision
from .barycentric import barycentric_point
from .conic import conic_coefficients, conic_tangent, edge_intersections, edge_quadratics
from .geometry import fresnel_reflectance, refract, safe_normalize
from .kernels.bilateral import bilateral_weight
from .kernels.collection import reuse_weight
from .kernels.fixed_point import fixed_point_accumulate
from .objectives import path_vectors, signed_sine_and_status
from .transport.differentials import ray_differential_D

#: Format version of the manifest and binary layout; bump on any incompatible change.
FORMAT_VERSION = 1
#: Factor between the worst measured float32 error and the tolerance. A GLSL port orders
#: its operations differently, may contract `a * b + c` to an FMA, and GLSL allows 2-3 ulp
#: for division, `sqrt` and `exp` where XLA rounds correctly.
SAFETY = 4.0
#: Relative error budget of the float64 reference itself (64 float64 ulps; the audit
#: measures at most ~10 ulps on the planted residuals) and of storing it as float32.
F64_BUDGET = 64 * float(np.finfo(np.float64).eps)
STORAGE_ROUNDING = 0.5 * float(np.finfo(np.float32).eps)
#: Case tags, stored per record in the `case_tag` field (`case` is a keyword in C and GLSL).
CASES = {"random": 0, "planted": 1, "adversarial": 2}
AUDIT_FILE = Path(__file__).resolve().parent.parent / "figures" / "float32_audit.json"

# std430: (base alignment, size) of one element, numpy dtype, C element type, storage
# width (vec3 stored as 4 floats, the fourth padding).
_TYPES = {
    "float": (4, 4, "<f4", "float", 1),
    "int": (4, 4, "<i4", "int32_t", 1),
    "uint": (4, 4, "<u4", "uint32_t", 1),
    "vec2": (8, 8, "<f4", "float", 2),
    "vec3": (16, 16, "<f4", "float", 4),
    "vec4": (16, 16, "<f4", "float", 4),
}
_WIDTH = {"float": 1, "int": 1, "uint": 1, "vec2": 2, "vec3": 3, "vec4": 4}


@dataclasses.dataclass(frozen=True)
class Field:
    """One member of a record: GLSL type, optional array length, role (input/output/case)."""

    name: str
    glsl: str
    role: str
    length: int | None = None
    scale_field: str | None = None  # tolerance scale: this field's magnitude instead of own

    @property
    def shape(self) -> list[int]:
        w = _WIDTH[self.glsl]
        return ([self.length] if self.length else []) + ([w] if w > 1 else [])

    @property
    def storage_shape(self) -> list[int]:
        w = _TYPES[self.glsl][4]
        return ([self.length] if self.length else []) + ([w] if w > 1 else [])

    @property
    def dtype(self) -> str:
        return {"<f4": "float32", "<i4": "int32", "<u4": "uint32"}[_TYPES[self.glsl][2]]

    @property
    def size(self) -> int:
        return _TYPES[self.glsl][1] * (self.length or 1)


def layout(fields: list[Field]) -> tuple[list[int], int]:
    """std430 offsets of `fields` (vec3 padded to 16 bytes) and the record stride."""
    offset, align_max, offsets = 0, 4, []
    for f in fields:
        align = _TYPES[f.glsl][0]
        offset = -(-offset // align) * align
        offsets.append(offset)
        offset += f.size
        align_max = max(align_max, align)
    return offsets, -(-offset // align_max) * align_max


@dataclasses.dataclass(frozen=True)
class Kernel:
    """A kernel's record layout, equations, case generator and float64/float32 evaluation.

    `generate(rng, n)` returns float64 inputs (dict of arrays, leading axis = records) and
    case codes for `n` random/planted candidates plus the fixed adversarial set;
    `evaluate(inputs)` runs the package kernel in the inputs' dtype; `keep(inputs, ref)`
    marks random candidates whose discrete outcome and conditioning are unambiguous in
    float32 (a shader test must not depend on a coin flip of rounding).
    """

    name: str
    equations: str
    fields: list[Field]
    generate: Callable
    evaluate: Callable
    keep: Callable | None = None
    audit: dict = dataclasses.field(default_factory=dict)  # output field -> (audit key, "abs"/"rel")
    reference: str = ""  # the package function that computes the reference outputs
    filter_planted: bool = False  # apply `keep` to planted candidates too

    def inputs(self):
        return [f for f in self.fields if f.role == "input"]

    def outputs(self):
        return [f for f in self.fields if f.role == "output"]


# --------------------------------------------------------------------------- generators

def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _f64(fn, *args):
    """`fn` (a package kernel) on float64 numpy arguments, as numpy: to build and select cases."""
    with precision("float64"):
        out = jax.jit(fn)(*(jnp.asarray(a, jnp.float64) for a in args))
        return jax.tree_util.tree_map(np.asarray, out)


def _split(n: int) -> tuple[int, int]:
    """Planted and random record counts for `count = n` (a quarter planted)."""
    planted = n // 4
    return planted, n - planted


def _stack_cases(parts):
    """Concatenate `(inputs, case_code)` parts into one inputs dict and a case array."""
    keys = parts[0][0].keys()
    inputs = {k: np.concatenate([np.asarray(p[0][k], np.float64) for p in parts]) for k in keys}
    case = np.concatenate([np.full(len(p[0][next(iter(keys))]), p[1], np.uint32) for p in parts])
    return inputs, case


def _random_paths(rng, n, normal_spread=0.3):
    """Random triangles (testing.random_triangles), a random interior `ab`, P below, L above."""
    V, N = testing.random_triangles(rng, n, normal_spread=normal_spread)
    ab = rng.dirichlet([2.0, 2.0, 2.0], n)[:, 1:]
    M = _f64(barycentric_point, V, ab)
    P = M + rng.uniform(-1, 1, (n, 3)) * [1, 1, 0] - rng.uniform(0.2, 2.0, (n, 1)) * [0, 0, 1]
    L = M + rng.uniform(-2, 2, (n, 3)) * [1, 1, 0] + rng.uniform(0.5, 5.0, (n, 1)) * [0, 0, 1]
    return V, N, P, L, ab


def _planted(rng, n, **kw):
    return testing.planted_paths(int(rng.integers(2**31)), n, **kw)


def _gen_refract(rng, n):
    n_pl, n_rand = _split(n)
    N = _unit(rng.normal(size=(4 * n_rand, 3)))
    I = _unit(rng.normal(size=(4 * n_rand, 3)))
    I = np.where(np.sum(I * N, -1, keepdims=True) > 0, -I, I)  # GLSL: dot(N, I) <= 0
    eta = rng.uniform(0.6, 1.5, 4 * n_rand)
    pl = _planted(rng, n_pl)
    _, n_s, w_P, _, _ = _f64(path_vectors, pl.V, pl.N, pl.P, pl.L, pl.ab)
    z, x = np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
    g = _unit(np.array([0.6, 0, -0.8]))
    adv = {  # normal incidence, grazing, eta = 1, deep total internal reflection, exact zeros
        "I": np.stack([-z, -z, x, x, g, g, -z, _unit(np.array([0.9, 0, -0.1]))]),
        "N": np.stack([z, z, z, z, z, z, z, z]),
        "eta": np.array([1.333, 1 / 1.333, 1 / 1.333, 1.333, 1.0, 1.333, 1.0, 1.333]),
    }
    return _stack_cases([
        ({"I": I, "N": N, "eta": eta}, CASES["random"]),
        ({"I": -w_P, "N": -n_s, "eta": np.full(n_pl, pl.eta)}, CASES["planted"]),
        (adv, CASES["adversarial"]),
    ])


def _keep_refract(x, ref):
    cos = np.sum(x["N"] * x["I"], -1)
    k = 1 - x["eta"] ** 2 * (1 - cos**2)
    return np.abs(k) > 1e-2  # sqrt(k) is ill-conditioned at the critical angle


def _eval_refract(x):
    return {"T": refract(x["I"], x["N"], x["eta"])}


def _gen_fresnel(rng, n):
    n_pl, n_rand = _split(n)
    m = 4 * n_rand
    rand = {"cos_i": rng.uniform(0, 1, m), "eta": rng.choice([1 / 1.333, 1.333, 1 / 1.5, 1.5], m)
            * rng.uniform(0.9, 1.1, m)}
    # planted: water -> air at normal incidence, R = ((eta - 1)/(eta + 1))^2 in closed form
    planted = {"cos_i": np.ones(n_pl), "eta": rng.uniform(0.5, 2.0, n_pl)}
    adv = {"cos_i": np.array([0.0, 0.0, 1.0, 1.0, 0.5, 0.2, 1.0, 0.0]),
           "eta": np.array([1 / 1.333, 1.333, 1.0, 1.333, 1.0, 1.333, 2.0, 1.0])}
    return _stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


def _keep_fresnel(x, ref):
    cos_t2 = 1 - x["eta"] ** 2 * (1 - x["cos_i"] ** 2)
    return (np.abs(cos_t2) > 1e-2) & (x["cos_i"] > 1e-2)


def _eval_fresnel(x):
    return {"R": fresnel_reflectance(x["cos_i"], x["eta"])}


def _gen_conic(rng, n):
    n_pl, n_rand = _split(n)
    V, N, P, L, _ = _random_paths(rng, n_rand)
    pl = _planted(rng, n_pl)
    z = np.array([0, 0, 1.0])
    Vf = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    adv = {  # constant normals (the conic is a line, A = B = C = 0), a tilted large-scale copy
        "V": np.stack([Vf, Vf, 100 * Vf + 50, 1e-3 * Vf]),
        "N": np.stack([np.stack([z] * 3)] * 2 + [np.stack([_unit(np.array([0.1, 0, 1.0])), z, z])] * 2),
        "P": np.array([[0.2, 0.3, -1.0], [0.5, 0.5, -0.5], [80, 90, -10.0], [2e-4, 3e-4, -1e-3]]),
        "L": np.array([[0.3, 0.1, 2.0], [0.5, 0.5, 3.0], [60, 60, 120.0], [4e-4, 1e-4, 2e-3]]),
    }
    return _stack_cases([({"V": V, "N": N, "P": P, "L": L}, CASES["random"]),
                         ({"V": pl.V, "N": pl.N, "P": pl.P, "L": pl.L}, CASES["planted"]),
                         (adv, CASES["adversarial"])])


def _eval_conic(x):
    return {"coef": conic_coefficients(x["V"], x["N"], x["P"], x["L"])}


def _conic64(V, N, P, L):
    """Float64 conic coefficients of generated geometry (inputs for the tangent and edge kernels)."""
    with precision("float64"):
        return np.asarray(jax.jit(conic_coefficients)(*(jnp.asarray(a, jnp.float64) for a in (V, N, P, L))))


def _gen_tangent(rng, n):
    n_pl, n_rand = _split(n)
    V, N, P, L, ab = _random_paths(rng, n_rand)
    coef = _conic64(V, N, P, L)
    pl = _planted(rng, n_pl)
    coef_pl = _conic64(pl.V, pl.N, pl.P, pl.L)
    adv = {  # a singular point (crossing lines a^2 - b^2 = 0 at the origin: t = 0), a circle
        "coef": np.array([[1.0, -1, 0, 0, 0, 0], [1, 1, 0, -1, -1, 0.25], [1, 1, 0, -1, -1, 0.25],
                          [0, 0, 0, 1, -1, 0]]),
        "ab": np.array([[0.0, 0], [0.5, 0], [1, 0.5], [0.25, 0.25]]),
    }
    return _stack_cases([({"coef": coef, "ab": ab}, CASES["random"]),
                         ({"coef": coef_pl, "ab": pl.ab}, CASES["planted"]), (adv, CASES["adversarial"])])


def _eval_tangent(x):
    return {"t": conic_tangent(x["coef"], x["ab"])}


def _gen_edges(rng, n):
    n_pl, n_rand = _split(n)
    V, N, P, L, _ = _random_paths(rng, 4 * n_rand, normal_spread=0.6)
    coef = _conic64(V, N, P, L)
    # planted: known roots r0 < r1 on edge 0 (b = 0) and s0 < s1 on edge 2 (a = 0): with
    # A = 1, D = -(r0 + r1), F = r0 r1 and B = F / (s0 s1), E = -B (s0 + s1); C is free
    m = 4 * n_pl  # candidates: edge 1's quadratic is whatever follows, kept only if well conditioned
    r0, s0 = rng.uniform(0.05, 0.45, m), rng.uniform(0.05, 0.45, m)
    r1, s1 = r0 + rng.uniform(0.1, 0.5, m), s0 + rng.uniform(0.1, 0.5, m)
    F = r0 * r1
    B = F / (s0 * s1)
    planted = np.stack([np.ones(m), B, rng.uniform(-1, 1, m), -(r0 + r1), -B * (s0 + s1), F], -1)
    adv = np.array([  # exact in float32: tangency, roots at vertices, linear edges, no curve
        [1, 0, 0, -1, 0, 0.25],      # edge b=0: (a - 1/2)^2 (tangent, double root)
        [1, 1, 0, 0, 0, 0],          # F = 0: root at V0 on two edges
        [1, 0, 0, -3, 0, 2],         # edge b=0: roots 1 and 2 (only 1 inside, at V1)
        [0, 0, 0, 1, 1, -0.5],       # A = B = C = 0: the line a + b = 1/2 (linear quadratics)
        [0, 0, 0, 0, 0, 0],          # the whole plane: no isolated root anywhere
        [1, 1, 0, 0, 0, 1],          # a^2 + b^2 + 1 = 0: no real curve
        [1, 1, 0, -1, -1, 0.375],    # circle inside the triangle: no edge crossings
        [0, 0, 0, 0, 1, -0.25],      # b = 1/4: crosses edges 1 and 2 only
        [1, 0, 0, 2**-20 - 0.5, 0, -(2**-21)],  # roots -2^-20 (inside the window, clamped to 0), 1/2
        [1, 0, 0, -(3 + 2**-20), 0, 2 + 2**-19],  # roots 1 + 2^-20 (clamped to 1) and 2
        [1, 0, 0, -1.5, 0, 0.5 - 2**-12],  # roots 0.4995 and 1.00049 (outside the window: dropped)
    ])
    return _stack_cases([({"coef": coef}, CASES["random"]), ({"coef": planted}, CASES["planted"]),
                         ({"coef": adv}, CASES["adversarial"])])


def _keep_edges(x, ref):
    ok = np.ones(len(x["coef"]), bool)
    quads = _f64(edge_quadratics, x["coef"])  # (records, edge, (q2, q1, q0)), seed 001 eq. 22-24
    for q2, q1, q0 in np.moveaxis(quads, (1, 2), (0, 1)):
        scale = np.maximum(np.maximum(np.abs(q2), np.abs(q1)), np.abs(q0))
        disc = q1 * q1 - 4 * q2 * q0
        rel_disc = disc / np.maximum(q1 * q1 + np.abs(4 * q2 * q0), 1e-300)
        ok &= np.abs(q2) > 1e-2 * scale
        ok &= np.abs(rel_disc) > 1e-2
        sq = np.sqrt(np.maximum(disc, 0))
        for root in ((-q1 - sq) / (2 * np.where(q2 == 0, 1, q2)), (-q1 + sq) / (2 * np.where(q2 == 0, 1, q2))):
            ok &= (disc < 0) | ((np.abs(root) > 1e-3) & (np.abs(root - 1) > 1e-3))
    return ok


#: Edge-root window of `edge_intersections` for a float32 consumer: its default for float32
#: inputs (64 eps), used for the float64 reference too, so that roots just outside an edge
#: are kept and clamped exactly as the float32 kernel and the shader do.
EDGE_TOL = 64 * float(np.finfo(np.float32).eps)


def _eval_edges(x):
    t, valid = edge_intersections(x["coef"], tol=EDGE_TOL)
    return {"t": t.reshape(*t.shape[:-2], 6), "valid": valid.reshape(*valid.shape[:-2], 6).astype(jnp.uint32)}


def _path_inputs(V, N, P, L, ab, eta):
    return {"V": V, "N": N, "P": P, "L": L, "ab": ab, "eta": np.broadcast_to(eta, (len(V),)).astype(np.float64)}


def _adversarial_paths():
    """TIR (P far off the normal), M = P exactly (degenerate), P above the surface."""
    z = np.array([0, 0, 1.0])
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    N = np.stack([z] * 3)
    ab = np.array([0.25, 0.25])
    M = np.array([0.25, 0.25, 0])
    P = np.stack([M + [1.5, 0, -0.5], M, M + [0.1, 0.2, 0.5], M + [0, 0, -1.0]])
    L = np.stack([M + [0, 0, 1.0], M + [0, 0, 1.0], M + [0, 0, 2.0], M + [0, 0, 2.0]])
    return _path_inputs(np.stack([V] * 4), np.stack([N] * 4), P, L, np.stack([ab] * 4), 1.333)


def _gen_signed_sine(rng, n):
    n_pl, n_rand = _split(n)
    V, N, P, L, ab = _random_paths(rng, 4 * n_rand)
    pl = _planted(rng, n_pl)
    return _stack_cases([(_path_inputs(V, N, P, L, ab, 1.333), CASES["random"]),
                         (_path_inputs(pl.V, pl.N, pl.P, pl.L, pl.ab, pl.eta), CASES["planted"]),
                         (_adversarial_paths(), CASES["adversarial"])])


def _path_np(x):
    """`n_s, w_P, w_L` (objectives.path_vectors), refract's `k` and `r = refract(-w_P, -n_s, eta)`, float64."""
    _, n_s, w_P, w_L, _ = _f64(path_vectors, x["V"], x["N"], x["P"], x["L"], x["ab"])
    cos = np.sum(n_s * w_P, -1)
    k = (1 - x["eta"]) * (1 + x["eta"]) + (x["eta"] * cos) ** 2  # negative under TIR, as in geometry.refract
    r = _f64(refract, -w_P, -n_s, x["eta"])
    return n_s, w_P, w_L, k, r


def _keep_signed_sine(x, ref):
    n_s, w_P, w_L, k, r = _path_np(x)
    c = np.cross(r, w_L)
    o = np.cross(x["L"] - x["P"], n_s)  # the 'plane' orientation reference of signed_sine_and_status
    sign_margin = np.abs(np.sum(c * o, -1)) / (np.linalg.norm(c, axis=-1) * np.linalg.norm(o, axis=-1) + 1e-300)
    return (np.abs(k) > 1e-2) & (sign_margin > 1e-2)


def _eval_signed_sine(x):
    f, status = signed_sine_and_status(x["V"], x["N"], x["P"], x["L"], x["ab"], x["eta"], orientation="plane")
    return {"f": f, "status": status.astype(jnp.uint32)}


def _gen_D(rng, n):
    n_pl, n_rand = _split(n)
    # random: planted geometry with the refraction point moved off the solution (D is still
    # defined there, it just describes a different ray map)
    r = _planted(rng, 4 * n_rand)
    ab = r.ab + rng.uniform(-0.1, 0.1, r.ab.shape)
    pl = _planted(rng, n_pl)
    return _stack_cases([(_path_inputs(r.V, r.N, r.P, r.L, ab, r.eta), CASES["random"]),
                         (_path_inputs(pl.V, pl.N, pl.P, pl.L, pl.ab, pl.eta), CASES["planted"]),
                         (_adversarial_paths(), CASES["adversarial"])])


def _keep_D(x, ref):
    n_s, w_P, w_L, k, _ = _path_np(x)
    E1, E2 = x["V"][:, 1] - x["V"][:, 0], x["V"][:, 2] - x["V"][:, 0]
    n_g = _unit(np.cross(E1, E2))
    # every validity threshold of ray_differential_D (sqrt(eps) of the dtype) far away
    return ((np.abs(k) > 1e-2) & (np.abs(np.sum(w_P * n_g, -1)) > 5e-2) & (np.sum(w_L * n_s, -1) > 5e-2)
            & (np.sum(w_P * n_s, -1) < -5e-2))


def _eval_D(x):
    D, valid = ray_differential_D(x["V"], x["N"], x["P"], x["L"], x["ab"], x["eta"])
    return {"D": D, "valid": valid.astype(jnp.uint32)}


def _photon_compression_ratio(x00, x10, x01, n00, n10, n01, l_dir, eta, t_hit, s, c):
    """Photon-differential footprint scale `sigma = sqrt(A'/A) s^c` (seed 004 eq. 10-11, Alg. 2).

    Private stand-in, used only where `transport.photon_differentials.compression_ratio`
    is not importable (it was being written alongside this module): the refraction
    variant of Alg. 2 (MATH.md §7) with the same conventions. Each surface point `x_ij`
    refracts the light direction `l_dir` with its normal `n_ij` into the medium
    (`geometry.refract` with ratio `1/eta`, `eta` = n_water / n_air), all three rays
    advance by the same hit distance `t'` (Alg. 2 lines 3-5), `A` and `A'` are the areas
    of the surface and caustic triangles (eq. 10, Alg. 2 line 6). Returns 0 where the
    surface triangle is degenerate (`A = 0`) instead of dividing by zero.
    """
    def hit(x, n):
        return x + t_hit[..., None] * safe_normalize(refract(l_dir, n, 1 / eta))

    def area(p0, p1, p2):
        return 0.5 * jnp.linalg.norm(jnp.cross(p1 - p0, p2 - p0), axis=-1)

    A = area(x00, x10, x01)
    A_prime = area(hit(x00, n00), hit(x10, n10), hit(x01, n01))
    ok = A > 0
    return jnp.where(ok, jnp.sqrt(A_prime / jnp.where(ok, A, 1)), 0) * s**c


try:  # the transport layer's implementation, where present (one implementation of each formula)
    from .transport.photon_differentials import compression_ratio as _transport_compression_ratio
except ImportError:  # pragma: no cover - depends on the checkout
    _transport_compression_ratio = None
#: Which function computes the photon_compression reference (written into its manifest).
PHOTON_REFERENCE = ("caustics_jax.transport.photon_differentials.compression_ratio"
                    if _transport_compression_ratio is not None else "caustics_jax.export._photon_compression_ratio")


def _gen_photon(rng, n):
    n_pl, n_rand = _split(n)
    m = n_rand

    def patch(m, spread):
        x00 = rng.uniform(-1, 1, (m, 3)) * [1, 1, 0.05]
        h = rng.uniform(0.005, 0.05, (m, 1))
        x10 = x00 + h * [1, 0, 0] + rng.normal(0, 0.2, (m, 3)) * h * [0, 0, 1]
        x01 = x00 + h * [0, 1, 0] + rng.normal(0, 0.2, (m, 3)) * h * [0, 0, 1]
        ns = [_unit([0, 0, 1.0] + spread * rng.normal(size=(m, 3)) * [1, 1, 0]) for _ in range(3)]
        return x00, x10, x01, ns

    x00, x10, x01, (n00, n10, n01) = patch(m, 0.05)
    theta = np.radians(rng.uniform(0, 60, m))
    phi = rng.uniform(0, 2 * np.pi, m)
    l_dir = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)], -1)
    rand = {"x00": x00, "x10": x10, "x01": x01, "n00": n00, "n10": n10, "n01": n01, "l_dir": l_dir,
            "eta": np.full(m, 1.333), "t_hit": rng.uniform(0.5, 5, m), "s": rng.uniform(1, 2, m),
            "c": rng.integers(0, 4, m).astype(np.float64)}
    # planted: a flat patch with one normal refracts every ray the same way, so the caustic
    # triangle is a translate of the surface triangle and sigma = s^c exactly
    p00, p10, p01, _ = patch(n_pl, 0)
    p10[:, 2] = p01[:, 2] = p00[:, 2]
    up = np.broadcast_to([0, 0, 1.0], (n_pl, 3))
    th = np.radians(rng.uniform(0, 60, n_pl))
    ldir_pl = np.stack([np.sin(th), np.zeros(n_pl), -np.cos(th)], -1)
    planted = {"x00": p00, "x10": p10, "x01": p01, "n00": up, "n10": up, "n01": up, "l_dir": ldir_pl,
               "eta": np.full(n_pl, 1.333), "t_hit": rng.uniform(0.5, 5, n_pl),
               "s": rng.uniform(1, 2, n_pl), "c": rng.integers(0, 4, n_pl).astype(np.float64)}
    z = np.array([0, 0, 1.0])
    adv = {  # collinear surface points (A = 0), light straight down, grazing light, c = 0
        "x00": np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0.0]]),
        "x10": np.array([[1, 0, 0], [0.01, 0, 0], [0.01, 0, 0.0]]),
        "x01": np.array([[2, 0, 0], [0, 0.01, 0], [0, 0.01, 0.0]]),
        "n00": np.stack([z] * 3), "n10": np.stack([z, _unit([0.1, 0, 1.0]), z]),
        "n01": np.stack([z, _unit([0, 0.1, 1.0]), z]),
        "l_dir": np.stack([-z, -z, _unit([1, 0, -0.05])]),
        "eta": np.full(3, 1.333), "t_hit": np.array([1.0, 2.0, 3.0]), "s": np.array([2.0, 1.5, 2.0]),
        "c": np.array([1.0, 0.0, 2.0]),
    }
    return _stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


def _eval_photon(x):
    if _transport_compression_ratio is not None:
        sigma, _ = _transport_compression_ratio(x["x00"], x["x10"], x["x01"], x["n00"], x["n10"], x["n01"], x["l_dir"],
                                                x["t_hit"], eta=x["eta"], scale=x["s"], level=x["c"], mode="refract")
    else:
        sigma = _photon_compression_ratio(x["x00"], x["x10"], x["x01"], x["n00"], x["n10"], x["n01"], x["l_dir"],
                                          x["eta"], x["t_hit"], x["s"], x["c"])
    return {"sigma": sigma}


def _gen_reuse(rng, n):
    n_pl, n_rand = _split(n)
    p = rng.uniform(-1, 1, (n_rand, 3))
    r = rng.uniform(1e-4, 5e-3, n_rand)
    p_prev = p + _unit(rng.normal(size=(n_rand, 3))) * (r * rng.uniform(0, 2, n_rand))[:, None]
    # planted: |p - p_prev| = k sigma along an axis, so w = exp(-k^2 / 2) (seed 000 eq. 3)
    q = rng.uniform(-1, 1, (n_pl, 3))
    rq = rng.uniform(1e-3, 5e-3, n_pl)
    k = rng.uniform(0, 3, n_pl)
    q_prev = q + np.eye(3)[rng.integers(0, 3, n_pl)] * (k * 0.75 * rq)[:, None]
    adv = {  # coincident points, r = 0 (delta kernel: 1 at coincident points, else 0), far away
        "p_prev": np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.51], [100, 100, 100.0]]),
        "p": np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.6], [0.5, 0.5, 0.5], [100, 100, 100.001]]),
        "r": np.array([1e-3, 0.0, 0.0, 1e-3, 1e-3]),
    }
    return _stack_cases([({"p_prev": p_prev, "p": p, "r": r}, CASES["random"]),
                         ({"p_prev": q_prev, "p": q, "r": rq}, CASES["planted"]), (adv, CASES["adversarial"])])


def _eval_reuse(x):
    return {"w": reuse_weight(x["p_prev"], x["p"], x["r"])}


def _gen_bilateral(rng, n):
    n_pl, n_rand = _split(n)
    m = n_rand
    pos_p = rng.uniform(-5, 5, (m, 3))
    rand = {"z_p": rng.uniform(0.1, 50, m), "z_q": rng.uniform(0.1, 50, m), "pos_p": pos_p,
            "pos_q": pos_p + rng.normal(0, 1, (m, 3)), "delta": rng.choice([15.0, 2.0, 1.0], m),
            "eps": np.ones(m)}
    # planted: q = p, the centre weight of Alg. 4 is 1 / eps
    pp = rng.uniform(-5, 5, (n_pl, 3))
    z = rng.uniform(0.1, 50, n_pl)
    planted = {"z_p": z, "z_q": z, "pos_p": pp, "pos_q": pp, "delta": rng.choice([15.0, 2.0, 1.0], n_pl),
               "eps": rng.choice([1.0, 0.5, 0.25], n_pl)}
    adv = {"z_p": np.array([0.1, 1e4, 1.0, 1.0]), "z_q": np.array([1e4, 0.1, 1.0, 1.0 + 2**-20]),
           "pos_p": np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0.0]]),
           "pos_q": np.array([[0, 0, 0], [1e3, 0, 0], [1e-3, 0, 0], [0, 0, 0.0]]),
           "delta": np.array([1.0, 1.0, 1e-4, 15.0]), "eps": np.array([1.0, 1.0, 1e-6, 1e-6])}
    return _stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


def _eval_bilateral(x):
    return {"w": bilateral_weight(x["z_p"], x["z_q"], x["pos_p"], x["pos_q"], x["delta"], x["eps"])}


FIXED_POINT_ADDENDS = 16


def _gen_fixed(rng, n):
    n_pl, n_rand = _split(n)
    k = FIXED_POINT_ADDENDS
    rand = rng.uniform(0, 1.6, (n_rand, k)) * rng.uniform(0, 1, (n_rand, 1))  # some sums reach 16
    planted = rng.integers(0, 2**24, (n_pl, k)) * 2.0**-28  # exact multiples of the step (24 bits: exact in float32)
    ties = (2 * rng.integers(0, 2**20, k) + 1) * 2.0**-29  # half-way between two codes
    adv = np.stack([np.zeros(k), np.full(k, 1.0), ties, np.full(k, 20.0), np.full(k, 15.999),
                    np.full(k, 2.0**-29), np.full(k, 3 * 2.0**-29)])
    return _stack_cases([({"x": rand}, CASES["random"]), ({"x": planted}, CASES["planted"]),
                         ({"x": adv}, CASES["adversarial"])])


def _eval_fixed(x):
    def one(row):
        s = fixed_point_accumulate(row)
        return s.code[0], s.overflow[0], s.value[0]

    code, overflow, value = jax.vmap(one)(x["x"])
    return {"code": code, "overflow": overflow.astype(jnp.uint32), "value": value}


def _in(name, glsl, length=None):
    return Field(name, glsl, "input", length)


def _out(name, glsl, length=None, scale_field=None):
    return Field(name, glsl, "output", length, scale_field)


_PATH_FIELDS = [_in("V", "vec3", 3), _in("N", "vec3", 3), _in("P", "vec3"), _in("L", "vec3"), _in("ab", "vec2"),
                _in("eta", "float")]

KERNELS: dict[str, Kernel] = {k.name: k for k in [
    Kernel("refract", "GLSL refract (MATH.md §1; seed 002 eq. 3.1-3.2)",
           [_in("I", "vec3"), _in("N", "vec3"), _in("eta", "float"), _out("T", "vec3")],
           _gen_refract, _eval_refract, _keep_refract, {"T": ("refract (abs, unit vector)", "abs")},
           reference="caustics_jax.geometry.refract"),
    Kernel("fresnel", "exact unpolarised dielectric Fresnel reflectance (the F of seed 001 eq. 25)",
           [_in("cos_i", "float"), _in("eta", "float"), _out("R", "float")],
           _gen_fresnel, _eval_fresnel, _keep_fresnel, {"R": ("Fresnel R air->water (abs)", "abs")},
           reference="caustics_jax.geometry.fresnel_reflectance"),
    Kernel("conic_coefficients", "seed 001 eq. 10-12 (MATH.md §2)",
           [_in("V", "vec3", 3), _in("N", "vec3", 3), _in("P", "vec3"), _in("L", "vec3"),
            _out("coef", "float", 6)],
           _gen_conic, _eval_conic, None, {"coef": ("conic coefficients (max abs / max |coef|)", "rel")},
           reference="caustics_jax.conic.conic_coefficients"),
    Kernel("conic_tangent", "seed 001 eq. 13-15 with the symmetric part S (MATH.md §2)",
           [_in("coef", "float", 6), _in("ab", "vec2"), _out("t", "vec2", scale_field="coef")],
           _gen_tangent, _eval_tangent, reference="caustics_jax.conic.conic_tangent"),
    Kernel("edge_intersections", "seed 001 eq. 22-24, corrected (MATH.md §3); roots edge-major, index 2 e + k; "
           "window tol = 64 float32 eps",
           [_in("coef", "float", 6), _out("t", "float", 6), _out("valid", "uint", 6)],
           _gen_edges, _eval_edges, _keep_edges, reference="caustics_jax.conic.edge_intersections",
           filter_planted=True),
    Kernel("signed_sine", "seed 001 eq. 19-21, orientation 'plane' (objectives.signed_sine_and_status)",
           _PATH_FIELDS + [_out("f", "float"), _out("status", "uint")],
           _gen_signed_sine, _eval_signed_sine, _keep_signed_sine,
           {"f": ("signed sine at planted M (abs)", "abs")},
           reference="caustics_jax.objectives.signed_sine_and_status"),
    Kernel("d_factor", "seed 001 eq. 26-33, signs as in transport/differentials.py",
           _PATH_FIELDS + [_out("D", "float"), _out("valid", "uint")],
           _gen_D, _eval_D, _keep_D, reference="caustics_jax.transport.differentials.ray_differential_D"),
    Kernel("photon_compression", "seed 004 eq. 10-11, Alg. 2 (refraction variant, MATH.md §7)",
           [_in("x00", "vec3"), _in("x10", "vec3"), _in("x01", "vec3"), _in("n00", "vec3"), _in("n10", "vec3"),
            _in("n01", "vec3"), _in("l_dir", "vec3"), _in("eta", "float"), _in("t_hit", "float"),
            _in("s", "float"), _in("c", "float"), _out("sigma", "float")],
           _gen_photon, _eval_photon, reference=PHOTON_REFERENCE),
    Kernel("reuse_weight", "seed 000 eq. 3, sigma = 0.75 r",
           [_in("p_prev", "vec3"), _in("p", "vec3"), _in("r", "float"), _out("w", "float")],
           _gen_reuse, _eval_reuse, reference="caustics_jax.kernels.collection.reuse_weight"),
    Kernel("bilateral_weight", "seed 004 eq. 21-23 (eps of Alg. 4 line 22 as an input)",
           [_in("z_p", "float"), _in("z_q", "float"), _in("pos_p", "vec3"), _in("pos_q", "vec3"),
            _in("delta", "float"), _in("eps", "float"), _out("w", "float")],
           _gen_bilateral, _eval_bilateral, reference="caustics_jax.kernels.bilateral.bilateral_weight"),
    Kernel("fixed_point", f"seed 000 §3.2: 4.28 fixed point, {FIXED_POINT_ADDENDS} addends per record, "
           "wrapping 32-bit adds",
           [_in("x", "float", FIXED_POINT_ADDENDS), _out("code", "uint"), _out("overflow", "uint"),
            _out("value", "float")],
           _gen_fixed, _eval_fixed, reference="caustics_jax.kernels.fixed_point.fixed_point_accumulate"),
]}

for _k in KERNELS.values():  # every record carries its case tag
    _k.fields.append(Field("case_tag", "uint", "case"))  # `case` is a keyword in C and GLSL


# --------------------------------------------------------------------------- records

def record_fields(kernel: Kernel) -> list[dict]:
    """Manifest entries of the record's fields (name, dtype, shape, storage_shape, offset, role, glsl)."""
    offsets, _ = layout(kernel.fields)
    return [{"name": f.name, "dtype": f.dtype, "shape": f.shape, "storage_shape": f.storage_shape,
             "offset": off, "role": f.role, "glsl": f.glsl + (f"[{f.length}]" if f.length else "")}
            for f, off in zip(kernel.fields, offsets, strict=True)]


def _field_view(raw: bytes | np.ndarray, entry: dict, count: int, stride: int) -> np.ndarray:
    """Strided numpy view of one field over all records, padding columns dropped."""
    dtype = np.dtype("<" + {"float32": "f4", "int32": "i4", "uint32": "u4"}[entry["dtype"]])
    sshape = list(entry["storage_shape"])
    strides = [dtype.itemsize] * len(sshape)
    for i in range(len(sshape) - 2, -1, -1):
        strides[i] = strides[i + 1] * sshape[i + 1]
    view = np.ndarray((count, *sshape), dtype, buffer=raw, offset=entry["offset"], strides=(stride, *strides))
    if sshape != list(entry["shape"]):
        view = view[..., : entry["shape"][-1]]
    return np.array(view)


def read_records(manifest: dict, raw: bytes) -> dict[str, np.ndarray]:
    """Every field of a `.bin` as a numpy array `(count, *shape)`, using nothing but the manifest."""
    if len(raw) != manifest["count"] * manifest["stride"]:
        raise ValueError(f"binary holds {len(raw)} bytes, manifest says {manifest['count']} x {manifest['stride']}")
    return {e["name"]: _field_view(raw, e, manifest["count"], manifest["stride"]) for e in manifest["fields"]}


def load(out_dir, kernel: str) -> tuple[dict, dict[str, np.ndarray]]:
    """`(manifest, records)` of `out_dir/<kernel>.json` and `.bin`."""
    out_dir = Path(out_dir)
    manifest = json.loads((out_dir / f"{kernel}.json").read_text())
    return manifest, read_records(manifest, (out_dir / f"{kernel}.bin").read_bytes())


def pack_records(kernel: Kernel, values: dict[str, np.ndarray]) -> bytes:
    """std430 bytes of `values` (one array per field, leading axis = records)."""
    offsets, stride = layout(kernel.fields)
    count = len(values["case_tag"])
    buf = np.zeros(count * stride, np.uint8)
    for f, off in zip(kernel.fields, offsets, strict=True):
        np_dtype = np.dtype(_TYPES[f.glsl][2])
        v = np.asarray(values[f.name]).astype(np_dtype).reshape(count, *f.shape)
        if f.storage_shape != f.shape:
            pad = np.zeros((count, *f.storage_shape), np_dtype)
            pad[..., : f.shape[-1]] = v
            v = pad
        item = np.ascontiguousarray(v).view(np.uint8).reshape(count, -1)
        rows = buf.reshape(count, stride)
        rows[:, off: off + item.shape[1]] = item
    return buf.tobytes()


# --------------------------------------------------------------------------- errors

def ulp_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance in float32 units in the last place (ordered integer difference); 2^32 for NaN."""
    a, b = np.asarray(a, np.float32), np.asarray(b, np.float32)

    def ordered(x):
        i = x.view(np.int32).astype(np.int64)
        return np.where(i < 0, -(i & 0x7FFFFFFF), i)

    d = np.abs(ordered(a) - ordered(b))
    return np.where(np.isnan(a) | np.isnan(b), 2**32, d)


def field_scale(records: dict[str, np.ndarray], ref: np.ndarray, field: dict | Field) -> np.ndarray:
    """Per-record tolerance scale: the largest magnitude of the field (or of `scale_field`)."""
    name = field["scale_field"] if isinstance(field, dict) else field.scale_field
    src = np.asarray(records[name] if name else ref, np.float64)
    return np.max(np.abs(src.reshape(len(src), -1)), axis=1)


def compare(manifest: dict, records: dict[str, np.ndarray], got: dict[str, np.ndarray]) -> dict:
    """Per output field and over the kernel: max abs / rel / ULP error and pass rate vs tolerance.

    `got` holds a port's outputs (e.g. read back from a GPU), `records` the export. A record
    passes when every element of every output field is within `abs + rel * scale` (float
    fields) or equal (integer fields); NaN never passes.
    """
    count = manifest["count"]
    ok = np.ones(count, bool)
    fields = {}
    for e in manifest["fields"]:
        if e["role"] != "output":
            continue
        ref, val = records[e["name"]].reshape(count, -1), np.asarray(got[e["name"]]).reshape(count, -1)
        if e["dtype"] != "float32":
            good = np.all(ref == val, axis=1)
            fields[e["name"]] = {"mismatches": int(np.sum(~good)), "pass_rate": float(np.mean(good))}
        else:
            tol = manifest["tolerance"][e["name"]]
            err = np.abs(val.astype(np.float64) - ref.astype(np.float64))
            err = np.where(np.isnan(err), np.inf, err)
            scale = field_scale(records, ref, tol)
            bound = tol["abs"] + tol["rel"] * scale[:, None]
            good = np.all(err <= bound, axis=1)
            usage = np.where(err == 0, 0.0, err / np.where(bound > 0, bound, np.finfo(np.float64).tiny))
            pos = scale > 0  # relative error only where the reference is not all zero
            rel = err[pos] / scale[pos, None]
            fields[e["name"]] = {"max_abs": float(err.max()), "max_rel": float(rel.max(initial=0.0)),
                                 "max_ulp": int(ulp_distance(val, ref).max()), "pass_rate": float(np.mean(good)),
                                 "tol_abs": tol["abs"], "tol_rel": tol["rel"], "max_err_over_tol": float(usage.max())}
        ok &= good
    return {"kernel": manifest["kernel"], "count": count, "fields": fields, "pass_rate": float(np.mean(ok)),
            "failures": np.nonzero(~ok)[0].tolist()}


# --------------------------------------------------------------------------- export

def _audit() -> dict:
    try:
        return json.loads(AUDIT_FILE.read_text())["float32"]
    except (OSError, KeyError, ValueError):
        return {}


def _evaluate(kernel: Kernel, inputs: dict[str, np.ndarray], dtype: str) -> dict[str, np.ndarray]:
    with precision(dtype):
        args = {k: jnp.asarray(v, dtype) for k, v in inputs.items()}
        return {k: np.asarray(v) for k, v in jax.jit(kernel.evaluate)(args).items()}


def _tolerance(kernel: Kernel, f: Field, records, ref, f32, audit: dict) -> dict:
    """Tolerance of one float output field from the measured float32 error (module docstring)."""
    count = len(ref)
    err = np.abs(f32.astype(np.float64) - ref.astype(np.float64)).reshape(count, -1).max(axis=1)
    scale = field_scale(records, ref, f)
    # errors of values below 1 in magnitude count as absolute, above 1 as relative
    small = scale <= 1
    meas_abs = float(err[small].max()) if small.any() else 0.0
    meas_rel = float((err[~small] / scale[~small]).max()) if (~small).any() else 0.0
    audit_key, audit_kind = kernel.audit.get(f.name, (None, None))
    audit_max = float(audit[audit_key]["max"]) if audit_key in audit else 0.0
    abs_tol = SAFETY * max(meas_abs, audit_max if audit_kind == "abs" else 0.0)
    rel_tol = SAFETY * max(meas_rel, audit_max if audit_kind == "rel" else 0.0, STORAGE_ROUNDING)
    # storage rounding of the reference and its own float64 error, on top of the margin
    abs_tol += STORAGE_ROUNDING * float(min(scale.max(initial=0.0), 1.0))
    rel_tol += STORAGE_ROUNDING + F64_BUDGET
    return {"abs": abs_tol, "rel": rel_tol, "scale_field": f.scale_field,
            "measured_float32": {"max_abs_below_1": meas_abs, "max_rel_above_1": meas_rel},
            "audit": {"key": audit_key, "max": audit_max} if audit_key in audit else None,
            "safety": SAFETY}


def export_kernel(kernel: Kernel, count: int, seed: int, audit: dict | None = None):
    """`(manifest, binary bytes)` for one kernel: `count` random and planted records plus the adversarial set."""
    audit = _audit() if audit is None else audit
    rng = np.random.default_rng([seed, zlib.crc32(kernel.name.encode())])
    inputs, case = kernel.generate(rng, count)
    # inputs as stored (float32), and the reference computed in float64 from exactly those
    stored = {f.name: np.asarray(inputs[f.name], np.float32) for f in kernel.inputs()}
    ref = _evaluate(kernel, {k: v.astype(np.float64) for k, v in stored.items()}, "float64")
    if kernel.keep is not None:
        x64 = {k: v.astype(np.float64) for k, v in stored.items()}
        with np.errstate(invalid="ignore", divide="ignore"):  # adversarial rows may be degenerate
            filtered = (case == CASES["random"]) | ((case == CASES["planted"]) & kernel.filter_planted)
            keep = kernel.keep(x64, ref) | ~filtered
    else:
        keep = np.ones(len(case), bool)
    n_pl, n_rand = _split(count)
    rand_idx = np.nonzero(keep & (case == CASES["random"]))[0][:n_rand]
    if len(rand_idx) < n_rand:
        raise RuntimeError(f"{kernel.name}: only {len(rand_idx)} of {n_rand} random cases are well conditioned")
    planted_idx = np.nonzero(keep & (case == CASES["planted"]))[0][:n_pl]
    if len(planted_idx) < n_pl:
        raise RuntimeError(f"{kernel.name}: only {len(planted_idx)} of {n_pl} planted cases are well conditioned")
    idx = np.concatenate([rand_idx, planted_idx,
                          np.nonzero(case == CASES["adversarial"])[0]])
    stored = {k: v[idx] for k, v in stored.items()}
    ref = {k: v[idx] for k, v in ref.items()}
    case = case[idx]
    f32 = _evaluate(kernel, stored, "float32")
    records = {**stored, **ref, "case_tag": case}
    tolerance = {}
    for f in kernel.outputs():
        if f.dtype == "float32":
            tolerance[f.name] = _tolerance(kernel, f, records, ref[f.name], f32[f.name], audit)
        else:
            tolerance[f.name] = {"exact": True}
    _, stride = layout(kernel.fields)
    from . import __version__

    manifest = {
        "kernel": kernel.name,
        "equations": kernel.equations,
        "reference": kernel.reference,
        "count": int(len(case)),
        "stride": stride,
        "endianness": "little",
        "layout": "std430, vec3 padded to 16 bytes",
        "fields": record_fields(kernel),
        "tolerance": tolerance,
        "tolerance_rule": "float fields: |value - ref| <= abs + rel * scale per element, scale = max |.| of the "
                          "field (or of scale_field) in the record; integer fields: equal",
        "cases": {name: {"code": code, "count": int(np.sum(case == code))} for name, code in CASES.items()},
        "seed": seed,
        "version": {"format": FORMAT_VERSION, "caustics_jax": __version__},
    }
    return manifest, pack_records(kernel, records)


def _c_field(f: Field, offset: int) -> str:
    ctype = _TYPES[f.glsl][3]
    dims = "".join(f"[{d}]" for d in f.storage_shape)
    note = "  /* vec3: 4th float is padding */" if f.glsl == "vec3" else ""
    return f"    {ctype} {f.name}{dims}; /* offset {offset}, {f.role} */{note}"


def c_header(kernels: list[Kernel]) -> str:
    """C11 header declaring one struct per record, with static asserts on every offset and size."""
    lines = ["/* Generated by `caustics-jax export`: std430 records of the caustics_jax reference data.",
             " * One struct per kernel; arrays of vec3 and vec3 members take 4 floats (the 4th is padding).",
             " * Case tags: " + ", ".join(f"{k} = {v}" for k, v in CASES.items()) + ". */",
             "#ifndef CAUSTICS_RECORDS_H", "#define CAUSTICS_RECORDS_H", "#include <stddef.h>",
             "#include <stdint.h>", f"#define CAUSTICS_RECORDS_VERSION {FORMAT_VERSION}", ""]
    for k in kernels:
        offsets, stride = layout(k.fields)
        sname = f"cj_{k.name}_record"
        lines.append(f"/* {k.name}: {k.equations} */")
        lines.append(f"typedef struct {sname} {{")
        end = 0
        for f, off in zip(k.fields, offsets, strict=True):
            if off > end:  # std430 alignment gap (vec2 on 8, vec3/vec4 on 16 bytes)
                lines.append(f"    uint8_t _pad_{f.name}[{off - end}];")
            lines.append(_c_field(f, off))
            end = off + f.size
        last = end
        if stride > last:
            lines.append(f"    uint8_t _pad_end[{stride - last}];")
        lines.append(f"}} {sname};")
        lines.append(f"_Static_assert(sizeof({sname}) == {stride}, \"{k.name} stride\");")
        lines += [f"_Static_assert(offsetof({sname}, {f.name}) == {off}, \"{k.name}.{f.name}\");"
                  for f, off in zip(k.fields, offsets, strict=True)]
        lines.append("")
    lines.append("#endif")
    return "\n".join(lines) + "\n"


def export(out_dir, kernels: list[str] | None = None, count: int = 256, seed: int = 0) -> list[Path]:
    """Write `<kernel>.json`, `<kernel>.bin` per kernel and `caustics_records.h` into `out_dir`.

    `count` random and planted records per kernel (a quarter planted), plus each kernel's
    fixed adversarial cases. Same arguments, same bytes. Raises ValueError on unknown
    kernel names, a count below 4, a negative seed or an `out_dir` that is a file.
    """
    names = list(KERNELS) if not kernels else list(kernels)
    unknown = [k for k in names if k not in KERNELS]
    if unknown:
        raise ValueError(f"unknown kernel(s) {unknown}; choose from {sorted(KERNELS)}")
    if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 4:
        raise ValueError(f"count must be an integer >= 4, got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    audit = _audit()
    written = []
    for name in names:
        manifest, raw = export_kernel(KERNELS[name], int(count), int(seed), audit)
        (out / f"{name}.json").write_text(json.dumps(manifest, indent=1) + "\n")
        (out / f"{name}.bin").write_bytes(raw)
        written += [out / f"{name}.json", out / f"{name}.bin"]
    (out / "caustics_records.h").write_text(c_header([KERNELS[n] for n in names]))
    written.append(out / "caustics_records.h")
    return written
