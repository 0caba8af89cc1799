"""Benchmark of `diffcontrol loop`: record -> fit -> train rounds on the mismatched Pendulum.

The real system is the one of ``fit_gap_pendulum.py`` (``diffcontrol/PendulumFriction-v0``
with g = 12 and friction 0.1; noise-free observations). For each model kind and seed S:

    diffcontrol loop pendulum --env diffcontrol/PendulumFriction-v0 --env-arg g=12 \
        --env-arg friction=0.1 --model KIND --rounds 2 --episodes 5 --seed S \
        --eval-episodes 100

so round 1 fits 5 episodes of random torques and round 2 adds 5 episodes of round 1's
controller (10 in all). Each round's controller is evaluated on the real system over 100
episodes (reset seeds 0-99, as in ``fit_gap_pendulum.py``).

    taskset -c 0 python benchmarks/fit_loop_pendulum.py [--seeds 3] [--kinds hybrid,neural]

Prints a table and writes benchmarks/results/fit_loop_pendulum.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

from diffcontrol.cli import main as cli  # noqa: E402

ARGS = ["--env", "diffcontrol/PendulumFriction-v0", "--env-arg", "g=12", "--env-arg"]
ARGS += ["friction=0.1", "--rounds", "2", "--episodes", "5", "--eval-episodes", "100"]


def run(kind: str, seed: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "loop"
        argv = ["loop", "pendulum", *ARGS, "--model", kind, "--seed", str(seed)]
        code = cli([*argv, "--out", str(out), "--quiet"])
        if code:
            raise SystemExit(f"diffcontrol loop failed with status {code}")
        doc = json.loads((out / "loop.json").read_text())
    return {"kind": kind, "seed": seed, "rounds": doc["rounds"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--kinds", default="hybrid,neural")
    args = parser.parse_args()
    rows = [run(k, s) for k in args.kinds.split(",") for s in range(args.seeds)]
    print("\nreturn on the real system (100 episodes) after each round")
    print("model    seed   round 1 (5 random episodes)   round 2 (+5 of its controller)")
    for r in rows:
        rets = [f"{x['real_return']:10.1f}" for x in r["rounds"]]
        print(f"{r['kind']:8} {r['seed']:4}   {rets[0]:>27}   {rets[1]:>30}")
    out = HERE / "results" / "fit_loop_pendulum.json"
    doc = {"machine": machine(), "command": "diffcontrol loop pendulum " + " ".join(ARGS)}
    out.write_text(json.dumps({**doc, "runs": rows}, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
