"""Process-wide JAX settings for the command line: the persistent compilation cache; and the
compiler options of the programs that run once (``compile_with``, ``FastJit``).

A second run of the same command loads its compiled programs from the cache instead of
compiling them again. JAX stores no program that contains a host callback, and Equinox's
runtime checks (``eqx.error_if``) insert one unless ``EQX_ON_ERROR`` says otherwise, so the
training programs of diffcontrol contain no such checks: non-finite values are detected by
the Python driver between chunks instead. ``cache_events()`` counts hits and misses so that
``metrics.json`` (and a test) can show that the cache really hits.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

_EVENTS = {"hits": 0, "misses": 0, "requests": 0}
_LISTENING = False

_NAMES = {
    "/jax/compilation_cache/cache_hits": "hits",
    "/jax/compilation_cache/cache_misses": "misses",
    "/jax/compilation_cache/compile_requests_use_cache": "requests",
}


def default_cache_dir() -> Path:
    """``$DIFFCONTROL_CACHE_DIR``, else ``$XDG_CACHE_HOME/diffcontrol/jax``, else ``~/.cache/...``."""
    if os.environ.get("DIFFCONTROL_CACHE_DIR"):
        return Path(os.environ["DIFFCONTROL_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "diffcontrol" / "jax"


def checks_as_nan() -> None:
    """``EQX_ON_ERROR=nan`` unless it is set: Equinox's runtime checks (Diffrax's, inside every
    ODE solve) become NaN instead of host callbacks, so that the persistent cache can store the
    programs of a continuous-time run. A failed check is then a non-finite value, which the
    training driver reports. Equinox reads the variable once, when first imported: the
    command line calls this before any import of JAX; a process that imported Equinox earlier
    keeps its own setting."""
    os.environ.setdefault("EQX_ON_ERROR", "nan")


def enable_compile_cache(cache_dir: str | Path | None = None) -> Path | None:
    """Turn on JAX's persistent compilation cache in ``cache_dir`` (default above).

    Returns the directory, or ``None`` if it could not be created (the run goes on uncached).
    """
    import jax
    from jax import monitoring

    global _LISTENING
    path = Path(cache_dir) if cache_dir else default_cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    # Cache every program, however quick to compile: short runs are where it matters.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _entries_carry_their_keys(path)
    if not _LISTENING:
        monitoring.register_event_listener(_on_event)
        _LISTENING = True
    return path


def _entries_carry_their_keys(path: Path) -> None:
    """Make every entry of the cache at ``path`` carry its own key, and load only those whose
    key is the program's.

    JAX finds an entry by its file's name alone. An entry that deserialises but is another
    program's (files swapped, copied or restored under other names) would be run as this one,
    and fail inside JAX with the other program's arguments. Here each entry starts with its
    key; one without it, or with another, counts as a miss: the program is compiled and the
    entry written again. JAX offers no hook for this, so the wrapper replaces the file cache
    of its private ``compilation_cache`` module (as it is from JAX 0.8 to 0.10, the releases the
    pins allow); where that module differs, the cache stays JAX's own.
    """
    try:
        from jax._src import compilation_cache as cc

        if not cc._is_cache_enabled():  # JAX_ENABLE_COMPILATION_CACHE=false: none at all
            return
        base, _ = cc.get_file_cache(str(path))
        with cc._cache_initialized_mutex:
            cc._cache = _KeyedEntries(base)
            cc._cache_initialized = True
    except (ImportError, AttributeError, TypeError):
        return


class _KeyedEntries:
    """A JAX cache (``get``, ``put``) whose entries start with their key and a newline."""

    def __init__(self, base: Any):
        self._base = base
        self._path = getattr(base, "_path", None)

    def get(self, key: str) -> bytes | None:
        value = self._base.get(key)
        tag = key.encode() + b"\n"
        if value is None or not value.startswith(tag):
            return None
        return value[len(tag) :]

    def put(self, key: str, value: bytes) -> None:
        self._base.put(key, key.encode() + b"\n" + value)

    def clear(self) -> None:
        self._base.clear()


def _on_event(event: str, **kwargs) -> None:
    name = _NAMES.get(event)
    if name:
        _EVENTS[name] += 1


def cache_events() -> dict[str, int]:
    """Counts of persistent-cache hits, misses and requests since the cache was enabled."""
    return dict(_EVENTS)


GC_THRESHOLDS = (10_000, 10, 10)
"""The garbage collector's thresholds in the console script (``cli.run``): a collection of the
youngest objects every 10,000 net allocations instead of Python's 700 (3.11, 3.12; 2,000 in
3.13), the older generations' ratios Python's own. Tracing a JAX program makes hundreds of
thousands of objects, and at Python's thresholds the collector runs hundreds of times while
a program is traced, the full collections among them walking everything JAX has made; here
it runs a twentieth as often, and a full collection still comes every million or so net
allocations, so a long command's cyclic garbage is freed as it runs (measured by
``benchmarks/gc_tracing.py``: ``benchmarks/results/gc_tracing*.json``). Not set by the library
itself: a Python caller's collector is its own."""


FAST_COMPILE = {"xla_backend_optimization_level": 1, "xla_cpu_use_fusion_emitters": False}
"""XLA's options that compile a CPU program faster: optimisation level 1 instead of 3, and the
older CPU emitters instead of the fusion emitters (which compile every fusion as its own LLVM
module). For programs that run once per run (a run's start, the reference solve a report
quotes, the throw a figure draws), where compiling is most of their cost. Each caller names
those that keep its results: the defaults' bits for a run's start, float rounding where a
result is only reported or drawn (each caller says which)."""


ONE_CORE = {"xla_cpu_parallel_codegen_split_count": 1}
"""For a program compiled with the older CPU emitters by a process that may run on one core
only: XLA splits a CPU program into modules that LLVM compiles in parallel, which on one core
only adds work. Without the split the programs keep their bits (the trebuchet's evaluation,
declared with other bits anyway, rounds its throws differently by about 1e-7). On two cores
the split pays, and programs with the fusion emitters gain nothing from dropping it, so it is
left there. ``fast_options`` adds it."""


def _one_core() -> bool:
    """Whether this process may run on one CPU core only (``taskset -c 0``, a 1-CPU machine)."""
    try:
        return len(os.sched_getaffinity(0)) == 1
    except AttributeError:  # no affinity on this platform
        return os.cpu_count() == 1


def fast_options(*names: str) -> dict[str, Any] | None:
    """The ``FAST_COMPILE`` options in ``names``, less those that ``XLA_FLAGS`` names (the test
    suite chooses its own) and, where the default backend is not a CPU, the CPU options; with
    the older emitters on one core, ``ONE_CORE`` too."""
    import jax

    flags = os.environ.get("XLA_FLAGS", "")
    cpu = jax.default_backend() == "cpu"
    options = {
        name: FAST_COMPILE[name]
        for name in names
        if name not in flags and (cpu or not name.startswith("xla_cpu_"))
    }
    if options.get("xla_cpu_use_fusion_emitters") is False and _one_core():
        options.update({k: v for k, v in ONE_CORE.items() if k not in flags})
    return options or None


def _unknown_option(error: Exception) -> bool:
    return "No such compile option" in str(error)


def compile_with(lowered: Any, *names: str) -> Any:
    """``lowered.compile`` with ``fast_options(*names)``; a jaxlib that does not know an option
    compiles with XLA's defaults."""
    import jax

    try:
        return lowered.compile(fast_options(*names))
    except jax.errors.JaxRuntimeError as e:
        if not _unknown_option(e):
            raise
        return lowered.compile()


class FastJit:
    """``jax.jit(fn, **jit_kwargs)`` whose programs compile with ``fast_options(*names)``: for a
    function called once or a few times per run with the same shapes. JAX's own cache keeps
    each program (by shapes, static arguments and device); the options are chosen at the first
    call, not at import; a jaxlib that does not know one falls back to XLA's defaults."""

    def __init__(self, fn: Any, *names: str, **jit_kwargs: Any):
        self.fn, self.names, self.jit_kwargs = fn, names, jit_kwargs
        self.jitted: Any = None

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        import jax

        if self.jitted is None:
            options = fast_options(*self.names)
            self.jitted = jax.jit(self.fn, compiler_options=options, **self.jit_kwargs)
        try:
            return self.jitted(*args, **kwargs)
        except jax.errors.JaxRuntimeError as e:
            if not _unknown_option(e):
                raise
            self.jitted = jax.jit(self.fn, **self.jit_kwargs)
            return self.jitted(*args, **kwargs)


RUNNING = {"xla_cpu_use_fusion_emitters": True}
"""XLA's options for a program whose running, not its compiling, is its cost (a grid dynamic
program's sweeps over every grid point and action): the fusion emitters, XLA's own CPU default,
named so that they hold under an ``XLA_FLAGS`` that turns them off (the test session's, where
the older emitters run such a program at half the speed). Under XLA's defaults the program and
its bits are the defaults'."""


class RunningJit:
    """``eqx.filter_jit(fn)`` whose programs compile with ``RUNNING`` on a CPU (chosen at the
    first call, not at import); a jaxlib that does not know an option compiles with XLA's
    defaults."""

    def __init__(self, fn: Any):
        self.fn, self.jitted = fn, None

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        import equinox as eqx
        import jax

        if self.jitted is None:
            options = RUNNING if jax.default_backend() == "cpu" else {}
            self.jitted = eqx.filter_jit(self.fn, compiler_options=options)
        try:
            return self.jitted(*args, **kwargs)
        except jax.errors.JaxRuntimeError as e:
            if not _unknown_option(e):
                raise
            self.jitted = eqx.filter_jit(self.fn)
            return self.jitted(*args, **kwargs)


_STALE_AFTER_X64 = False


def traced_in_float64() -> None:
    """Say that a program traced under ``float64()`` read float64 NumPy constants through
    ``jax.numpy`` functions that JAX compiles once (MJX's integrator tables through
    ``jnp.tril``). JAX's staging caches keep those constants' float64 types, and a later trace
    of the same code in float32 then fails to lower ("operand type mismatch ... f64");
    ``float64()`` clears the caches when it ends."""
    global _STALE_AFTER_X64
    _STALE_AFTER_X64 = True


class float64:  # noqa: N801 (used as a context manager, like jax.enable_x64)
    """``jax.enable_x64(True)``, after which JAX's caches are cleared if anything traced inside
    called ``traced_in_float64`` (the compiled programs that diffcontrol keeps itself stay;
    only JAX's own are traced and compiled again): the model fits and the reference checks
    run in float64, the training after them in float32."""

    def __enter__(self) -> None:
        import jax

        self._x64 = jax.enable_x64(True)
        self._x64.__enter__()

    def __exit__(self, *exc: Any) -> None:
        import jax

        global _STALE_AFTER_X64
        self._x64.__exit__(*exc)
        if _STALE_AFTER_X64 and not jax.config.jax_enable_x64:
            _STALE_AFTER_X64 = False
            jax.clear_caches()
