"""Process-wide JAX settings for the command line: the persistent compilation cache; and the
compiler options of the programs that run once (``compile_with``).

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
    programs of a continuous-time run (before, it compiled everything again each time). A
    failed check is then a non-finite value, which the training driver reports. Equinox reads
    the variable once, when first imported: the command line calls this before any import of
    JAX; a process that imported Equinox earlier keeps its own setting."""
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
    if not _LISTENING:
        monitoring.register_event_listener(_on_event)
        _LISTENING = True
    return path


def _on_event(event: str, **kwargs) -> None:
    name = _NAMES.get(event)
    if name:
        _EVENTS[name] += 1


def cache_events() -> dict[str, int]:
    """Counts of persistent-cache hits, misses and requests since the cache was enabled."""
    return dict(_EVENTS)


FAST_COMPILE = {"xla_backend_optimization_level": 1, "xla_cpu_use_fusion_emitters": False}
"""XLA's options that compile a CPU program faster: optimisation level 1 instead of 3, and the
older CPU emitters instead of the fusion emitters (which compile every fusion as its own LLVM
module). For programs that run once per run (a run's start, the reference solve a report
quotes, the throw a figure draws), where compiling is most of their cost. Each caller names
those that keep its results: the defaults' bits for a run's start, float rounding where a
result is only reported or drawn (each caller says what it measured)."""


def compile_with(lowered: Any, *names: str) -> Any:
    """``lowered.compile`` with the ``FAST_COMPILE`` options in ``names``.

    An option that ``XLA_FLAGS`` names is left to it (the test suite chooses its own), a CPU
    option is left out where the default backend is not a CPU, and a jaxlib that does not know
    an option compiles with XLA's defaults.
    """
    import jax

    flags = os.environ.get("XLA_FLAGS", "")
    cpu = jax.default_backend() == "cpu"
    options = {
        name: FAST_COMPILE[name]
        for name in names
        if name not in flags and (cpu or not name.startswith("xla_cpu_"))
    }
    try:
        return lowered.compile(options or None)
    except jax.errors.JaxRuntimeError as e:
        if "No such compile option" not in str(e):
            raise
        return lowered.compile()


_BUILT: dict[tuple, Any] = {}


def built_once(make: Any, key: Any, statics: tuple) -> Any:
    """``make(key)``, a network's random weights from a concrete PRNG key, as one compiled
    program kept for the process by its text and ``statics`` (the arguments beside the key
    that fix the result's structure: sizes, initialisation).

    Drawn op by op, they take one program per layer's weight and bias, about 0.13 s of
    compiling each on one core and shape; as one program compiled with ``FAST_COMPILE``'s
    options, about 0.3 s in all, with the same bits (``tests/test_startup.py``),
    and the next network of the same shape (another seed, another round, a loaded file)
    compiles nothing.
    """
    import hashlib

    import equinox as eqx

    lowered = eqx.filter_jit(make).lower(key)
    cache_key = (hashlib.sha256(lowered.as_text().encode()).hexdigest(), statics)
    if cache_key not in _BUILT:
        _BUILT[cache_key] = compile_with(lowered, *FAST_COMPILE)
    return _BUILT[cache_key](key)
