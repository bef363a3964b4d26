"""`runtime.fusion.stored`: exact (every bit of every leaf back, floats' signed zeros and
NaN payloads included), and a real store on XLA:CPU (a shared chain of element-wise
decisions is computed once, not copied into each output's kernel)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax.runtime.fusion import stored


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_stored_returns_every_bit(dtype):
    info = np.finfo(dtype)
    uint = {4: np.uint32, 8: np.uint64}[info.bits // 8]
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, info.tiny, info.tiny / 4, -info.max, 1.0], dtype)
    payload_nan = np.array([0x7FC00001 if info.bits == 32 else 0x7FF8000000000001], uint).view(dtype)
    rng = np.random.default_rng(3)
    x = np.concatenate([special, payload_nan, rng.standard_normal(64).astype(dtype)])
    # booleans: more than one word of them (70 + 3 + 10 bits), a matrix, a scalar, an empty one
    tree = {"x": x, "i": np.arange(-5, 5, dtype=np.int32), "b": np.arange(10) % 3 == 0, "m": x[:8].reshape(2, 4),
            "many": rng.random(70) < 0.5, "grid": rng.random((3, 1)) < 0.5, "one": np.bool_(True),
            "none": np.zeros(0, bool)}
    out = jax.jit(stored)(tree)
    for k, v in tree.items():
        got = np.asarray(out[k])
        assert got.dtype == v.dtype and got.shape == v.shape
        assert got.tobytes() == v.tobytes(), k


def _fused_instructions(fn, *args) -> int:
    """Instructions inside XLA:CPU's fused computations of `jit(fn)` (copies counted)."""
    text = jax.jit(fn).lower(*args).compile().as_text()
    body, total = False, 0
    for line in text.splitlines():
        if line.startswith("%fused") or line.startswith("fused"):
            body = True
        elif line.startswith("}"):
            body = False
        elif body and "=" in line and "parameter(" not in line:
            total += 1
    return total


def _chain(x):
    """A chain of 40 element-wise compares."""
    flag = x > 0
    for k in range(40):
        flag = flag ^ (x * (k + 1) > k)
    return flag


def _fused_without_and_with(program) -> tuple[int, int]:
    """Fused instructions of `program(x, ys, False)` and of `program(x, ys, True)` on 512
    lanes, after checking that both give the same outputs."""
    x = jnp.linspace(-1, 1, 512)
    ys = [x + i for i in range(10)]
    np.testing.assert_array_equal(jax.jit(lambda x, ys: program(x, ys, True))(x, ys),
                                  jax.jit(lambda x, ys: program(x, ys, False))(x, ys))
    return tuple(_fused_instructions(lambda x, ys, on=on: program(x, ys, on), x, ys) for on in (False, True))


def test_stored_decisions_are_computed_once_on_cpu():
    """Ten outputs select on one chain of 40 compares: without `stored` XLA:CPU copies the
    chain into the outputs' kernels, with it the chain is computed once."""
    if jax.default_backend() != "cpu":
        pytest.skip("the fusion behaviour measured is XLA:CPU's")

    def program(x, ys, store):
        flag = stored(_chain(x)) if store else _chain(x)
        return [jnp.where(flag, y, -y) * (i + 2) for i, y in enumerate(ys)]

    copied, once = _fused_without_and_with(program)
    assert once * 3 < copied, (once, copied)


def test_stored_booleans_share_one_kernel_on_cpu():
    """Ten decisions that share one chain of 40 compares, stored together: the chain is
    computed once (in the kernel of their shared word), where ten booleans stored one by
    one compute it ten times (each stored leaf is its own kernel)."""
    if jax.default_backend() != "cpu":
        pytest.skip("the fusion behaviour measured is XLA:CPU's")

    def program(x, ys, together):
        chain = _chain(x)
        flags = [chain ^ (x > i / 10) for i in range(10)]
        flags = stored(flags) if together else [stored(f) for f in flags]
        return [jnp.where(f, y, -y) for f, y in zip(flags, ys, strict=True)]

    apart, together = _fused_without_and_with(program)
    assert together * 3 < apart, (together, apart)


def test_the_walk_crossing_step_computes_its_decisions_once():
    """The walk's crossing step (the pool's widest program) compiles to fewer than 3,500
    fused instructions at 512 lanes: 2,443 with its outcome stored, 4,967 without, when
    XLA:CPU copies the decisions into each state field's kernel (this 512-face pool,
    2026-12-02; docs/solvers.md "Stored decisions"). Shapes only: the step is compiled,
    never run."""
    if jax.default_backend() != "cpu":
        pytest.skip("the fusion behaviour measured is XLA:CPU's")
    import caustics_jax as cj
    from caustics_jax.runtime.lane_solver import stage_lane
    from caustics_jax.solvers.walk import Walk, WalkLane, WalkSolver
    from caustics_jax.solvers.walk_steps import BISECT, WALK

    mesh = cj.scenes.wavy_pool(512, n_receivers=4, dtype="float32").surface
    f32 = jnp.float32
    solver = WalkSolver(mesh, f32(1.333), f32(1e-5), jnp.int32(512), Walk())
    n = 512
    lanes = WalkLane(jax.ShapeDtypeStruct((n, 3), f32), jax.ShapeDtypeStruct((n, 3), f32),
                     jax.ShapeDtypeStruct((n,), jnp.int32), jax.ShapeDtypeStruct((n, 2), f32),
                     jax.ShapeDtypeStruct((n,), jnp.bool_))
    moving = jax.eval_shape(jax.vmap(lambda x: solver.moving(stage_lane(solver, x))), lanes)
    count = _fused_instructions(jax.vmap(lambda m: solver.step(m, WALK)), moving)
    assert count < 3500, count
    # The refinement step: 1,798 with its decisions stored, 2,982 without (2026-12-04).
    count = _fused_instructions(jax.vmap(lambda m: solver.step(m, BISECT)), moving)
    assert count < 2400, count
