"""Pictures of a MuJoCo task's recorded states, for ``animate``: MuJoCo's own renderer where
an OpenGL context can be made, else the bodies drawn with matplotlib.

MuJoCo's Python bindings choose their OpenGL backend once, when ``mujoco`` is imported, from
``MUJOCO_GL``, and on Linux without it they take GLFW, which needs a display. Here the context
is made explicitly: the backend ``MUJOCO_GL`` names, else GLFW where there is a display
(``DISPLAY``/``WAYLAND_DISPLAY``, or not Linux), else EGL, which renders headless (on a GPU,
or in software with Mesa). Where that fails (no OpenGL library, no PyOpenGL), the frames are
matplotlib drawings: each body a dot joined to its parent, seen along the axis the bodies
move least in, so a planar robot is seen face on.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np

SIZE = (360, 480)
"""Height and width of a rendered frame, in pixels (within MuJoCo's default offscreen
buffer, 640 x 480)."""


def _gl_context(width: int, height: int) -> Any:
    """A current OpenGL context for MuJoCo's offscreen renderer (module docstring)."""
    backend = os.environ.get("MUJOCO_GL", "").lower()
    if not backend:
        display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
        backend = "glfw" if display or not sys.platform.startswith("linux") else "egl"
    if backend not in ("egl", "osmesa", "glfw"):
        raise RuntimeError(f"MUJOCO_GL={backend!r} names no offscreen backend")
    context = importlib.import_module(f"mujoco.{backend}").GLContext(width, height)
    context.make_current()
    return context


def plane(positions: np.ndarray) -> np.ndarray:
    """The two axes (of x, y, z) along which the bodies of ``positions`` (``[frames, bodies,
    3]``) spread most, in order: the plane a planar robot moves in."""
    flat = positions.reshape(-1, 3)
    return np.sort(np.argsort(flat.max(0) - flat.min(0))[-2:])


def kinematics(task: Any, states: np.ndarray) -> tuple[np.ndarray, float]:
    """The bodies' world positions in each state, ``[frames, bodies, 3]`` (the world body left
    out), and how far the moving geoms (of bodies other than the world) reach from the model's
    centre of mass at most over ``states`` (their centres' distance plus their bounding
    radius), by MuJoCo's kinematics in the C engine."""
    import mujoco

    model, nq = task.system.mj_model, task.system.nq
    data = mujoco.MjData(model)
    moving = model.geom_bodyid > 0
    any_moving = bool(np.any(moving))
    positions = np.empty((len(states), model.nbody - 1, 3))
    reach = 0.0 if any_moving else 1.0
    for i, state in enumerate(states):
        data.qpos[:] = state[:nq]
        mujoco.mj_kinematics(model, data)
        positions[i] = data.xpos[1:]
        if any_moving:
            mujoco.mj_comPos(model, data)
            far = np.linalg.norm(data.geom_xpos[moving] - data.subtree_com[0], axis=-1)
            reach = max(reach, float(np.max(far + model.geom_rbound[moving])))
    return positions, max(reach, 0.05)


def _camera(mujoco: Any, model: Any, positions: np.ndarray, reach: float, settings: dict) -> Any:
    """The view: following the model's centre of mass, facing the plane its bodies move in
    (from the side where it holds the vertical, from above at 60 degrees where it does not),
    from 3.5 times the geoms' ``reach`` from it (``kinematics``); ``settings`` (``distance``,
    ``elevation``, ``azimuth``, ``trackbodyid``) over it."""
    camera = mujoco.MjvCamera()
    mujoco.mjv_defaultFreeCamera(model, camera)
    camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    camera.trackbodyid = 0  # the world's subtree: the whole model's centre of mass
    axes = plane(positions)
    camera.distance = 3.5 * reach
    if 2 in axes:  # x-z (or y-z): look along the other horizontal axis
        camera.elevation, camera.azimuth = -10.0, 90.0 if axes[0] == 0 else 0.0
    else:
        camera.elevation, camera.azimuth = -60.0, 90.0
    for key, value in settings.items():
        setattr(camera, key, value)
    return camera


def rendered(task: Any, states: np.ndarray) -> Iterator[np.ndarray]:
    """RGB frames of ``states`` (rows of ``concat(qpos, qvel, ...)``) by MuJoCo's renderer.

    Raises (before the first frame): whatever making an OpenGL context raises.
    """
    import mujoco

    system = task.system
    model, (height, width) = system.mj_model, SIZE
    context = _gl_context(width, height)
    try:
        data = mujoco.MjData(model)
        scene = mujoco.MjvScene(model, maxgeom=10_000)
        render_context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, render_context)
        viewport = mujoco.MjrRect(0, 0, width, height)
        positions, reach = kinematics(task, states)
        camera = _camera(mujoco, model, positions, reach, dict(task.camera))
        option, perturb = mujoco.MjvOption(), mujoco.MjvPerturb()
        pixels = np.empty((height, width, 3), np.uint8)
        for state in states:
            data.qpos[:] = state[: system.nq]
            data.qvel[:] = state[system.nq : system.nq + system.nv]
            mujoco.mj_forward(model, data)
            mujoco.mjv_updateScene(
                model, data, option, perturb, camera, mujoco.mjtCatBit.mjCAT_ALL, scene
            )
            mujoco.mjr_render(viewport, scene, render_context)
            mujoco.mjr_readPixels(pixels, None, viewport, render_context)
            yield np.flipud(pixels).copy()  # OpenGL's rows run bottom to top
        render_context.free()
    finally:
        context.free()


def drawn(task: Any, states: np.ndarray, times: np.ndarray) -> Iterator[Any]:
    """matplotlib figures of ``states``: the bodies as dots, each joined to its parent, on the
    plane of the two axes along which they spread most."""
    from ._scene import close, scene

    positions, _ = kinematics(task, states)
    axes = plane(positions)
    flat = positions[..., axes]
    low, high = flat.reshape(-1, 2).min(0), flat.reshape(-1, 2).max(0)
    margin = 0.1 * max(float(np.max(high - low)), 0.1)
    low, high = low - margin, high + margin
    width = 4.0 * min(3.0, max(1.0, (high[0] - low[0]) / (high[1] - low[1])))
    fig, ax = scene(width, 4.0, (low[0], high[0]), (low[1], high[1]))
    parents = task.system.mj_model.body_parentid[1:] - 1  # -1: the world
    links = [(child, parent) for child, parent in enumerate(parents) if parent >= 0]
    lines = [ax.plot([], [], lw=4, color="#4d79cc", solid_capstyle="round")[0] for _ in links]
    (dots,) = ax.plot([], [], "o", color="#333333", ms=4)
    names = "xyz"
    ax.set_title(f"{names[axes[0]]}-{names[axes[1]]} plane", fontsize=8)
    text = ax.text(low[0], high[1], "", fontsize=8, family="monospace", va="top")
    for frame, when in zip(flat, times, strict=True):
        for line, (child, parent) in zip(lines, links, strict=True):
            line.set_data(frame[[parent, child], 0], frame[[parent, child], 1])
        dots.set_data(frame[:, 0], frame[:, 1])
        text.set_text(f"t={when:6.2f} s")
        yield fig
    close(fig)


def frames(task: Any, recording: Any, every: int) -> Iterator[Any]:
    """One frame per ``every`` steps of ``recording`` (module docstring)."""
    index = np.arange(0, recording.states.shape[0], every)
    states = np.asarray(recording.states, np.float64)[index]
    pictures = rendered(task, states)
    try:
        first = next(pictures)
    except Exception:  # no OpenGL here: draw instead
        yield from drawn(task, states, index * recording.dt)
        return
    yield first
    yield from pictures
