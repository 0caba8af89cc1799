"""What the benchmark scripts share: the machine's description and a pinned `diffcontrol train`."""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path


def machine() -> dict:
    """The library's description of the machine (CPU, versions), the cores used and the date."""
    from diffcontrol.compare import machine as describe

    return {
        **describe(),
        "cores_used": 1 if shutil.which("taskset") else os.cpu_count(),
        "date": dt.date.today().isoformat(),
    }


def train_cli(task: str, seed: int, out: Path, extra: list[str]) -> tuple[dict, float]:
    """Run `diffcontrol train TASK --out OUT --seed SEED ...` in a fresh process on core 0.

    The persistent compilation cache is off, so the run compiles everything from scratch.
    Returns the run's ``metrics.json`` and the whole process's wall-clock seconds (Python and
    JAX start-up, compilation, training, evaluation and the files included).
    """
    cmd = [sys.executable, "-m", "diffcontrol.cli", "train", task, "--out", str(out)]
    cmd += ["--seed", str(seed), "--quiet", *extra]
    if shutil.which("taskset"):
        cmd = ["taskset", "-c", "0", *cmd]
    env = dict(os.environ, DIFFCONTROL_NO_COMPILE_CACHE="1")
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
    seconds = time.perf_counter() - t0
    return json.loads((out / "metrics.json").read_text()), seconds
