"""A pytest plugin for ``suite_time.py``: each test's wall time and what JAX spent on it.

JAX's part comes from its public monitoring events only: tracing (``jaxpr_trace_duration``),
lowering (``jaxpr_to_mlir_module_duration``) and the backend's compile or persistent-cache load
(``backend_compile_duration``, with ``cache_hits`` telling a load from a compile), each with
the program's name. Also recorded: the setup time of each module- or session-scoped fixture,
and matplotlib's rendering (``Figure.savefig`` and the Agg canvas's ``draw``). Each process (an
xdist worker, or pytest itself) writes its records to ``$SUITE_PROBE_DIR/<worker>.json`` at the
end of the session.
"""

from __future__ import annotations

import functools
import json
import os
import time
from pathlib import Path

import pytest

EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "compile",
}
_records: list[tuple[str | None, str, str, float, bool]] = []
"""(test id, kind, name, seconds, loaded from the cache) in the order they happened; the name is
the program's, the fixture's or the drawing method's."""
_state: dict = {"test": None, "hits": 0, "drawing": False}


def _duration(event: str, duration: float, **kwargs) -> None:
    kind = EVENTS.get(event)
    if kind is None:
        return
    hit = kind == "compile" and _state["hits"] > 0
    if kind == "compile":
        _state["hits"] = 0
    _records.append((_state["test"], kind, str(kwargs.get("fun_name", "")), duration, hit))


def _event(event: str, **kwargs) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _state["hits"] += 1


def _drawing_timed(cls: type, method: str) -> None:
    """Record the time of ``cls.method`` as drawing, where no drawing is already timed (a
    ``savefig`` draws its canvas)."""
    original = getattr(cls, method)

    @functools.wraps(original)
    def timed(*args, **kwargs):
        if _state["drawing"]:
            return original(*args, **kwargs)
        _state["drawing"] = True
        t0 = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            _state["drawing"] = False
            _records.append((_state["test"], "draw", method, time.perf_counter() - t0, False))

    setattr(cls, method, timed)


def pytest_configure(config):
    import jax.monitoring
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    jax.monitoring.register_event_duration_secs_listener(_duration)
    jax.monitoring.register_event_listener(_event)
    # matplotlib's rendering: the pictures (savefig) and the animations' frames (canvas draws)
    _drawing_timed(Figure, "savefig")
    _drawing_timed(FigureCanvasAgg, "draw")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _state["test"] = item.nodeid
    t0 = time.perf_counter()
    yield
    _records.append((item.nodeid, "wall", "", time.perf_counter() - t0, False))
    _state["test"] = None


@pytest.hookimpl(hookwrapper=True)
def pytest_fixture_setup(fixturedef, request):
    """A shared fixture's setup (module or session scope), which the first test of each
    process that asks for it pays: recorded under the fixture's name."""
    t0 = time.perf_counter()
    yield
    if fixturedef.scope in ("module", "session"):
        name = f"{fixturedef.baseid.split('::')[0] or 'conftest'}::{fixturedef.argname}"
        _records.append((_state["test"], "fixture", name, time.perf_counter() - t0, False))


def pytest_sessionfinish(session):
    out = os.environ.get("SUITE_PROBE_DIR")
    if out:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        (Path(out) / f"{worker}.json").write_text(json.dumps(_records))
