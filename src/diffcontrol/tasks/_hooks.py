"""What a layer does with a task, overridable per task without the task knowing the layer.

A layer (evaluation, runs, identify, ...) defines each of its functions of a task with
``task_hook``: the default body lives in the layer, not on the task. A task changes it in one
of two ways:

- a registration in the layer for its class, ``@evaluate_run.register(TrebuchetAiming)``: the
  built-in systems do so from modules of their own (``diffcontrol.builtin``), which the task
  registry names with ``plugin`` and which are imported when a hook first meets one of their
  tasks, so that no layer imports a system;
- a method of the same name on the task's class: a user's task in one file defines, say,
  ``frames`` or ``write_figures`` (see docs/own-system.md), and the hook calls it.
"""

from __future__ import annotations

import functools
import importlib
import types
from collections.abc import Callable
from typing import Any

from .._registry import hooks_of

_PLUGINS: dict[type, str] = {}
_LOADED: set[str] = set()


def plugin(cls: type, module: str) -> None:
    """Name the module that registers the overrides of the tasks of class ``cls`` (and its
    subclasses); it is imported when a hook first meets such a task."""
    _PLUGINS[cls] = module


def load_plugins(cls: type) -> None:
    """Import the modules that register overrides for ``cls`` and its bases, once: those
    named with ``plugin``, and the built-in tasks' (the registry's ``hooks``)."""
    for klass in cls.__mro__:
        module = _PLUGINS.get(klass) or hooks_of(klass)
        if module is not None and module not in _LOADED:
            importlib.import_module(module)
            _LOADED.add(module)


def task_hook(default: Callable[..., Any] | None = None, *, method: str | None = None) -> Any:
    """Make ``default(task, ...)`` a layer's function of a task that a task can override: by a
    registration for its class (``hook.register(cls)``, as ``functools.singledispatch``), or by
    a method of its own class named ``method`` (default the function's name), which wins.
    ``hook.implementation(task)`` is the function that would run for ``task``."""
    if default is None:
        return functools.partial(task_hook, method=method)
    dispatch = functools.singledispatch(default)
    name = method or default.__name__

    def implementation(task: Any) -> Callable[..., Any]:
        own = getattr(type(task), name, None)
        if callable(own):
            return own
        load_plugins(type(task))
        return dispatch.dispatch(type(task))

    @functools.wraps(default)
    def call(task: Any, *args: Any, **kwargs: Any) -> Any:
        return implementation(task)(task, *args, **kwargs)

    call.register = dispatch.register  # type: ignore[attr-defined]
    call.dispatch = dispatch.dispatch  # type: ignore[attr-defined]
    call.implementation = implementation  # type: ignore[attr-defined]
    # ``hook.bound(task)``: the function for ``task`` with ``task`` bound, as a method (equal
    # for the same task, so that programs traced from it are cached as a method's would be).
    call.bound = lambda task: types.MethodType(implementation(task), task)  # type: ignore
    return call
