"""A pytest plugin for ``suite_time.py``: each test's wall time and what JAX spent on it.

Through JAX's public monitoring events only: tracing (``jaxpr_trace_duration``), lowering
(``jaxpr_to_mlir_module_duration``) and the backend's compile or persistent-cache load
(``backend_compile_duration``, with ``cache_hits`` telling a load from a compile), each with
the program's name; and the setup time of each module- or session-scoped fixture. Each process
(an xdist worker, or pytest itself) writes its records to ``$SUITE_PROBE_DIR/<worker>.json`` at
the end of the session.
"""

from __future__ import annotations

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
"""(test id, kind, program, seconds, loaded from the cache) in the order they happened."""
_state: dict = {"test": None, "hits": 0}


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


def pytest_configure(config):
    import jax.monitoring

    jax.monitoring.register_event_duration_secs_listener(_duration)
    jax.monitoring.register_event_listener(_event)


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
