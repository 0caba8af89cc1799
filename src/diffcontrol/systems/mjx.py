"""A MuJoCo model as a pure, differentiable JAX program, through MJX (``mujoco.mjx``).

``MjxSystem(path)`` loads an MJCF file with MuJoCo's own parser and puts it on the device as
an ``mjx.Model``. Its state is ``concat(qpos, qvel)``; ``simulate(state, ctrl, frames)`` sets
the controls and advances ``frames`` physics steps of ``model.opt.timestep`` each, as
Gymnasium's ``MujocoEnv.do_simulation`` does with ``mj_step(..., nstep=frames)``, and returns
MJX's ``Data`` after the last one (positions, site poses, constraint forces of that step).

Where the derivative is non-smooth or missing:

- the step runs ``model.opt.iterations = 1`` of the constraint solver: with more, MJX runs a
  ``lax.while_loop``, which JAX cannot differentiate in reverse mode. One iteration solves a
  model without active constraints exactly (there is nothing to solve), so the step equals
  MuJoCo's C engine there; where a joint limit or a contact is active, the one-iteration solve
  differs from the converged one and the two drift apart (``tests/test_mujoco.py``);
- the derivative (``simulate``, ``gradient``): ``"exact"``, the derivative of the step itself
  (the one-iteration solve included), computed in forward mode; or ``"smooth"``, that of the
  step without its constraint solver: the same where no constraint is active, blind to a
  constraint's force where one is. MJX's own reverse-mode derivative of its solver can be NaN
  (its line search's tolerance takes the square root of an exact zero; the zero cotangent
  times the infinite slope is NaN), which ends training; forward mode never forms that
  product, since the tolerance only enters comparisons.

The ``mujoco`` extra (``pip install 'diffcontrol[mujoco]'``) installs MuJoCo and MJX; without
it, making a system raises ``ConfigError`` that says so.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
from pathlib import Path
from typing import Any

import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._jax_setup import traced_in_float64
from ..errors import ConfigError

EXTRA = "pip install 'diffcontrol[mujoco]'"


def modules() -> tuple[Any, Any]:
    """``(mujoco, mujoco.mjx)``, imported on first use (the optional ``mujoco`` extra)."""
    try:
        import mujoco
    except ImportError as exc:
        raise ConfigError(f"MuJoCo tasks need the mujoco extra: {EXTRA} ({exc})") from None
    # MJX's optional Warp backend prints a line to stdout when Warp is not installed; the
    # JAX backend this module uses does not need it, and stdout may be a --json answer.
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            from mujoco import mjx
        except ImportError as exc:
            raise ConfigError(f"MuJoCo tasks need MJX: {EXTRA} ({exc})") from None
    return mujoco, mjx


def gymnasium_asset(name: str) -> Path:
    """The path of one of Gymnasium's own MuJoCo model files (``"reacher.xml"``), found
    without importing Gymnasium's MuJoCo environments."""
    import importlib.util

    spec = importlib.util.find_spec("gymnasium")
    assert spec is not None and spec.origin is not None  # a dependency of diffcontrol
    return Path(spec.origin).parent / "envs" / "mujoco" / "assets" / name


def resolve(model_file: str | os.PathLike[str]) -> Path:
    """``model_file`` as a path: an existing file, or the name of a Gymnasium asset."""
    path = Path(model_file).expanduser()
    if path.is_file():
        return path
    asset = gymnasium_asset(str(model_file))
    if os.sep not in str(model_file) and asset.is_file():
        return asset
    raise ConfigError(
        f"MuJoCo model file {str(model_file)!r} does not exist; give the path of an MJCF "
        "file, or the name of one of Gymnasium's assets (e.g. 'reacher.xml')"
    )


GRADIENTS = ("exact", "smooth")
"""How ``MjxSystem.simulate`` is differentiated (module docstring)."""

DIFFERENTIATED = ("qpos", "qvel", "act", "xpos", "xquat", "site_xpos", "xipos", "qfrc_constraint")
"""The fields of ``Data`` a step's derivative reaches: the state, the bodies' and sites' poses
and the constraint forces. A task reads its losses and observations from these."""


class MjxSystem:
    """One MuJoCo model on the device, stepped by MJX.

    Args:
        model_file: an MJCF path, or the name of one of Gymnasium's assets.
        iterations: the constraint solver's iterations (``model.opt.iterations``); 1, the
            default, is what differentiation needs (module docstring).
        gradient: ``"exact"`` or ``"smooth"``: how ``simulate`` is differentiated.

    Attributes:
        mj_model: MuJoCo's ``MjModel`` (the C engine's), with ``iterations`` set.
        model: the ``mjx.Model``.
        nq, nv, nu: sizes of ``qpos``, ``qvel`` and ``ctrl``.
        dt: the duration of one physics step (``opt.timestep``, s).
    """

    def __init__(
        self, model_file: str | os.PathLike[str], iterations: int = 1, gradient: str = "smooth"
    ):
        if gradient not in GRADIENTS:
            raise ConfigError(f"gradient must be one of {GRADIENTS}, got {gradient!r}")
        mujoco, mjx = modules()
        self.gradient = gradient
        self.path = resolve(model_file)
        try:
            mj_model = mujoco.MjModel.from_xml_path(str(self.path))
        except ValueError as exc:  # MuJoCo's parser: one line naming the element
            msg = " ".join(str(exc).split())
            raise ConfigError(f"MuJoCo cannot load {str(self.path)!r}: {msg}") from None
        mj_model.opt.iterations = iterations
        self.mj_model = mj_model
        self.nq, self.nv, self.nu = mj_model.nq, mj_model.nv, mj_model.nu
        self.dt = float(mj_model.opt.timestep)
        self._mjx = mjx
        self._free = mujoco.MjModel.from_xml_path(str(self.path))
        self._free.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
        # Concrete arrays even when a task first loads its model inside a trace (jit, grad):
        # a traced value kept here would leak into the next program.
        with jax.ensure_compile_time_eval():
            self._put(mj_model, self._free)
        self._by_dtype: dict[Any, MjxSystem] = {}
        self.init_qpos = np.asarray(mj_model.qpos0, np.float32)
        """``qpos0``: the model's reference configuration (Gymnasium's ``init_qpos``)."""

    def _put(self, mj_model: Any, free: Any) -> None:
        """The models and their initial ``Data`` on the device (JAX's default float type)."""
        mjx = self._mjx
        self.model = mjx.put_model(mj_model)
        self.data0 = mjx.make_data(self.model)
        """MJX's ``Data`` of the model's initial configuration (every field a step reads)."""
        self.unconstrained = mjx.put_model(free)
        """The model with its constraint solver switched off: the steps' derivatives."""
        self.data0_unconstrained = mjx.make_data(self.unconstrained)

    def at(self, dtype: Any) -> MjxSystem:
        """This system with its model and ``Data`` in ``dtype``: itself where they are, else a
        copy put on the device again. A state in float64 (``jax_enable_x64`` turned on after
        the model was loaded) steps in float64: MJX's loops need every float in one type."""
        key = jnp.dtype(dtype)
        if key.itemsize == 8:
            traced_in_float64()  # MJX's float64 NumPy tables stay in JAX's caches
        if jnp.asarray(self.data0.qpos).dtype == key:
            return self
        if key not in self._by_dtype:
            copy = object.__new__(MjxSystem)
            copy.__dict__.update(self.__dict__)
            with jax.ensure_compile_time_eval(), jax.enable_x64(key.itemsize == 8):
                copy._put(self.mj_model, self._free)
            self._by_dtype[key] = copy
        return self._by_dtype[key]

    def body_id(self, name: str) -> int:
        """The index of body ``name``; ``ConfigError`` naming the bodies there are if none."""
        mujoco, _ = modules()
        index = mujoco.mj_name2id(self.mj_model, mujoco.mjtObj.mjOBJ_BODY, name)
        if index < 0:
            names = [self.mj_model.body(i).name for i in range(self.mj_model.nbody)]
            raise ConfigError(f"model {self.path.name!r} has no body {name!r}; it has {names}")
        return int(index)

    def forward(self, state: Array) -> Any:
        """``Data`` of ``state = concat(qpos, qvel)`` after MuJoCo's forward pass (positions,
        velocities, constraint forces), as Gymnasium's ``set_state`` leaves it."""
        nq, nv = self.nq, self.nv
        sys = self.at(state.dtype)
        data = sys.data0.replace(qpos=state[:nq], qvel=state[nq : nq + nv])
        return sys._mjx.forward(sys.model, data)

    def simulate(self, state: Array, ctrl: Array, frames: int) -> Any:
        """``Data`` after ``frames`` physics steps from ``state = concat(qpos, qvel)`` with the
        controls ``ctrl`` held (MuJoCo clamps them to the actuators' ``ctrlrange``).

        The value is MJX's steps of the model. The derivative by ``state`` and ``ctrl`` is,
        with ``gradient="exact"``, that of these steps (of the fields in ``DIFFERENTIATED``),
        formed column by column in forward mode; with ``"smooth"``, that of the same steps
        with the constraint solver switched off, one physics step at a time (of the state and
        the poses): the same function wherever no constraint is active; where one is (a joint
        at its limit), it does not see the constraint's force.
        """
        nq, nv = self.nq, self.nv
        sys = self.at(state.dtype)
        data = sys.data0.replace(
            qpos=state[:nq], qvel=state[nq : nq + nv], ctrl=jnp.asarray(ctrl, state.dtype)
        )
        if sys.gradient == "exact":
            return _exact_frames(sys, frames, data.qpos, data.qvel, data.act, data.ctrl)
        return jax.lax.fori_loop(0, frames, lambda _, d: sys._step(d), data)

    def _frames(self, frames: int, qpos: Array, qvel: Array, act: Array, ctrl: Array) -> Any:
        data = self.data0.replace(qpos=qpos, qvel=qvel, act=act, ctrl=ctrl)
        return jax.lax.fori_loop(0, frames, lambda _, d: self._mjx.step(self.model, d), data)

    def _step(self, data: Any) -> Any:
        exact = jax.lax.stop_gradient(self._mjx.step(self.model, data))
        # The unconstrained model's Data has no constraint rows: its own, in this state.
        start = self.data0_unconstrained.replace(
            qpos=data.qpos, qvel=data.qvel, act=data.act, ctrl=data.ctrl, time=data.time
        )
        smooth = self._mjx.step(self.unconstrained, start)

        def value_of_one_gradient_of_other(e: Any, s: Any) -> Any:
            if not jnp.issubdtype(e.dtype, jnp.inexact) or e.shape != s.shape:
                return e
            return s + jax.lax.stop_gradient(e - s)

        fields = {
            name: value_of_one_gradient_of_other(getattr(exact, name), getattr(smooth, name))
            for name in ("qpos", "qvel", "act", "ctrl", "xpos", "xquat", "site_xpos", "xipos")
        }
        return exact.replace(**fields)


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1))
def _exact_frames(system: MjxSystem, frames: int, qpos, qvel, act, ctrl) -> Any:
    """``system._frames``, whose reverse-mode derivative is formed in forward mode."""
    return system._frames(frames, qpos, qvel, act, ctrl)


def _exact_frames_fwd(system: MjxSystem, frames: int, qpos, qvel, act, ctrl):
    return system._frames(frames, qpos, qvel, act, ctrl), (qpos, qvel, act, ctrl)


def _exact_frames_bwd(system: MjxSystem, frames: int, inputs, cotangent):
    # The Jacobian of the differentiated fields by every input, one forward-mode column per
    # input number (a few dozen at most), then the cotangent's product with it.
    flat, unflatten = jax.flatten_util.ravel_pytree(inputs)

    def fields(x):
        data = system._frames(frames, *unflatten(x))
        return {name: getattr(data, name) for name in DIFFERENTIATED}

    jacobian = jax.jacfwd(fields)(flat)
    total = jnp.zeros_like(flat)
    for name in DIFFERENTIATED:
        ct = getattr(cotangent, name)
        if ct is None or ct.dtype == jax.dtypes.float0:
            continue
        total = total + jnp.tensordot(ct, jacobian[name], axes=ct.ndim)
    return unflatten(total)


_exact_frames.defvjp(_exact_frames_fwd, _exact_frames_bwd)
