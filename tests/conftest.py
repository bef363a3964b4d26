"""Test configuration: float64 is switched on here, by the caller, as the package requires.

Every float32 test builds float32 arrays explicitly; kernels must keep them float32.
"""

import os

import jax
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)

# No persistent compilation cache in the tests (unless the caller sets
# CAUSTICS_JAX_COMPILATION_CACHE): on 2026-11-30 three `make test` runs each lost one xdist
# worker to a segfault inside JAX's executable serialisation (`executable.serialize()` in
# `compilation_cache.put_executable_and_time`, twice) or deserialisation (once), on a walk
# program and on photon-differential programs; not reproduced by a single process writing
# (and reading) the same programs (docs/solvers.md "Compilation"). The tests' own compile
# counts use JAX's in-process cache, which this leaves as it is.
os.environ.setdefault("CAUSTICS_JAX_COMPILATION_CACHE", "0")

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
