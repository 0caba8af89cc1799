"""Issue 40, item 6: a Pendulum controller from 1,000 random real steps.

For each data seed S, the command of the issue, `diffcontrol loop pendulum --env Pendulum-v1
--model neural --rounds 1 --episodes 5 --seed S` (5 episodes of random torques: 1,000 real
steps, a neural model fitted to them, a controller through it), once with the loop's default
controller (an MLP trained through the model) and once with `--controller plan` (the task's
planner acting through the model), each in a fresh process pinned to one core with the
persistent compilation cache off. Each controller is then judged with `diffcontrol evaluate
RUN --env Pendulum-v1` on reset seeds it never saw (1000 onwards; the loop records on seeds
past its own evaluation's 0-19 and judges on those).

    python benchmarks/real_steps_pendulum.py                    # data seeds 0-2, 50 episodes
    python benchmarks/real_steps_pendulum.py --seeds 1 --episodes 100
    python benchmarks/real_steps_pendulum.py --controllers default  # no --controller at all

Prints a table and writes benchmarks/results/real_steps_pendulum.json (machine, date, every
figure).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

TARGET = -150.0
"""The issue's bar: a mean return of at least -150 on Pendulum-v1."""


def _command(*args: str) -> list[str]:
    cmd = [sys.executable, "-m", "diffcontrol.cli", *args]
    return ["taskset", "-c", "0", *cmd] if shutil.which("taskset") else cmd


def one(seed: int, controller: str, episodes: int, work: Path) -> dict:
    """The loop of one data seed with one controller, and its controller judged."""
    out = work / f"{controller}-{seed}"
    argv = ["loop", "pendulum", "--env", "Pendulum-v1", "--model", "neural", "--rounds", "1"]
    argv += ["--episodes", "5", "--seed", str(seed), "--quiet"]
    argv += [] if controller == "default" else ["--controller", controller]
    env = dict(os.environ, DIFFCONTROL_NO_COMPILE_CACHE="1")
    t0 = time.perf_counter()
    subprocess.run(
        _command(*argv, "--out", str(out)), check=True, env=env, stdout=subprocess.DEVNULL
    )
    seconds = time.perf_counter() - t0
    doc = json.loads((out / "loop.json").read_text())
    loop = doc["rounds"][0]
    judge = ["evaluate", str(out / "round_1" / "run"), "--env", "Pendulum-v1"]
    judge += ["--episodes", str(episodes), "--seed", "1000", "--json"]
    done = subprocess.run(_command(*judge), check=True, capture_output=True, text=True, env=env)
    ev = json.loads(done.stdout.strip().splitlines()[-1])
    return {
        "seed": seed,
        "controller": controller,
        "acting": doc["settings"].get("controller", "train"),
        "real_steps": loop["real_steps"],
        "loop_seconds": seconds,
        "loop_return_seeds_0_19": loop["real_return"],
        "unseen_seeds": [1000, 1000 + episodes - 1],
        "unseen_mean_return": ev["mean_return"],
        "unseen_std_return": ev["std_return"],
        "unseen_standard_error": ev["std_return"] / episodes**0.5,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=3, help="data seeds 0..N-1 (default 3)")
    parser.add_argument("--episodes", type=int, default=50, help="unseen evaluation episodes")
    parser.add_argument(
        "--controllers", default="train,plan",
        help="the loops' --controller, comma-separated; 'default' passes none, leaving the "
        "choice to the loop (default train,plan)",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, default=HERE / "results" / "real_steps_pendulum.json")
    args = parser.parse_args()
    controllers = args.controllers.split(",")
    header = f"{'controller':>10} {'seed':>4} {'real steps':>10} {'loop s':>7} {'seeds 0-19':>10} {'unseen':>16}"
    print(header)
    print("-" * len(header))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for controller in controllers:
            for seed in range(args.seeds):
                r = one(seed, controller, args.episodes, Path(tmp))
                rows.append(r)
                print(
                    f"{controller:>10} {seed:>4} {r['real_steps']:>10} {r['loop_seconds']:>7.1f} "
                    f"{r['loop_return_seeds_0_19']:>10.1f} {r['unseen_mean_return']:>8.1f} ± "
                    f"{r['unseen_standard_error']:<5.1f}",
                    flush=True,
                )
    summary = {}
    for controller in controllers:
        means = [r["unseen_mean_return"] for r in rows if r["controller"] == controller]
        summary[controller] = {
            "worst_unseen_mean_return": min(means),
            "median_unseen_mean_return": statistics.median(means),
            "target_met_on_every_seed": min(means) >= TARGET,
        }
        worst = min(means)
        verdict = "met on every seed" if worst >= TARGET else f"missed by {TARGET - worst:.1f}"
        print(
            f"{controller}: unseen mean returns {worst:.1f} to {max(means):.1f}; target "
            f">= {TARGET:g} {verdict}"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"machine": machine(), "target": TARGET, "runs": rows, "summary": summary}
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
