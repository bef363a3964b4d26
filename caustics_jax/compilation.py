"""JAX's persistent compilation cache, on by default (DESIGN.md "Performance methodology").

A solver program takes seconds to compile (docs/solvers.md "Throughput"); the cache keeps
compiled programs on disk between processes, so a second `caustics-jax compare`, test run
or notebook reuses them. `enable_compilation_cache()` runs at the first `solve` (not at
import: importing the package changes no JAX setting) and sets
`jax_compilation_cache_dir` unless the user has already set one:

- default directory `$XDG_CACHE_HOME/caustics_jax/jax` (`~/.cache/caustics_jax/jax`);
- `CAUSTICS_JAX_COMPILATION_CACHE=0` (or `off`, `false`, `no`) leaves the cache off;
- `CAUSTICS_JAX_COMPILATION_CACHE=/some/dir` puts it there.

JAX caches only programs that took at least `jax_persistent_cache_min_compile_time_secs`
(1 s by default) to compile, i.e. the solvers, not the small eager kernels. The cache is
bounded (`MAX_BYTES`, least recently used entries evicted) unless the user set
`jax_compilation_cache_max_size`; a bound also makes JAX lock the directory (`filelock`)
around every read and write. Unbounded, JAX writes entries without a lock, so a process
could read a program another one is still writing (two test workers, two runs started
together). The cache is trusted code: keep it in a directory only you can write (JAX's warning for
`jax.config.update("jax_compilation_cache_dir", ...)`).

In memory, every compiled program holds about three memory mappings of the process on
XLA:CPU until JAX drops it; past Linux's `vm.max_map_count` (65,530 by default) XLA dies
by SIGSEGV or SIGABRT. A process that compiles tens of thousands of programs (the test
suite's workers; a long notebook sweeping shapes) calls `release_compiled_programs()`
between units of work (docs/solvers.md "Compilation").
"""

from __future__ import annotations

import gc
import os
from pathlib import Path

import jax

#: Environment variable: "0"/"off"/"false"/"no" disables the cache, a path relocates it.
ENV = "CAUSTICS_JAX_COMPILATION_CACHE"
#: Bound of the cache directory (bytes): a few hundred solver programs.
MAX_BYTES = 4 << 30
_OFF = ("0", "off", "false", "no")
_done = False


def cache_dir() -> Path | None:
    """Where the cache goes (None: off), from `CAUSTICS_JAX_COMPILATION_CACHE` (module docstring)."""
    value = os.environ.get(ENV, "").strip()
    if value.lower() in _OFF:
        return None
    if value and value.lower() not in ("1", "on", "true", "yes"):
        return Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "caustics_jax" / "jax"


def enable_compilation_cache() -> Path | None:
    """Point JAX's persistent compilation cache at `cache_dir()` once per process, unless a
    directory is already configured (then that one is kept) or the cache is turned off.
    Returns the directory in use (None when off). An unwritable directory leaves it off."""
    global _done
    current = jax.config.jax_compilation_cache_dir
    if _done or current:
        return Path(current) if current else None
    _done = True
    path = cache_dir()
    if path is None:
        return None
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    if jax.config.jax_compilation_cache_max_size == -1:  # JAX's default: unbounded, unlocked
        jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)
    jax.config.update("jax_compilation_cache_dir", str(path))
    return path


#: Linux's default `vm.max_map_count`, assumed where /proc/sys/vm cannot be read.
DEFAULT_MAX_MAP_COUNT = 65530


def memory_maps() -> tuple[int, int] | None:
    """(memory mappings of this process, the kernel's limit `vm.max_map_count`), or None
    where /proc does not list them (not Linux)."""
    try:
        with open("/proc/self/maps", "rb") as maps:
            count = sum(1 for _ in maps)
    except OSError:
        return None
    try:
        with open("/proc/sys/vm/max_map_count") as limit:
            return count, int(limit.read())
    except (OSError, ValueError):
        return count, DEFAULT_MAX_MAP_COUNT


def release_compiled_programs(fraction: float = 0.5) -> bool:
    """Drop JAX's in-memory compiled programs (`jax.clear_caches()`) when this process holds
    more than `fraction` of the memory mappings Linux allows (module docstring); later calls
    compile again, or load from the persistent cache. Returns whether it released."""
    if isinstance(fraction, bool) or not isinstance(fraction, int | float) or not 0 < fraction <= 1:
        raise ValueError(f"fraction must be a real number in (0, 1], got {fraction!r}")
    maps = memory_maps()
    if maps is None or maps[0] <= fraction * maps[1]:
        return False
    jax.clear_caches()
    gc.collect()
    return True
