"""Where a run's time goes: the process's age, and every XLA compilation counted and timed.

``metrics.json``'s ``timings`` (and the last line of ``diffcontrol train``) split a run into
disjoint parts: ``import`` (from the process's start to the training stack imported),
``compile`` (tracing, lowering and compiling every program, or loading it from the persistent
cache; ``compile_programs`` counts them), ``train``, ``evaluate`` and ``write`` (each without
the compilation inside it), and ``total`` (the process's age when the files are written).
Compilations are seen through ``jax.monitoring``'s time spans, merged where they nest (a
``jit`` traced inside another), so nothing is counted twice. Nothing here imports JAX: the
listener is installed by ``watch_compiles`` once JAX is imported anyway.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator

_TRACE = "/jax/core/compile/jaxpr_trace_duration"
_LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
_BACKEND = "/jax/core/compile/backend_compile_duration"
_EVENTS = (_TRACE, _LOWER, _BACKEND)

_spans: list[tuple[float, float]] = []  # merged, disjoint, in order of their ends
_programs: list[str] = []  # the name of each program compiled (or loaded from the cache)
_watching = False


def process_seconds() -> float | None:
    """Seconds since this process started (Linux's ``/proc``; ``None`` elsewhere)."""
    try:
        with open("/proc/self/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        return max(0.0, uptime - int(fields[19]) / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError, AttributeError):
        return None


def watch_compiles() -> None:
    """Count and time every compilation from now on (idempotent; imports JAX)."""
    global _watching
    if _watching:
        return
    from jax import monitoring

    monitoring.register_event_time_span_listener(_on_span)
    _watching = True


def _on_span(event: str, start: float, end: float, **kwargs) -> None:
    if event not in _EVENTS:
        return
    if event == _BACKEND:
        _programs.append(str(kwargs.get("fun_name", "?")))
    # Merge with the spans it overlaps (a nested trace lies inside its parent's).
    while _spans and _spans[-1][1] >= start:
        s, e = _spans.pop()
        start, end = min(s, start), max(e, end)
    _spans.append((start, end))


def compile_seconds() -> float:
    """Seconds spent compiling (tracing, lowering, XLA or the persistent cache) so far."""
    return sum(e - s for s, e in _spans)


def compiled_programs() -> int:
    """How many programs were compiled (or loaded from the persistent cache) so far."""
    return len(_programs)


def program_names() -> list[str]:
    """The names of the programs compiled so far, in order (``jit(chunk)``, ...)."""
    return list(_programs)


@contextlib.contextmanager
def phase(timings: dict[str, float], name: str) -> Iterator[None]:
    """Add the wall time of the block, less its compilation, to ``timings[name]``, and its
    compilation to ``timings["compile"]`` and ``timings["compile_programs"]``."""
    t0, c0, n0 = time.perf_counter(), compile_seconds(), compiled_programs()
    try:
        yield
    finally:
        compiled = compile_seconds() - c0
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0 - compiled
        timings["compile"] = timings.get("compile", 0.0) + compiled
        timings["compile_programs"] = timings.get("compile_programs", 0) + (
            compiled_programs() - n0
        )


def describe(timings: dict[str, float]) -> str:
    """``timings`` in a few words for the last line of ``diffcontrol train``."""
    parts = [
        f"{name} {timings[name]:.1f}"
        + (f" ({timings['compile_programs']} programs)" if name == "compile" else "")
        for name in ("import", "compile", "train", "evaluate", "write")
        if name in timings
    ]
    total = timings.get("total")
    head = f"{total:.1f} s in all" if total is not None else "time"
    return f"{head}: " + ", ".join(parts) + " s"
