"""JAX's persistent compilation cache (on by default) and the XLA options of the solver programs.

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

The solvers' block programs compile with the project's XLA options (`jit`, `XLA_OPTIONS`:
XLA:CPU's loop emitters, which compile the walk faster than XLA's default fusion emitters,
docs/solvers.md "Compilation"); `CAUSTICS_JAX_XLA_OPTIONS=default` keeps XLA's own options.

In memory, every compiled program holds about three memory mappings of the process on
XLA:CPU until JAX drops it; past Linux's `vm.max_map_count` (65,530 by default) XLA dies
by SIGSEGV or SIGABRT. A process that compiles tens of thousands of programs (the test
suite's workers; a long notebook sweeping shapes) calls `release_compiled_programs()`
between units of work (docs/solvers.md "Compilation").
"""

from __future__ import annotations

import contextlib
import gc
import os
from collections.abc import Iterator
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


# --------------------------------------------------------------------------- XLA options

#: Environment variable: "default" (or "0", "off", "false", "no") compiles the solver
#: programs with XLA's default options instead of `XLA_OPTIONS`; read at import
#: (`options_from_env`).
XLA_ENV = "CAUSTICS_JAX_XLA_OPTIONS"
#: XLA options of the solvers' block programs (`jit`): XLA:CPU's loop emitters instead of
#: its MLIR fusion emitters (`xla_cpu_use_fusion_emitters`, on by default in this JAX):
#: the solver programs compile faster and give the same statuses, with calls about as
#: fast or faster (`experiments/compile_options.py`; docs/solvers.md "Compilation" and
#: "Measurements behind the code"). Only CPU programs take them (`jit_kwargs`).
XLA_OPTIONS: dict = {"xla_cpu_use_fusion_emitters": False}


def options_from_env(value: str | None) -> dict:
    """The option set `CAUSTICS_JAX_XLA_OPTIONS=value` selects: `XLA_OPTIONS` when unset,
    empty or "1"/"on"/"project"; `{}` (XLA's defaults) for "default", "0", "off", "false",
    "no"; anything else is a `ValueError` (a typo must not silently change the programs)."""
    v = (value or "").strip().lower()
    if v in ("", "1", "on", "true", "yes", "project"):
        return dict(XLA_OPTIONS)
    if v in ("default",) + _OFF:
        return {}
    raise ValueError(f"{XLA_ENV} must be 'project' (the default) or 'default' (XLA's own options), got {value!r}")


_xla: dict = options_from_env(os.environ.get(XLA_ENV))


def xla_options() -> dict:
    """The XLA options the solver programs are compiled with now (`jit`): `XLA_OPTIONS`,
    or `{}` (XLA's defaults) when `CAUSTICS_JAX_XLA_OPTIONS=default` or inside
    `using_xla_options`."""
    return dict(_xla)


@contextlib.contextmanager
def using_xla_options(options: dict | None) -> Iterator[None]:
    """Programs built inside use `options` (None or `{}`: XLA's defaults): for comparing
    compile options in one process (`experiments/compile_options.py`). The solvers' block
    programs (`blocks.on_devices`) are built per option set; programs already built keep
    theirs."""
    global _xla
    if options is not None and not isinstance(options, dict):
        raise ValueError(f"options must be a dict of XLA option names to values or None, got {options!r}")
    saved, _xla = _xla, dict(options or {})
    try:
        yield
    finally:
        _xla = saved


def jit_kwargs(platform: str | None = None) -> dict:
    """`jax.jit`'s keyword arguments for the project's XLA options (`xla_options()`) on
    `platform` (default: JAX's default backend): `{"compiler_options": ...}` on the CPU,
    `{}` for XLA's defaults or another platform (the options are XLA:CPU's; a GPU program
    compiles exactly as without them)."""
    if not _xla or (platform or jax.default_backend()) != "cpu":
        return {}
    return {"compiler_options": xla_options()}


def jit(fun, platform: str | None = None, **kwargs):
    """`jax.jit` with the project's XLA options (`jit_kwargs(platform)`, read when `jit`
    runs), for top-level programs only: JAX refuses `compiler_options` on a jitted function
    called inside another trace (a kernel inside a user's `jit`), so the package's kernels
    and decorated functions keep XLA's defaults and only the solvers' block programs
    (`blocks.on_devices`) take these options."""
    return jax.jit(fun, **jit_kwargs(platform), **kwargs)
