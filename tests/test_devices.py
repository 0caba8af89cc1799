"""Beyond one device: the batch or a sweep's members split over devices, and several hosts.

Several devices are simulated on the CPU (``--xla_force_host_platform_device_count``), which
must be set before JAX starts: those tests run in a subprocess. Hosts are processes on
localhost that talk over Gloo.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import textwrap

import jax
import pytest

from diffcontrol.cli import main
from diffcontrol.errors import ConfigError
from diffcontrol.training._devices import join_hosts

TINY = dict(updates=20, eval_every=10, batch=4, window=10, eval_episodes=4, hidden=(8,))


def _run_with_devices(script: str, devices: int = 8) -> None:
    # the session's compiler flags (conftest.py) and the simulated devices
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={devices}"
    env = {**os.environ, "XLA_FLAGS": flags.strip()}
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(script)], env=env, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr[-2000:]


@pytest.mark.slow
def test_members_sharded_over_devices_match_one_device(tmp_path):
    """8 simulated CPU devices give each member the controller one device gives."""
    script = f"""
        import jax, numpy as np
        import diffcontrol as dc
        from diffcontrol.training import grid, sweep
        assert len(jax.devices()) == 8
        task = dc.make("cartpole")
        configs = grid(task.default_config().replace(**{TINY!r}), range(8), {{}})
        one, eight = sweep(task, configs, devices=1), sweep(task, configs)
        assert eight.members[0].metrics["sweep"]["devices"] == 8
        diff = max(
            float(np.max(np.abs(np.asarray(x) - np.asarray(y))))
            for a, b in zip(one.members, eight.members)
            for x, y in zip(jax.tree.leaves(a.controller), jax.tree.leaves(b.controller))
        )
        print("diff", diff)
        assert diff < 1e-4
        """
    _run_with_devices(script)


@pytest.mark.slow  # a subprocess with two devices and three trainings: about 10 s
def test_a_program_kept_for_one_device_is_not_run_on_another():
    """``compiled_once`` keys its programs by device: a run on the second device compiles its
    own and leaves its controller there; the next run there compiles nothing."""
    script = f"""
        import jax
        import diffcontrol as dc
        from diffcontrol.training import train
        task = dc.make("cartpole")
        config = task.default_config().replace(**{TINY!r})
        first = train(task, config)
        with jax.default_device(jax.devices()[1]):
            second = train(task, config.replace(seed=1))
            third = train(task, config.replace(seed=2))
        programs = [r.metrics["timings"]["compile_programs"] for r in (first, second, third)]
        assert programs == [3, 3, 0], programs
        placed = {{x.devices().pop() for x in jax.tree.leaves(second.controller) if hasattr(x, "devices")}}
        assert placed == {{jax.devices()[1]}}, placed
        """
    _run_with_devices(script, devices=2)


@pytest.mark.slow
def test_batch_split_over_devices_matches_one_device(tmp_path):
    """Data-parallel training: 8 simulated CPU devices give the controller one device gives,
    for a single run and for a population; a batch they do not divide is one line."""
    script = """
        import jax, numpy as np
        import diffcontrol as dc
        from diffcontrol.errors import ConfigError
        task = dc.make("pendulum")
        # no terminal value: its grid solve is the same on one device or eight
        cfg = task.default_config().replace(updates=20, eval_every=10, batch=16, window=10,
                                            eval_episodes=8, hidden=(16,), value_grid=0)
        def diff(a, b):
            return max(float(np.max(np.abs(np.asarray(x) - np.asarray(y))))
                       for x, y in zip(jax.tree.leaves(a.controller), jax.tree.leaves(b.controller)))
        for c in (cfg, cfg.replace(population=2)):
            one, eight = dc.train(task, c), dc.train(task, c, devices=8)
            assert eight.metrics["devices"] == 8
            assert diff(one, eight) < 1e-4, diff(one, eight)
            assert abs(one.metrics["final_eval_return"] - eight.metrics["final_eval_return"]) < 1e-2
        try:
            dc.train(task, cfg.replace(batch=12), devices=8)
        except ConfigError as e:
            assert "use --batch 8 or 16" in str(e), e
        else:
            raise AssertionError("batch 12 over 8 devices was accepted")
        """
    _run_with_devices(script)


def test_more_devices_than_there_are_is_one_line(tmp_path, capsys):
    out = tmp_path / "run"
    n = len(jax.local_devices()) + 1
    assert (
        main(["train", "cartpole", "--out", str(out), "--devices", str(n), "--updates", "1"]) == 2
    )
    err = capsys.readouterr().err
    assert f"got {n}" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# the windows recipe: no grid solve in each of the processes
TINY_CLI = ["--updates", "20", "--eval-every", "10", "--batch", "8", "--window", "10",
            "--eval-episodes", "8", "--hidden", "16", "--final-eval", "2", "--no-animation",
            "--quiet", "--recipe", "windows"]  # fmt: skip


@pytest.mark.slow
def test_two_hosts_train_what_one_trains(tmp_path):
    """Two processes on localhost (CPU collectives over Gloo) split the batch; process 0
    writes the run, whose learning curve is one process's to noise, and whose checkpoint
    resumes in a single process."""
    port = _free_port()
    cmd = [sys.executable, "-m", "diffcontrol.cli", "train", "pendulum", *TINY_CLI]
    hosts = ["--coordinator", f"127.0.0.1:{port}", "--processes", "2", "--join-timeout", "60"]
    both = tmp_path / "two"
    procs = [
        subprocess.Popen(
            [*cmd, "--out", str(both), *hosts, "--process-id", str(i)],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )  # fmt: skip
        for i in (0, 1)
    ]
    outputs = [p.communicate(timeout=600)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outputs
    assert "process 1 of 2: done" in outputs[1]
    one = tmp_path / "one"
    assert main(["train", "pendulum", "--out", str(one), *TINY_CLI]) == 0
    two_m, one_m = (json.loads((d / "metrics.json").read_text()) for d in (both, one))
    assert (two_m["processes"], two_m["devices"], one_m["processes"]) == (2, 2, 1)
    for a, b in zip(two_m["curve"], one_m["curve"], strict=True):
        assert a["eval_return"] == pytest.approx(b["eval_return"], abs=1e-2)
    # the two-host checkpoint holds whole arrays: one process can finish the run from it
    run = json.loads((both / "run.json").read_text())
    (both / "run.json").write_text(json.dumps({k: v for k, v in run.items() if k != "complete"}))
    (both / "model.json").unlink()
    assert main(["train", "--out", str(both), "--resume", "--quiet"]) == 0
    assert (both / "model.json").exists()


def test_a_host_that_cannot_join_is_one_line(tmp_path, capsys):
    port = _free_port()  # nobody listens there
    code = main(["train", "cartpole", "--out", str(tmp_path / "r"), "--coordinator",
                 f"127.0.0.1:{port}", "--processes", "2", "--process-id", "1",
                 "--join-timeout", "1"])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert f"127.0.0.1:{port}" in err and "process 1 of 2" in err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (("localhost", 2, 0), "HOST:PORT"),
        (("localhost:99999", 2, 0), "HOST:PORT"),
        (("localhost:1234", 2, 2), "--process-id must be in 0 ... 1"),
    ],
)
def test_bad_host_settings(args, message):
    with pytest.raises(ConfigError, match=message):
        join_hosts(*args)
