"""``fit``: one entry point for every model of every task, and ``fit_dir``: the ``fit`` directory
(``fitted.json``, ``prediction.png`` and the printed report) that ``diffcontrol fit`` writes."""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .._run_dir import check_no_dangling_link
from .._version import __version__
from ..errors import ConfigError, RunDirectoryError
from ..io import now_iso, write_json, write_json_new
from ..settings import FitConfig
from ..tasks import as_task
from ._progress import reporting
from ._routes import model_route
from ._shooting import FitResult
from .data import TrajectoryData
from .fitted import FITTED_FILE, FITTED_FORMAT, check_real_env, checked_env, real_params
from .kinds import kind


def fit(task: Any, data: Any, model: str = "params", **settings: Any) -> FitResult:
    """Fit a model of ``task``'s system to recorded ``data``.

    The route (the discrete step, the vector field, or the task's own) is the task's
    ``model_route``; nothing here asks which system the task is.

    Args:
        task: any task (``diffcontrol.make``/``tasks.resolve``).
        data: recorded episodes (``TrajectoryData``, or the path of its CSV or NPZ file;
            one-step episodes where the system gives one measured outcome).
        model: ``params`` (grey box: the task's physical parameters), ``hybrid`` (physics plus
            a network) or ``neural`` (a network alone).
        settings: ``names`` (the parameters of a grey box; default the task's
            ``fit_parameter_names``), ``window``, ``steps``, ``learning_rate``, ``lm_steps``,
            ``hidden``, ``seed``, ``init``, ``params`` (the physics to start from), and for
            vector fields ``weight_decay`` and ``substeps``. Adam's ``steps`` and
            ``learning_rate`` default to the route's for the model type.

    Returns:
        The ``FitResult``.

    Raises:
        ConfigError: an unknown model type or setting; DataFileError: data of another
        system; InsufficientDataError: too little data (the message says how much is needed).
    """
    kind(model)  # an unknown kind is refused before the data is read
    task = as_task(task, "fit()")
    route = model_route(task)
    if isinstance(data, str | os.PathLike):  # a recorded file: read (and checked) first
        data = route.read(data)
    if not isinstance(data, TrajectoryData):
        raise ConfigError(
            f"fit() takes recorded data (a TrajectoryData, or the path of a CSV or NPZ file "
            f"that diffcontrol record wrote), not {type(data).__name__}"
        )
    steps, lr = route.defaults(model)
    settings = {"steps": steps, "learning_rate": lr, **settings}
    result = route.fit(task, data, model, **{k: v for k, v in settings.items() if v is not None})
    return _within_ranges(task, result)


def _within_ranges(task: Any, result: FitResult) -> FitResult:
    """A grey box whose fitted value of a ``nonnegative_params`` parameter came out below 0
    (a friction fitted from data with none: the noise pulls it either way) is held at its
    bound 0, and the message says so: ``train --model`` then accepts what ``fit`` wrote (the
    task's ``check_params`` refuses a negative friction). Positive parameters are fitted as
    ``exp(z)`` and cannot leave their range."""
    below = [
        n
        for n in result.names
        if n in getattr(task, "nonnegative_params", ()) and result.values.get(n, 0.0) < 0
    ]
    if not below or kind(result.model_type).network:
        return result
    import equinox as eqx
    import numpy as np

    params = eqx.tree_at(
        lambda p: tuple(getattr(p, n) for n in below),
        result.params,
        tuple(np.zeros_like(np.asarray(getattr(result.params, n))) for n in below),
    )
    held = ", ".join(f"{n} (fitted {result.values[n]:.3g})" for n in below)
    return dataclasses.replace(
        result,
        model=params,
        params=params,
        values={**result.values, **{n: 0.0 for n in below}},
        message=f"{result.message}; held at the bound 0: {held}",
    )


@dataclasses.dataclass(frozen=True)
class FitDir:
    """What ``fit_dir`` wrote: the result, the ``fitted.json`` document, the report's lines
    (parameters with standard errors, held-out errors, a divergence, the files written) and
    the fit's duration (s)."""

    result: FitResult
    doc: dict
    lines: list[str]
    seconds: float


def check_fit_dir(out: Path, force: bool) -> None:
    """Refuse, before fitting, an ``out`` that could not take fitted.json (nothing is created)."""
    check_no_dangling_link(out)
    if out.exists() and not out.is_dir():
        raise RunDirectoryError(f"--out {out} is a file; give a directory")
    if (out / FITTED_FILE).exists() and not force:
        raise RunDirectoryError(
            f"{out / FITTED_FILE} already exists; pass --force to replace it or choose "
            "another --out"
        )
    parent = next((p for p in (out, *out.parents) if p.exists()), Path("."))
    if not os.access(parent, os.W_OK | os.X_OK):
        raise RunDirectoryError(f"cannot write --out {out}: {parent} is not writable")


def split(route: Any, data: Any, fraction: float) -> tuple[Any, Any]:
    """``(fitted, held_out)``: the last ``fraction`` of the episodes held out, at
    least one when ``fraction > 0``; ``held_out`` is None for 0."""
    n = route.count(data)
    if fraction == 0:
        return data, None
    held = max(1, round(fraction * n))
    if n - held < 1:
        unit = route.unit
        raise ConfigError(
            f"--holdout {fraction} of {n} {unit}(s) leaves none to fit; record at least 2 "
            f"{unit}s, or pass --holdout 0"
        )
    return route.split(data, n - held)


def fit_dir(
    task: Any,
    data_file: str | Path,
    model: str,
    out: str | Path,
    config: FitConfig | None = None,
    *,
    force: bool = False,
    progress: Callable[[str], None] | None = None,
    env_id: str | None = None,
    **start: Any,
) -> FitDir:
    """``diffcontrol fit``: read ``data_file``, hold out its last ``config.holdout`` fraction,
    fit ``model`` (``fit``, with the settings ``config``: a ``FitConfig``, by default
    ``FitConfig()``) and write ``out/fitted.json`` and ``out/prediction.png``. ``start`` is
    what the fit starts from, as ``fit`` takes it: ``init`` (a grey box's initial values) or
    ``params`` (a hybrid's physics). ``env_id``: the data's environment as the user names it
    (``--env``), for an id whose module is the user's (``my_envs:MyPendulum-v0``), which is
    not imported because the file names it.

    Raises:
        RunDirectoryError: ``out`` cannot take the files (or holds a fit, without ``force``);
            otherwise what ``fit`` raises, and nothing is created for a refused fit.
    """
    route = model_route(task)
    if hasattr(route, "check_model"):  # before anything is read or created
        route.check_model(task, model)
    steps, lr = route.defaults(model)
    given = {k: v for k, v in dataclasses.asdict(config or FitConfig()).items() if v is not None}
    settings = {"steps": steps, "learning_rate": lr, **given, **start}
    holdout = settings["holdout"]
    with reporting(progress):
        data = route.read(data_file)
    meta = getattr(data, "metadata", None) or {}
    if isinstance(meta.get("params"), dict) and not meta.get("env_id"):
        # what train --model will judge on: checked now
        real_params(task, {"params": meta["params"]})
    if env_id is not None and meta.get("env_id") != env_id:
        raise ConfigError(
            f"--env {env_id} is not the environment the data of {data_file} came from "
            f"({meta.get('env_id')!r}); leave --env out, or fit data of {env_id}"
        )
    if meta.get("env_id"):  # the real system train --model judges on: checked now too
        real_id, env_kwargs = checked_env(
            meta["env_id"], meta.get("env_kwargs"), str(data_file), trusted=env_id
        )
        check_real_env(task, real_id, env_kwargs, str(data_file))
    out = Path(out)
    check_fit_dir(out, force)
    train, held_out = split(route, data, holdout)
    if progress:
        progress(route.announce(task, model, train, held_out, data_file, settings))
    if hasattr(route, "check_split"):
        route.check_split(task, data, train, held_out, settings)
    t0 = time.perf_counter()
    fit_settings = {k: v for k, v in settings.items() if k != "holdout"}
    with reporting(progress):
        result = fit(task, train, model, **fit_settings)
    seconds = time.perf_counter() - t0
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RunDirectoryError(f"cannot create --out {out} ({e.strerror})") from None
    body, held_lines = route.outputs(task, result, data, train, held_out, data_file, settings, out)
    doc = save_fit(out, task, result, body, seconds, force=force)
    return FitDir(
        result, doc, report(body.get("parameters", {}), result, out, seconds, held_lines), seconds
    )


def save_fit(
    out: str | Path, task: Any, result: FitResult, body: dict, seconds: float, force: bool = True
) -> dict:
    """Write ``out/fitted.json``: the format's head, ``body`` (the route's model, settings,
    data and prediction errors) with how the fit ended, and when and by what; returns it."""
    head = {"format": FITTED_FORMAT, "version": 1, "task": task.name, "model": result.model_type}
    ended = {
        "loss": result.loss,
        "nominal_loss": result.nominal_loss,
        "diverged": result.diverged,
        "message": result.message,
        "loss_history": [float(v) for v in result.loss_history],
        "seconds": seconds,
    }
    body = {**body, "fit": {**body.get("fit", {}), **ended}}
    doc = {**head, **body, "created": now_iso(), "diffcontrol_version": __version__}
    path = Path(out) / FITTED_FILE
    if force:
        write_json(path, doc)
    else:  # of two fits racing for one --out, one writes and the other is told
        try:
            write_json_new(path, doc)
        except FileExistsError:
            raise RunDirectoryError(
                f"{path} was written by another process meanwhile; choose another --out"
            ) from None
    return doc


def report(parameters: dict, result: FitResult, out: Path, seconds: float, lines: list) -> list:
    """The printed report: the fitted parameters with their standard errors, the held-out
    errors, a divergence and the files written."""
    text = []
    for n, p in parameters.items():
        se = p["standard_error"]
        pm = f" ± {se:.3g}" if math.isfinite(se) else " (not identifiable from this data)"
        text.append(f"{n} = {p['value']:.6g}{pm} (nominal {p['nominal']:.6g})")
    text += lines
    if result.diverged:
        text.append(f"warning: {result.message}")
    text.append(f"wrote {out / FITTED_FILE} and {out / 'prediction.png'} ({seconds:.1f} s fit)")
    return text
