"""Benchmark of `diffcontrol loop`: record -> fit -> train rounds on the mismatched Pendulum.

The real system is the one of ``fit_gap_pendulum.py`` (``diffcontrol/PendulumFriction-v0``
with g = 12 and friction 0.1; noise-free observations). For each model kind and seed S:

    diffcontrol loop pendulum --env diffcontrol/PendulumFriction-v0 --env-arg g=12 \
        --env-arg friction=0.1 --model KIND --rounds 2 --episodes 5 --seed S \
        --eval-episodes 100

so round 1 fits 5 episodes of random torques and round 2 adds 5 episodes of round 1's
controller (10 in all; ``--rounds R --episodes N`` for other splits). Each round's controller
is evaluated on the real system over 100 episodes (reset seeds 0-99, as in
``fit_gap_pendulum.py``).

    taskset -c 0 python benchmarks/fit_loop_pendulum.py [--seeds 3] [--kinds hybrid,neural]

Prints a table and writes benchmarks/results/fit_loop_pendulum.json. ``--members K`` fits
ensembles of K networks (``--uncertainty-penalty W`` their penalty, ``--explore-noise F`` the
noise of the controller's recording; written to ``fit_loop_pendulum-ensembleK.json``).
``--controller plan`` lets the planner through each round's model act instead of a trained MLP
(``loop --controller plan``; ``-plan`` is added to the file's name).
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
ARGS += ["friction=0.1", "--eval-episodes", "100"]


def run(kind: str, seed: int, extra: list[str]) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "loop"
        argv = ["loop", "pendulum", *ARGS, "--model", kind, "--seed", str(seed), *extra]
        code = cli([*argv, "--out", str(out), "--quiet"])
        if code:
            raise SystemExit(f"diffcontrol loop failed with status {code}")
        doc = json.loads((out / "loop.json").read_text())
    return {"kind": kind, "seed": seed, "rounds": doc["rounds"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--kinds", default="hybrid,neural")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--members", type=int, default=1)
    parser.add_argument("--uncertainty-penalty", type=float, default=None)
    parser.add_argument("--explore-noise", type=float, default=None)
    parser.add_argument("--controller", choices=("train", "plan"), default="train")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--episodes", type=int, default=5, help="real episodes per round")
    parser.add_argument("--fit-steps", type=int, default=None, help="Adam steps of each fit")
    args = parser.parse_args()
    extra = ["--rounds", str(args.rounds), "--episodes", str(args.episodes)]
    extra += ["--fit-steps", str(args.fit_steps)] if args.fit_steps else []
    extra += ["--members", str(args.members)] if args.members > 1 else []
    extra += ["--controller", args.controller]
    for flag in ("uncertainty_penalty", "explore_noise"):
        if getattr(args, flag) is not None:
            extra += ["--" + flag.replace("_", "-"), str(getattr(args, flag))]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    rows = [run(k, s, extra) for k in args.kinds.split(",") for s in seeds]
    print("\nreturn on the real system (100 episodes) after each round")
    print(f"round 1: {args.episodes} random episodes; each later round adds {args.episodes} of the")
    print("last round's controller")
    print("model    seed " + "".join(f"   round {k + 1:<3}" for k in range(args.rounds)))
    for r in rows:
        rets = "".join(f"{x['real_return']:12.1f}" for x in r["rounds"])
        print(f"{r['kind']:8} {r['seed']:4} {rets}")
    name = "fit_loop_pendulum" + (f"-ensemble{args.members}" if args.members > 1 else "")
    name += "-plan" if args.controller == "plan" else ""
    name += f"-{args.rounds}x{args.episodes}" if (args.rounds, args.episodes) != (2, 5) else ""
    name += f"-fit{args.fit_steps}" if args.fit_steps else ""
    noise = args.explore_noise
    name += f"-noise{noise:g}" if noise is not None and noise != 0.1 else ""  # 0.1: the usual
    name += f"-seeds{seeds[0]}-{seeds[-1]}" if args.first_seed else ""
    out = HERE / "results" / f"{name}.json"
    command = "diffcontrol loop pendulum " + " ".join([*ARGS, *extra])
    doc = {"machine": machine(), "command": command}
    out.write_text(json.dumps({**doc, "runs": rows}, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
