"""The test session's XLA flags (``conftest.py``) change how fast programs compile, not what
they compute: short trainings under them and under XLA's defaults, as users run, agree to
rounding."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

SCRIPT = """
import json, sys
import equinox as eqx, jax, numpy as np
import diffcontrol
runs = {
    "cartpole": dict(updates=10, eval_every=5, batch=4, window=10, eval_episodes=4),
    "pendulum": dict(updates=10, eval_every=5, batch=4, window=10, eval_episodes=4),
    "cartpole-swingup": dict(updates=10, eval_every=5, population=2),
}
out = {}
for name, settings in runs.items():
    task = diffcontrol.make(name)
    r = diffcontrol.train(task, task.default_config().replace(**settings))
    leaves = jax.tree.leaves(eqx.filter(r.controller, eqx.is_inexact_array))
    out[name] = {
        "weights": [np.asarray(x, np.float64).ravel().tolist() for x in leaves],
        "curve": [[p["loss"], p["eval_return"]] for p in r.curve[1:]],
    }
json.dump(out, sys.stdout)
"""


def _trained(xla_flags: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, check=False
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout)


@pytest.mark.slow  # two processes, one compiling at XLA's default level: about 25 s on one core
def test_the_sessions_compiler_flags_agree_with_xlas_defaults_to_rounding():
    ours, users = _trained(os.environ.get("XLA_FLAGS", "")), _trained(None)
    for name in users:
        for a, b in zip(ours[name]["weights"], users[name]["weights"], strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-5, err_msg=name)
        (loss, ret), (user_loss, user_ret) = (np.asarray(r[name]["curve"]).T for r in (ours, users))
        np.testing.assert_allclose(loss, user_loss, rtol=1e-3, atol=1e-4, err_msg=name)
        # a return is a count of steps: rounding may end one evaluation episode a step or two
        # apart (XLA's level 0 did, 382.25 against 381.75 for CartPole's mean of 4 episodes)
        np.testing.assert_allclose(ret, user_ret, rtol=1e-4, atol=1.0, err_msg=name)
