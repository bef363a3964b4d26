"""Test configuration: float64 is switched on here, by the caller, as the package requires.

Every float32 test builds float32 arrays explicitly; kernels must keep them float32.
"""

import os

import jax
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)

# One persistent compilation cache per test process (xdist's PYTEST_XDIST_WORKER), kept
# between runs: no two test processes share a directory. On 2026-11-30 a worker crashed twice
# (segfault inside JAX's cache read, and once its write) while another process used the same
# directory, although `caustics_jax.compilation` bounds the cache so that JAX locks it; a
# sequential write-then-read of the same programs did not crash (docs/solvers.md).
if "CAUSTICS_JAX_COMPILATION_CACHE" not in os.environ:
    _base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    os.environ["CAUSTICS_JAX_COMPILATION_CACHE"] = os.path.join(
        _base, "caustics_jax", "jax-tests", os.environ.get("PYTEST_XDIST_WORKER", "main"))

# Examples are whole batches (arrays), so few examples cover many cases; derandomised in CI
# so a failure reproduces.
settings.register_profile(
    "ci",
    max_examples=12,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "dev",
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
