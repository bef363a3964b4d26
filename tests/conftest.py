"""Test configuration: float64 is switched on here, by the caller, as the package requires.

Every float32 test builds float32 arrays explicitly; kernels must keep them float32.
"""

import gc
import os

import jax
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)

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


# Every compiled XLA:CPU program holds about three memory mappings of its own (code, data)
# until JAX drops it, and the suite compiles tens of thousands of programs per worker (each
# shape of each jitted kernel, each eager op). Near Linux's `vm.max_map_count` (65530 by
# default) mmap fails inside XLA and the worker dies by SIGSEGV or SIGABRT in whatever it
# compiles, (de)serialises or runs next (docs/solvers.md "Compilation"). After a module
# whose worker holds over half the limit, the compiled programs are released
# (`jax.clear_caches()`; the persistent compilation cache reloads the slow ones).
def _memory_maps() -> tuple[int, int] | None:
    """(mappings of this process, the kernel's limit; 65530, Linux's default, where it cannot
    be read), or None where /proc does not list the mappings (not Linux)."""
    try:
        with open("/proc/self/maps", "rb") as maps:
            count = sum(1 for _ in maps)
    except OSError:
        return None
    try:
        with open("/proc/sys/vm/max_map_count") as limit:
            return count, int(limit.read())
    except (OSError, ValueError):
        return count, 65530


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    yield
    maps = _memory_maps()
    if maps is not None and maps[0] > maps[1] // 2:
        jax.clear_caches()
        gc.collect()
