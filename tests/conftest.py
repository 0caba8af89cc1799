"""Shared test setup: a private compilation cache, and small trained runs shared by tests."""

from __future__ import annotations

import os
import shutil
import tempfile

# A private persistent compilation cache for the whole test session, set before any
# diffcontrol import reads it; the user's own cache is never touched by the tests.
# The process that makes it (pytest's, or xdist's controller, whose workers inherit it)
# removes it at the end.
_OWN_CACHE = None
if "DIFFCONTROL_CACHE_DIR" not in os.environ:
    _OWN_CACHE = tempfile.mkdtemp(prefix="diffcontrol-test-cache-")
    os.environ["DIFFCONTROL_CACHE_DIR"] = _OWN_CACHE
# XLA's CPU compiler, for the tests' programs, which are small and most run a few steps: its
# older fusion emitters at backend optimisation level 1 compile them fastest
# (docs/development.md has the paired timings). They compute what XLA's defaults compute up to rounding, which
# the tests' tolerances are for (tests/test_compile_flags.py checks it); not at level 0, where
# a swing-up population's gradients became NaN. The library's own programs keep XLA's
# defaults; the tests that compare the bits of two compilations name their options
# (tests/test_startup.py), and the bit-for-bit comparisons with Gymnasium run under these
# flags. A level or emitter already in XLA_FLAGS is left as it is; where this jaxlib does not
# know a flag (an unknown flag aborts the process), fewer of them (below).
# One LLVM module per program, not XLA's 32 parts compiled on a thread pool: two workers on two
# cores gain nothing from the pool, and splitting costs (the same bits: docs/development.md).
_FAST_COMPILE = (
    "--xla_backend_optimization_level=1",
    "--xla_cpu_use_fusion_emitters=false",
    "--xla_cpu_parallel_codegen_split_count=1",
)


def _xla_knows(flags: str) -> bool:
    """Whether a JAX process with ``XLA_FLAGS=flags`` starts (XLA aborts on an unknown flag)."""
    import subprocess
    import sys

    code = "import jax.numpy as jnp; jnp.zeros(1).block_until_ready()"
    env = dict(os.environ, XLA_FLAGS=flags)
    try:
        done = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, timeout=120
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


_given = os.environ.get("XLA_FLAGS", "")
if "xla_backend_optimization_level" not in _given and "xla_cpu_use_fusion_emitters" not in _given:
    # pytest-xdist's workers inherit the flags from the controller, which probes them: all
    # three, else without the split, else level 0 alone (what ran before)
    _tries = (_FAST_COMPILE, _FAST_COMPILE[:2], ("--xla_backend_optimization_level=0",))
    _flags = [" ".join((_given, *t)).strip() for t in _tries]
    os.environ["XLA_FLAGS"] = next((f for f in _flags[:2] if _xla_knows(f)), _flags[2])
# As the command line sets it (``cli.main``): Equinox's checks as NaN, not host callbacks,
# so the ODE tasks' programs go into the session's cache too.
os.environ.setdefault("EQX_ON_ERROR", "nan")

import gc  # noqa: E402

import pytest  # noqa: E402

from diffcontrol._jax_setup import GC_THRESHOLDS, enable_compile_cache  # noqa: E402
from diffcontrol.cli import main  # noqa: E402

# Tests that train the same small configurations share compiled programs through the cache.
enable_compile_cache()
# The collector as the console script sets it (_jax_setup.GC_THRESHOLDS): fewer collections
# while the tests trace their programs, each walking every object the session has made so far.
gc.set_threshold(*GC_THRESHOLDS)


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session):
    """After the session's fixtures are torn down: one full collection, whose garbage's
    ``__del__`` errors reach pytest's report of unraisable exceptions, then the session's
    objects frozen out of the collector, as the console script freezes a command's
    (``cli.run``). pytest ends a session with five full collections, each of a worker's
    millions of objects (about a second each after one test file); four are spared. The
    session's own compilation cache is removed by the process that made it."""
    gc.collect()
    gc.freeze()
    if _OWN_CACHE is not None and not hasattr(session.config, "workerinput"):
        shutil.rmtree(_OWN_CACHE, ignore_errors=True)


def pytest_collection_modifyitems(config, items):
    """The slow tests first (longest first, as a scheduler packs jobs): each xdist worker
    then ends on short tests, and no worker is left running a long one while the other
    waits. The order within each kind is the files' own."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def pytest_report_header(config):
    """The compiler flags the session runs under (see above), in pytest's header."""
    return f"XLA_FLAGS: {os.environ.get('XLA_FLAGS', '')!r}"


TINY_CARTPOLE = [
    "--updates",
    "20",
    "--eval-every",
    "10",
    "--eval-episodes",
    "4",
    "--final-eval",
    "3",
]


@pytest.fixture(scope="session")
def cartpole_run(tmp_path_factory):
    """A CartPole run trained by the CLI on a tiny budget (shared, read-only)."""
    out = tmp_path_factory.mktemp("runs") / "cartpole"
    assert main(["train", "cartpole", "--out", str(out), "--quiet", *TINY_CARTPOLE]) == 0
    return out


@pytest.fixture(scope="session")
def pendulum_run(tmp_path_factory):
    """A Pendulum run trained by the CLI on a tiny budget (shared, read-only)."""
    out = tmp_path_factory.mktemp("runs") / "pendulum"
    args = ["--updates", "10", "--window", "10", "--batch", "4", "--eval-every", "5"]
    args += ["--eval-episodes", "2", "--final-eval", "2"]
    assert main(["train", "pendulum", "--out", str(out), "--quiet", *args]) == 0
    return out


TINY_SWINGUP = ["--updates", "50", "--final-eval", "0"]


@pytest.fixture(scope="session")
def swingup_run(tmp_path_factory):
    """A cartpole-swingup run trained by the CLI on a small budget (shared, read-only)."""
    out = tmp_path_factory.mktemp("runs") / "swingup"
    assert main(["train", "cartpole-swingup", "--out", str(out), "--quiet", *TINY_SWINGUP]) == 0
    return out
