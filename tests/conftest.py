"""Shared test setup: a private compilation cache, and small trained runs shared by tests."""

from __future__ import annotations

import os
import tempfile

# A private persistent compilation cache for the whole test session, set before any
# diffcontrol import reads it; the user's own cache is never touched by the tests.
os.environ.setdefault("DIFFCONTROL_CACHE_DIR", tempfile.mkdtemp(prefix="diffcontrol-test-cache-"))
# The tests' programs are small and most run a few steps: XLA's backend optimisation costs
# more than it saves there (measured on tests/test_trebuchet_task.py and test_swingup.py,
# 12 % less CPU time in all). It changes how fast the code runs, not what it computes (up to
# the rounding of fused operations, which the tests' tolerances are for).
if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    flags = os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0"
    os.environ["XLA_FLAGS"] = flags.strip()
# As the command line sets it (``cli.main``): Equinox's checks as NaN, not host callbacks,
# so the ODE tasks' programs go into the session's cache too.
os.environ.setdefault("EQX_ON_ERROR", "nan")

import pytest  # noqa: E402

from diffcontrol._jax_setup import enable_compile_cache  # noqa: E402
from diffcontrol.cli import main  # noqa: E402

# Tests that train the same small configurations share compiled programs through the cache.
enable_compile_cache()

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
