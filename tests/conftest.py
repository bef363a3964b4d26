"""Test configuration: float64 is switched on here, by the caller, as the package requires.

Every float32 test builds float32 arrays explicitly; kernels must keep them float32.
"""

import os

import jax
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)
# The suite's two workers share the persistent compilation cache (the package points JAX at
# it at the first solve): programs that compile in a quarter second (start points per
# mesh, the kernels' shapes) are kept too, so the other worker, and this one after
# `release_compiled_programs`, load them instead of compiling them again.
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.25)

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


# Every compiled XLA:CPU program holds about three memory mappings until JAX drops it, and
# the suite compiles tens of thousands of programs per worker (each shape of each jitted
# kernel, each eager op). Near Linux's `vm.max_map_count` (65530 by default) mmap fails
# inside XLA and the worker dies by SIGSEGV or SIGABRT in whatever it compiles,
# (de)serialises or runs next (docs/solvers.md "Compilation"). After a module that leaves
# its worker above half the limit, the compiled programs are released.
@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    yield
    from caustics_jax.runtime.compilation import release_compiled_programs  # (after x64 is on, above)

    release_compiled_programs(0.5)
