"""Lane scheduling (`caustics_jax.runtime.lanes`): the slot pool against the chunked scheduler,
compaction of rare work, fixed-size blocks (one compile whatever the lane count), and the
persistent compilation cache's settings.

The scheduler comparison runs 4096 lanes of the default pool's receivers (a floor grid
under the point light of `scenes.wavy_pool`) on a 2048-triangle pool in both dtypes.
"""

import functools
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax import Newton, Walk, scenes, solve
from caustics_jax.runtime import compilation
from caustics_jax.runtime.blocks import run_blocks
from caustics_jax.runtime.lane_solver import SCHEDULERS, LaneSolver, Stage, run_lanes
from caustics_jax.runtime.lanes import LanePacking
from caustics_jax.runtime.pools import map_where, run_pools
from caustics_jax.testing import assert_same_lanes

DTYPES = ["float32", "float64"]
FIELDS = ("status", "point", "barycentric", "triangle", "iterations", "crossed", "residual", "start_point")
SOLVERS = {
    "walk": lambda **kw: Walk(**kw),
    "newton": lambda **kw: Newton(**kw),
    "newton-one-step": lambda **kw: Newton(stepping="one_step", **kw),
}


@functools.cache
def _pool(dtype):
    """4096 receivers of the default pool's layout (64 x 64 floor grid, one point light)."""
    sc = scenes.wavy_pool(2048, n_receivers=64, dtype=dtype)
    return sc.surface, np.asarray(sc.receivers), np.asarray(sc.lights.endpoint(sc.receivers))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("solver", list(SOLVERS))
def test_slot_pool_gives_the_lanes_of_the_chunked_scheduler(solver, dtype):
    """Same per-lane iteration, another schedule: statuses, iteration counts and crossings
    are identical, points and residuals within rounding of the program's vector code
    (`assert_same_lanes`; the pool's 256 slots vmap the step at the chunks' width,
    `pools.pool_slots`)."""
    mesh, P, L = _pool(dtype)
    assert len(P) == 4096
    pool = solve(mesh, P, L, method=SOLVERS[solver](scheduler="pool"))
    chunked = solve(mesh, P, L, method=SOLVERS[solver](scheduler="chunked"))
    assert np.asarray(pool.found).mean() > 0.99, pool.summary()
    if solver != "newton-one-step":
        assert_same_lanes(pool, chunked, FIELDS)
        return
    # A lane whose |f| lies within f's rounding noise of `tol` in either run (the float32
    # audit's 1e-6 noise floor of f; 1e-14 in float64) is accepted by rounding: one program
    # stops, the other takes one more step. Measured: 1 lane of 4096 in float32 (closed-form
    # Jacobian, 2026-12-02) stopped after 2 steps at |f| = 9.98e-6 in one run and after 3 at
    # 2.2e-7 in the other, points 6.5e-6 m apart; 55 of the 4096 end within the noise of tol
    # (a step stops at the first |f| <= tol). Such lanes must both be FOUND within the tolerance band:
    # two points that pass |f| <= tol lie within about 2 tol (d_P + d_L) of each other.
    tol = Newton().tolerance(jnp.dtype(dtype))
    noise = 1e-6 if dtype == "float32" else 1e-14
    at_tol = np.maximum(np.abs(np.asarray(pool.residual)), np.abs(np.asarray(chunked.residual))) > tol - noise
    assert at_tol.mean() <= 0.05, f"{int(at_tol.sum())} lanes at the tolerance"  # measured 55 of 4096
    M = np.asarray(pool.point, np.float64)
    band = 2 * tol * (np.linalg.norm(P - M, axis=-1) + np.linalg.norm(L - M, axis=-1))
    gap = np.linalg.norm(M - np.asarray(chunked.point, np.float64), axis=-1)
    assert np.all(np.asarray(pool.found)[at_tol] & np.asarray(chunked.found)[at_tol])
    assert np.all(gap[at_tol] <= band[at_tol]), (gap[at_tol], band[at_tol])
    keep = ~at_tol
    assert_same_lanes(jax.tree.map(lambda x: x[keep], pool), jax.tree.map(lambda x: x[keep], chunked), FIELDS)


class _Toy(LaneSolver):
    """A lane solver in integers (exact at any vector width): stages that double `x`, set
    `y` only where `x` is odd (kept elsewhere) and draw `z` only where `x > 50` (zeros
    elsewhere: the whole record, so those lanes take no step); two phases chosen by the
    parity of `x`; two passes, the second restarting the lanes whose `x` ended above 100
    (once). Only `(x, k, n)` move through the pools."""

    phases: ClassVar[tuple[str, ...]] = ("even", "odd")
    passes: ClassVar[int] = 2
    pool_shares: ClassVar[tuple[float, ...]] = (1.0, 0.5)

    def stages(self):
        def double(c):
            return {**c, "x": 2 * c["x"] + c["n"] % 2}

        return (Stage(double),
                Stage(lambda c: {**c, "y": c["x"] * 7 + 1}, when=lambda c: c["x"] % 2 == 1, keep=True),
                Stage(lambda c: {**c, "z": c["x"] - 50}, when=lambda c: c["x"] > 50))

    def route(self, m):
        return jnp.where(m["k"] < m["n"], m["x"] % 2, -1).astype(jnp.int32)

    def step(self, m, phase):
        even = {**m, "x": (m["x"] // 2 + 5) % 1009, "k": m["k"] + 1}
        odd = {**m, "x": (3 * m["x"] + 1) % 1013, "k": m["k"] + 1}
        if phase is None:
            return jax.tree.map(lambda a, b: jnp.where(m["x"] % 2 == 0, a, b), even, odd)
        return even if phase == 0 else odd

    def restart(self, c):
        again = (c["x"] > 100) & ~c["again"]
        return {**c, "n": jnp.where(again, c["n"] + 3, c["n"]), "again": c["again"] | again}

    def moving(self, c):
        return {"x": c["x"], "k": c["k"], "n": c["n"]}

    def settle(self, c, m):
        return {**c, **m}

    def finish(self, c):
        return c


def test_run_lanes_gives_each_lane_its_own_loop_under_both_schedulers():
    """`runtime.lane_solver.run_lanes`: every lane ends as in a per-lane program of its
    stages, its steps and its restart, under the pool scheduler (pools of unequal widths,
    8 and 4 slots for 300 lanes) and the chunked one; the `when` stages touch only their
    lanes (kept, or zeros elsewhere)."""
    rng = np.random.default_rng(0)
    n = 300
    lanes = {"x": jnp.asarray(rng.integers(0, 60, n), jnp.int32), "n": jnp.asarray(rng.integers(0, 30, n), jnp.int32),
             "k": jnp.zeros(n, jnp.int32), "y": jnp.full(n, -1, jnp.int32), "z": jnp.full(n, -1, jnp.int32),
             "again": jnp.zeros(n, bool)}

    def alone(c):
        c = {**c, "x": 2 * c["x"] + c["n"] % 2}
        c = {**c, "y": jnp.where(c["x"] % 2 == 1, c["x"] * 7 + 1, c["y"])}
        drawn = c["x"] > 50
        c = jax.tree.map(lambda v: jnp.where(drawn, v, jnp.zeros_like(v)), {**c, "z": c["x"] - 50})
        for _ in range(2):
            again = (c["x"] > 100) & ~c["again"]
            c = {**c, "n": jnp.where(again, c["n"] + 3, c["n"]), "again": c["again"] | again}
            c = jax.lax.while_loop(lambda c: c["k"] < c["n"], lambda c: jax.lax.cond(
                c["x"] % 2 == 0, lambda c: {**c, "x": (c["x"] // 2 + 5) % 1009, "k": c["k"] + 1},
                lambda c: {**c, "x": (3 * c["x"] + 1) % 1013, "k": c["k"] + 1}, c), c)
        return c

    want = jax.vmap(alone)(lanes)
    assert 0 < int(np.sum(np.asarray(want["again"]))) < n and 0 < int(np.sum(np.asarray(want["z"]) == 0)) < n
    for scheduler in SCHEDULERS:
        got = jax.jit(lambda x, s=scheduler: run_lanes(_Toy(), x, scheduler=s, slots=8))(lanes)
        for key in lanes:
            np.testing.assert_array_equal(np.asarray(got[key]), np.asarray(want[key]), err_msg=f"{scheduler} {key}")


def test_an_unknown_scheduler_is_refused():
    with pytest.raises(ValueError, match="scheduler must be one of"):
        run_lanes(_Toy(), {"x": jnp.zeros(4, jnp.int32)}, scheduler="fifo")


def test_run_pools_moves_lanes_of_every_dtype_and_shape_exactly():
    """A pool moves lanes as one matrix per dtype (bools with the integers): a state of
    bools, int32, float32 matrices and an empty leaf comes back exactly as per-lane loops
    leave it (the float updates are small integers: exact at any vector width)."""
    rng = np.random.default_rng(1)
    need = jnp.asarray(rng.integers(0, 9, 200), jnp.int32)
    state = {"flag": jnp.asarray(rng.integers(0, 2, 200), bool), "k": jnp.zeros(200, jnp.int32),
             "m": jnp.asarray(rng.integers(-5, 5, (200, 2, 3)), jnp.float32), "none": jnp.zeros((200, 0)),
             "n": need}

    def advance(c):
        return {**c, "flag": ~c["flag"], "k": c["k"] + 1, "m": c["m"] * 2 - c["k"].astype(jnp.float32)}

    def route(c):
        return jnp.where(c["k"] < c["n"], 0, -1).astype(jnp.int32)

    def alone(c):
        return jax.lax.while_loop(lambda c: c["k"] < c["n"], advance, c)

    want = jax.vmap(alone)(state)
    got = jax.jit(lambda s: run_pools((advance,), route, s, 16))(state)
    for key in state:
        assert got[key].dtype == state[key].dtype and got[key].shape == state[key].shape, key
        np.testing.assert_array_equal(np.asarray(got[key]), np.asarray(want[key]), err_msg=key)


def test_lane_packing_carries_booleans_as_bits_32_to_an_int32_column():
    """45 booleans in leaves of shapes (), (40,), (2, 2) and one empty leaf travel as two
    int32 columns after the int32 leaf's (bit 31 included), and unpack to the same values,
    dtypes and shapes; a tree without booleans packs as before."""
    rng = np.random.default_rng(3)
    n = 64
    tree = {"a": jnp.asarray(rng.normal(size=(n, 3)), jnp.float32), "b": jnp.asarray(rng.integers(0, 2, (n, 40)), bool),
            "c": jnp.asarray(rng.integers(-5, 5, n), jnp.int32), "d": jnp.ones(n, bool),
            "e": jnp.asarray(rng.integers(0, 2, (n, 2, 2)), bool), "f": jnp.ones((n, 0), bool)}
    packing = LanePacking(tree)
    floats, ints = jax.jit(packing.pack)(tree)
    assert floats.shape == (n, 3) and ints.shape == (n, 1 + 2) and ints.dtype == jnp.int32
    back = jax.jit(packing.unpack)((floats, ints))
    for key in tree:
        assert back[key].dtype == tree[key].dtype and back[key].shape == tree[key].shape, key
        np.testing.assert_array_equal(np.asarray(back[key]), np.asarray(tree[key]), err_msg=key)
    word = np.asarray(ints[:, 1]).view(np.uint32)  # bits 0-31: the first 32 of "b"
    np.testing.assert_array_equal((word[:, None] >> np.arange(32)) & 1, np.asarray(tree["b"][:, :32]))
    plain = {"a": tree["a"], "c": tree["c"]}
    assert [x.shape for x in LanePacking(plain).pack(plain)] == [(n, 3), (n, 1)]
    empty = {"a": tree["a"], "f": tree["f"]}  # booleans, but no bit to carry
    empty_packing = LanePacking(empty)
    assert empty_packing.unpack(empty_packing.pack(empty))["f"].shape == (n, 0)


def test_map_where_computes_only_the_needed_lanes():
    """`fn` replaces exactly the needed lanes; its trips scale with their count (a chunk of
    16 over 1000 lanes of which 40 need it: 3 trips, traced once)."""
    calls = []

    def fn(x):
        calls.append(x.shape)
        return x * 2 + 1

    need = np.zeros(1000, bool)
    need[np.random.default_rng(1).choice(1000, 40, replace=False)] = True
    x = jnp.arange(1000.0)
    out = jax.jit(lambda n, x: map_where(fn, n, jnp.full(1000, -1.0), x, chunk=16))(jnp.asarray(need), x)
    np.testing.assert_array_equal(np.asarray(out), np.where(need, 2 * np.arange(1000.0) + 1, -1.0))
    assert calls == [()]  # traced once, per lane (vmapped)


def test_map_where_moves_a_pytree_of_every_dtype_exactly():
    """`map_where` carries `out` as one matrix per dtype: bools, int32 and float matrices come
    back exactly, replaced at the needed lanes only (dtype and shape kept)."""
    rng = np.random.default_rng(2)
    need = jnp.asarray(rng.integers(0, 2, 300), bool)
    x = jnp.asarray(rng.integers(-50, 50, 300), jnp.int32)
    out = {"b": jnp.zeros(300, bool), "i": jnp.full(300, -1, jnp.int32), "m": jnp.full((300, 2, 3), 0.5, jnp.float32)}

    def fn(v):
        return {"b": v > 0, "i": v * 3, "m": jnp.full((2, 3), v, jnp.float32) / 4}

    got = jax.jit(lambda n, o, v: map_where(fn, n, o, v, chunk=32))(need, out, x)
    want = jax.vmap(fn)(x)
    for key in out:
        assert got[key].dtype == out[key].dtype and got[key].shape == out[key].shape, key
        mask = np.asarray(need).reshape((-1,) + (1,) * (out[key].ndim - 1))
        np.testing.assert_array_equal(np.asarray(got[key]), np.where(mask, want[key], out[key]), err_msg=key)


def test_map_where_without_out_gives_zeros_elsewhere_and_traces_fn_once():
    """`out=None`: `fn`'s output (a pytree of two dtypes) at the needed lanes, zeros of its
    shape and dtype elsewhere; `fn` is traced once although its output shape is needed
    before the loop (the walk's first triangle: a second trace cost 0.35 s of a first call)."""
    calls = []

    def fn(v):
        calls.append(v.shape)
        return {"i": v * 3, "m": jnp.stack([v, -v]).astype(jnp.float32) + 0.5}

    rng = np.random.default_rng(4)
    need = jnp.asarray(rng.integers(0, 2, 200), bool)
    x = jnp.asarray(rng.integers(-50, 50, 200), jnp.int32)
    got = jax.jit(lambda n, v: map_where(fn, n, None, v, chunk=16))(need, x)
    want = jax.vmap(fn)(x)
    for key in want:
        assert got[key].dtype == want[key].dtype and got[key].shape == want[key].shape, key
        mask = np.asarray(need).reshape((-1,) + (1,) * (want[key].ndim - 1))
        np.testing.assert_array_equal(np.asarray(got[key]), np.where(mask, want[key], 0), err_msg=key)
    assert calls == [(), ()]  # once under map_where's jit, once for `want` above


def test_map_where_on_its_own_record_reads_each_lane_before_writing_it():
    """A stage that updates its own record (`map_where(fn, need, rec, rec)`, read from the
    packed record it writes): every needed lane gets `fn` of its original value over several
    trips, the others keep theirs, as with a separate copy of the arguments; with no lane
    needed, the record itself (and `out=None`: zeros)."""
    rng = np.random.default_rng(5)
    rec = {"i": jnp.asarray(rng.integers(-50, 50, 300), jnp.int32), "b": jnp.asarray(rng.integers(0, 2, 300), bool),
           "m": jnp.asarray(rng.normal(size=(300, 2)), jnp.float32)}

    def fn(r):
        return {"i": r["i"] * 3 + 1, "b": ~r["b"], "m": r["m"][::-1] * 2}

    need = jnp.asarray(rng.integers(0, 2, 300), bool)
    own = jax.jit(lambda n, r: map_where(fn, n, r, r, chunk=16))
    copy = jax.jit(lambda n, r, a: map_where(fn, n, r, a, chunk=16))
    got, want = own(need, rec), copy(need, rec, jax.tree.map(jnp.copy, rec))
    for key in rec:
        mask = np.asarray(need).reshape((-1,) + (1,) * (rec[key].ndim - 1))
        np.testing.assert_array_equal(np.asarray(got[key]), np.where(mask, jax.vmap(fn)(rec)[key], rec[key]), key)
        np.testing.assert_array_equal(np.asarray(got[key]), np.asarray(want[key]), key)
    none = jnp.zeros(300, bool)
    for key, value in own(none, rec).items():
        np.testing.assert_array_equal(np.asarray(value), np.asarray(rec[key]), key)
    zeros = jax.jit(lambda n, r: map_where(fn, n, None, r, chunk=16))(none, rec)
    assert all(not np.any(np.asarray(v)) for v in zeros.values())


def test_run_pools_equals_a_per_lane_loop():
    """Two pools: each lane sees `steps[k](state)` for the pool `k` it is routed to until it
    is done, as in a per-lane loop that branches on its route (the walk's crossing and
    refinement pools). Lanes hop between pools; a step resets `x` once per lane (as the
    walk's turn-back does), so the route depends on the lane's whole history."""
    rng = np.random.default_rng(3)
    n = 240
    state = {"x": jnp.asarray(rng.integers(0, 7, n), jnp.int32), "k": jnp.zeros(n, jnp.int32),
             "reset": jnp.zeros(n, bool), "f": jnp.asarray(rng.normal(size=(n, 2)), jnp.float32),
             "n": jnp.asarray(rng.integers(0, 12, n), jnp.int32)}

    def route(c):  # pool by the parity of x; -1 when done
        return jnp.where(c["k"] < c["n"], c["x"] % 2, -1).astype(jnp.int32)

    def reset(c):  # once per lane, when x passes 9: back to 0
        hit = (c["x"] > 9) & ~c["reset"]
        return {**c, "x": jnp.where(hit, 0, c["x"]), "reset": c["reset"] | hit}

    steps = (lambda c: reset({**c, "x": c["x"] + 1, "k": c["k"] + 1, "f": c["f"] * 2}),
             lambda c: reset({**c, "x": c["x"] + 3, "k": c["k"] + 1, "f": c["f"] - 1}))

    def alone(c):
        return jax.lax.while_loop(lambda c: route(c) >= 0, lambda c: jax.lax.switch(route(c), steps, c), c)

    want = jax.vmap(alone)(state)
    got = jax.jit(lambda s: run_pools(steps, route, s, 16))(state)
    assert np.any(np.asarray(want["reset"])) and not np.all(np.asarray(want["reset"]))
    for key in state:
        np.testing.assert_array_equal(np.asarray(got[key]), np.asarray(want[key]), err_msg=key)


def test_run_blocks_pads_the_last_block_and_cuts_it_back():
    seen = []

    def fn(a, b):
        seen.append((a.shape, b.shape, np.asarray(a)[-1], np.asarray(b)[-1]))
        return {"s": a + b[:, 0]}

    a, b = np.arange(10.0), np.ones((10, 2))
    out = run_blocks(fn, (a, b), (np.float64(-7), np.zeros(2)), size=4)
    np.testing.assert_array_equal(out["s"], a + 1)
    assert [s[:2] for s in seen] == [((4,), (4, 2))] * 3
    assert seen[-1][2] == -7.0 and np.all(seen[-1][3] == 0)  # the padding rows


@pytest.mark.parametrize("method", ["walk", "newton", "newton-one-step"])
def test_a_new_lane_count_compiles_nothing(method, monkeypatch):
    """Lanes run in fixed-size blocks (256 here, `CAUSTICS_JAX_BLOCK_LANES`), so a second
    call with another lane count (1 block, then 3) traces and compiles nothing: no jit
    cache miss, no XLA compile, no program loaded from the persistent cache."""
    monkeypatch.setenv("CAUSTICS_JAX_BLOCK_LANES", "256")
    mesh, P, L = _pool("float32")
    events = []

    def on_duration(event, *_, **__):
        if event.startswith("/jax/core/compile/"):
            events.append(event)

    def on_event(event, **_):
        if event == "/jax/compilation_cache/cache_hits":
            events.append(event)

    jax.monitoring.register_event_duration_secs_listener(on_duration)
    jax.monitoring.register_event_listener(on_event)
    try:
        solve(mesh, P[:200], L[:200], method=SOLVERS[method]())
        assert events, "the first call compiles (nothing was counted: is the listener wired?)"
        events.clear()
        sol = solve(mesh, P[:700], L[:700], method=SOLVERS[method]())
        assert events == []
    finally:
        jax.monitoring.unregister_event_duration_listener(on_duration)
        jax.monitoring.unregister_event_listener(on_event)
    assert np.asarray(sol.found).shape == (700,) and np.asarray(sol.found).mean() > 0.99


@pytest.mark.parametrize("value, expected", [("0", None), ("off", None), ("False", None),
                                             ("/tmp/cj-cache", "/tmp/cj-cache"), ("1", "default"), (None, "default")])
def test_compilation_cache_directory_from_the_environment(value, expected, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    if value is None:
        monkeypatch.delenv(compilation.ENV, raising=False)
    else:
        monkeypatch.setenv(compilation.ENV, value)
    got = compilation.cache_dir()
    if expected == "default":
        assert got == tmp_path / "caustics_jax" / "jax"
    else:
        assert (None if got is None else str(got)) == expected


@pytest.mark.parametrize("value, project", [(None, True), ("", True), ("project", True), ("1", True),
                                            ("default", False), ("Off", False), ("0", False)])
def test_xla_options_from_the_environment(value, project):
    got = compilation.options_from_env(value)
    assert got == (compilation.XLA_OPTIONS if project else {})
    assert got is not compilation.XLA_OPTIONS  # a copy: nothing can edit the defaults through it


def test_a_misspelt_xla_options_setting_is_refused():
    with pytest.raises(ValueError, match="CAUSTICS_JAX_XLA_OPTIONS"):
        compilation.options_from_env("defualt")
    with pytest.raises(ValueError, match="dict"):
        with compilation.using_xla_options("default"):
            pass


def test_xla_options_are_passed_to_cpu_programs_only():
    with compilation.using_xla_options(compilation.XLA_OPTIONS):
        assert compilation.jit_kwargs("cpu") == {"compiler_options": compilation.XLA_OPTIONS}
        assert compilation.jit_kwargs("gpu") == {} and compilation.jit_kwargs("tpu") == {}
    with compilation.using_xla_options({}):
        assert compilation.jit_kwargs("cpu") == {}


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="the options are XLA:CPU's")
def test_the_project_xla_options_reach_every_block_program():
    """The block programs (`blocks.on_devices`) compile with `compilation.xla_options()`: an
    option XLA does not know fails their compile, so the options are passed; the project's
    own options are accepted by the installed XLA and give the results of XLA's defaults;
    leaving `using_xla_options` restores the options in force."""
    from caustics_jax.runtime.blocks import on_devices

    def block(scale, x, static):
        return jnp.sin(x) * scale + static

    x = jnp.linspace(0.0, 1.0, 8 * len(jax.local_devices()))
    before = compilation.xla_options()
    outs = {}
    for name, options in (("project", compilation.XLA_OPTIONS), ("xla", {})):
        with compilation.using_xla_options(options):
            assert compilation.xla_options() == options
            outs[name] = np.asarray(on_devices(block, 0.5, (jnp.float32(2.0),), (x,)))
    np.testing.assert_allclose(outs["project"], outs["xla"], rtol=4 * np.finfo(np.float32).eps)
    with compilation.using_xla_options({"xla_no_such_option_here": True}):
        with pytest.raises(Exception, match="xla_no_such_option_here"):
            on_devices(block, 0.25, (jnp.float32(2.0),), (x,))
    assert compilation.xla_options() == before


@pytest.mark.skipif(compilation.memory_maps() is None, reason="/proc/self/maps: Linux only")
def test_release_compiled_programs_gives_back_the_memory_mappings():
    """Each compiled program holds memory mappings until JAX drops it (the cause of the
    worker crashes of 2026-11-30, docs/solvers.md "Compilation"): 200 programs hold
    hundreds; released, the count falls back."""
    before = compilation.memory_maps()[0]
    for i in range(200):
        jax.jit(lambda x, i=i: jnp.sin(x) * i)(jnp.ones(i + 1)).block_until_ready()
    held = compilation.memory_maps()[0]
    assert held - before > 200, (before, held)
    assert not compilation.release_compiled_programs(1.0)  # below the whole limit: nothing
    assert compilation.release_compiled_programs(1e-9)
    assert compilation.memory_maps()[0] < held - 200
    for bad in (0, -0.5, 1.5, True, "half"):
        with pytest.raises(ValueError, match="fraction"):
            compilation.release_compiled_programs(bad)


def test_assert_same_lanes_tolerates_rounding_only():
    """The schedule comparison's check: statuses exact, float fields to 64 epsilons of the
    lane's magnitude; anything more is a failure."""
    from types import SimpleNamespace

    point = np.array([[940.0, 0.5, -1.0], [0.25, 0.5, 0.125]])
    eps = np.finfo(point.dtype).eps
    a = SimpleNamespace(status=np.array([0, 1]), point=point)
    near = SimpleNamespace(status=np.array([0, 1]), point=point + [[0.0, 900 * 10 * eps, 0.0], [0.0, 0.0, 10 * eps]])
    assert_same_lanes(a, near, ("status", "point"))
    both_nan = SimpleNamespace(status=a.status, point=point + [[np.nan, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert_same_lanes(both_nan, both_nan, ("status", "point"))
    empty = SimpleNamespace(status=np.zeros(0), point=np.zeros((0, 3)))
    assert_same_lanes(empty, empty, ("status", "point"))
    for far in (SimpleNamespace(status=np.array([0, 2]), point=point),
                SimpleNamespace(status=a.status, point=point + [[0.0, 0.0, 0.0], [100 * eps, 0.0, 0.0]]),
                SimpleNamespace(status=a.status, point=point + [[1e-9, 0.0, 0.0], [0.0, 0.0, 0.0]]),
                SimpleNamespace(status=a.status, point=point + [[np.nan, 0.0, 0.0], [0.0, 0.0, 0.0]]),
                SimpleNamespace(status=a.status, point=point + [[np.inf, 0.0, 0.0], [0.0, 0.0, 0.0]])):
        with pytest.raises(AssertionError):
            assert_same_lanes(a, far, ("status", "point"))


def test_a_lane_solver_without_its_steps_cannot_be_built():
    """`LaneSolver`'s `stages`, `route`, `step` and `finish` are abstract."""
    class NoSteps(LaneSolver):
        phases: ClassVar[tuple[str, ...]] = ("only",)

        def stages(self):
            return ()

    with pytest.raises(TypeError):
        NoSteps()
