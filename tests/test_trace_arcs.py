"""`arcs.trace_arcs`, the library's curve tracer (seed 001 §3.4.3; math.md §2-3): its samples
lie on the coplanarity curve, inside their face, and its arcs chain across edges.

One trace per dtype (one compile each) of a small wavy pool; the checks are the numpy
oracle's (`testing.oracle.triple_product`, seed 001 eq. 9; `inside_triangle`, eq. 3).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax.curve.arcs import N_ARCS, trace_arcs
from caustics_jax.surface.scenes import wavy_pool
from caustics_jax.testing import oracle

SAMPLES = 32
P = np.array([-0.6, -0.5, -0.6])
L = np.array([0.8, 0.6, 1.0])
# Measured on this scene (126 arcs, 4032 samples): relative triple product of the samples
# 3.5e-16 (float64) and 1.0e-7 (float32, against the float64 mesh); end samples off their
# exact roots along the curve by 2e-7 / 5e-3 (barycentric, the tangent-line conditioning of
# the pencil at u = 0, documented in `trace_arcs`); interior samples inside their face
# exactly in float64, within 4.2e-7 in float32. Bounds keep about 10x.
ON_CURVE = {jnp.float64: 5e-15, jnp.float32: 1e-6}
ENDS = {jnp.float64: 2e-6, jnp.float32: 5e-2}
INSIDE = {jnp.float64: 0.0, jnp.float32: 4e-6}


@functools.cache
def _scene():
    mesh = wavy_pool(392, seed=3, amplitude=0.1, wavelength=(0.5, 1.2), dtype="float64").surface
    return oracle.NumpyMesh.from_mesh(mesh).triangles(np.arange(mesh.faces.shape[0]))


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_traced_arcs_lie_on_the_curve_inside_their_faces_and_chain(dtype):
    V, N = _scene()
    trace = jax.jit(trace_arcs, static_argnames=("samples", "return_arcs"))
    ab, xyz, ok, arcs = jax.tree.map(np.asarray, trace(*(jnp.asarray(x, dtype) for x in (V, N, P, L)),
                                                       samples=SAMPLES, return_arcs=True))
    assert ab.shape == (len(V), N_ARCS, SAMPLES, 2) and xyz.shape == (len(V), N_ARCS, SAMPLES, 3)
    assert ab.dtype == xyz.dtype == dtype
    exists = arcs.ok & oracle.inside_triangle(arcs.starts, 0.0)
    f, k = np.nonzero(exists)
    assert len(f) > 50
    samples = ab[f, k].astype(np.float64)
    # a pencil line that misses its second cut leaves the start in place (masked, not poisoned):
    # none in float64; in float32 the samples of 3 nearly straight arcs (phi_end 1e-3 .. 3e-10)
    not_cut = ~ok[f, k, 1:]
    assert not_cut.sum() <= {jnp.float64: 0, jnp.float32: 0.05 * not_cut.size}[dtype]
    starts = np.broadcast_to(arcs.starts[f, k][:, None], samples[:, 1:].shape)
    np.testing.assert_array_equal(samples[:, 1:][not_cut], starts[not_cut])
    rel = oracle.triple_product(V[f][:, None], N[f][:, None], P, L, samples, relative=True)
    assert np.max(rel) < ON_CURVE[dtype]
    np.testing.assert_allclose(xyz[f, k], oracle.barycentric_point(V[f][:, None], samples),
                               atol=10 * float(jnp.finfo(dtype).eps))
    assert np.all(oracle.inside_triangle(samples[:, 1:-1], INSIDE[dtype]))
    assert np.all(oracle.inside_triangle(samples, ENDS[dtype]))
    assert np.max(np.abs(samples[:, 0] - arcs.starts[f, k])) < ENDS[dtype]
    assert np.max(np.abs(samples[:, -1] - arcs.ends[f, k])) < ENDS[dtype]
    # each arc between two edge roots is listed from both ends: its end is the start of its twin
    edge_arcs = k < N_ARCS - 1
    twins = [np.any(exists[fi, : N_ARCS - 1] & np.all(arcs.starts[fi, : N_ARCS - 1] == arcs.ends[fi, ki], -1))
             for fi, ki in zip(f[edge_arcs], k[edge_arcs], strict=True)]
    assert all(twins)
