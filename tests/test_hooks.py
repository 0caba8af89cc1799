"""``tasks._hooks``: a layer's function of a task, its default in the layer, overridden by a
registration for the task's class (imported lazily from the module the registry names) or by
a method of the task's own."""

from __future__ import annotations

import sys

import pytest

import diffcontrol
from diffcontrol.evaluation import evaluate_run
from diffcontrol.tasks import _hooks


class Base:
    pass


class Registered(Base):
    pass


class Own(Registered):
    def describe(self, suffix):
        return "own" + suffix


@_hooks.task_hook
def describe(task, suffix):
    return "default" + suffix


@describe.register(Registered)
def _registered(task, suffix):
    return "registered" + suffix


def test_a_hook_takes_the_default_a_registration_or_the_tasks_own_method():
    assert describe(Base(), "!") == "default!"
    assert describe(Registered(), "!") == "registered!"
    assert describe(Own(), "!") == "own!"  # a user's method wins over its base's registration


def test_a_plugin_is_imported_when_a_hook_first_meets_its_task(tmp_path, monkeypatch):
    (tmp_path / "hooks_plugin_probe.py").write_text(
        "from tests.test_hooks import describe, Lazy\n"
        "describe.register(Lazy)(lambda task, suffix: 'plugin' + suffix)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    _hooks.plugin(Lazy, "hooks_plugin_probe")
    try:
        assert "hooks_plugin_probe" not in sys.modules
        assert describe(Lazy(), "?") == "plugin?"
        assert "hooks_plugin_probe" in sys.modules
    finally:
        _hooks._PLUGINS.pop(Lazy)
        sys.modules.pop("hooks_plugin_probe", None)


class Lazy(Base):
    pass


@pytest.mark.parametrize("name", ["trebuchet", "cartpole-swingup", "cartpole-swingup-friction"])
def test_the_built_in_systems_register_their_run_hooks(name):
    """The trebuchet and the swing-ups are judged and drawn their own way: their plugins
    register for their classes when a hook first meets one."""
    from diffcontrol.plots import animate_run, write_figures

    task = diffcontrol.make(name)
    _hooks.load_plugins(type(task))
    for hook in (evaluate_run, write_figures, animate_run):
        assert hook.dispatch(type(task)).__module__.startswith("diffcontrol.builtin."), hook
    assert evaluate_run.dispatch(type(diffcontrol.make("pendulum"))).__module__ == (
        "diffcontrol.evaluation"
    )
