"""Lanes spread over every local device: two host devices give the per-lane results of one.

The two-device run happens in a subprocess (`blocks.use_cpu_devices(2)`, what
`caustics-jax compare --cpu-devices` calls, must run before JAX starts); it writes its
results to an .npz that this process compares, array for array, with the same solves on
its single device. The subprocess uses blocks of 256 lanes per device
(`CAUSTICS_JAX_BLOCK_LANES`), so its 600 lanes span two blocks of 512 (each split in two
device shares) while this process runs them in one block of the default size: per-lane
results depend neither on the device count nor on the blocking.
"""

import os
import subprocess
import sys
import textwrap
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

import caustics_jax as cj

ROOT = Path(__file__).resolve().parents[1]
N_LANES = 600
RUNS = {  # name -> (method options, irradiance?)
    "walk": ({"method": "walk"}, False),
    "newton": ({"method": "newton"}, False),  # optimistix: one program per device (blocks.on_devices)
    "newton_one_step": ({"method": "newton", "stepping": "one_step"}, False),
    "irradiance": ({"method": "walk"}, True),
}
# (name, dtype) pairs run on two devices: the walk in both dtypes, each other path in one
# (each pair compiles its own two-device program in the subprocess: minutes on 2 cores).
PAIRS = [("walk", "float32"), ("walk", "float64"), ("newton", "float32"), ("newton_one_step", "float64"),
         ("irradiance", "float32")]

SCRIPT = textwrap.dedent("""
    import sys
    import jax
    import numpy as np
    import caustics_jax as cj
    from caustics_jax.runtime.blocks import lanes_per_block, use_cpu_devices
    assert use_cpu_devices(2) == 2
    sys.path.insert(0, {tests!r})
    from test_devices import PAIRS, scene, run
    assert len(jax.local_devices()) == 2, jax.local_devices()
    assert lanes_per_block() == 512
    out = {{}}
    for name, dtype in PAIRS:
        mesh, P, L = scene(dtype)
        for key, value in run(name, mesh, P, L).items():
            out[f"{{dtype}}/{{name}}/{{key}}"] = value
    np.savez(sys.argv[1], **out)
""")


def scene(dtype):
    """600 receivers under a point light on a 2048-triangle wavy pool."""
    sc = cj.scenes.wavy_pool(2048, amplitude=0.06, n_receivers=25, dtype=dtype)
    P = np.asarray(sc.receivers)[:N_LANES]
    return sc.surface, P, np.asarray(sc.lights.endpoint(P))


def run(name, mesh, P, L) -> dict:
    options, irradiance = RUNS[name]
    with cj.precision(mesh.dtype):
        if irradiance:
            E, sol = cj.irradiance(mesh, P, L, intensity=1.0, receiver_normal=[0, 0, 1], return_solution=True,
                                   **options)
            return {"E": np.asarray(E), "status": np.asarray(sol.status)}
        sol = cj.solve(mesh, P, L, **options)
    return {k: np.asarray(getattr(sol, k)) for k in ("status", "point", "barycentric", "iterations", "crossed")}


@pytest.fixture(scope="module")
def two_devices(tmp_path_factory):
    out = tmp_path_factory.mktemp("devices") / "two.npz"
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "CAUSTICS_JAX_BLOCK_LANES": "256", "JAX_ENABLE_X64": "1"}
    env.pop("XLA_FLAGS", None)
    script = SCRIPT.format(tests=str(ROOT / "tests"))
    proc = subprocess.run([sys.executable, "-c", script, str(out)], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=1500)
    assert proc.returncode == 0, proc.stderr[-4000:]
    return dict(np.load(out))


@pytest.mark.parametrize("name, dtype", PAIRS)
def test_two_host_devices_give_the_lanes_of_one(two_devices, name, dtype):
    mesh, P, L = scene(dtype)
    one = run(name, mesh, P, L)
    assert (one["status"] == cj.Status.FOUND).mean() > 0.95
    for key, value in one.items():
        np.testing.assert_array_equal(two_devices[f"{dtype}/{name}/{key}"], value, err_msg=f"{name} {key}")


def test_use_cpu_devices_refuses_bad_counts_and_a_started_backend():
    import jax

    from caustics_jax.runtime.blocks import use_cpu_devices

    have = len(jax.devices("cpu"))  # this process's backend is running
    assert use_cpu_devices(have) == have  # the count it already has: accepted
    with pytest.raises(ValueError, match="already started with"):
        use_cpu_devices(have + 1)
    for bad in (0, -2, "two", True, 1.5, None, 10**6):  # (1000 had padded a 100k comparison to 32M lanes)
        with pytest.raises(ValueError, match="positive integer or 'all'"):
            use_cpu_devices(bad)
    if have != 8:  # "all" on a 64-core machine asks for MAX_AUTO_CPU_DEVICES = 8
        with mock.patch("os.cpu_count", return_value=64), pytest.raises(ValueError, match="8 CPU devices"):
            use_cpu_devices("all")
