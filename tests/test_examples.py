"""The examples run and do what they say."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses (equinox modules) look their module up here
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_custom_task_example_learns():
    result = _load("custom_task").main(updates=60)
    first, last = result.curve[0]["eval_return"], result.curve[-1]["eval_return"]
    assert last > 0.3 * first  # returns are negative: the cost fell by more than 70 %


@pytest.mark.slow
def test_continuous_task_example_learns():
    result = _load("continuous_task").main(updates=300)
    first, last = result.curve[0]["eval_loss"], result.curve[-1]["eval_loss"]
    assert last < 0.3 * first  # the mass reaches x = 1 m and stays (the loss fell by > 70 %)
