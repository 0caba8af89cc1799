"""Which of XLA's faster compile options keep a training program's results, task by task.

For each task (and recipe) given, the run's training chunks (every stage) and its evaluation
program are lowered once, as `diffcontrol train` lowers them, then compiled four ways: XLA's
defaults, optimisation level 1, the older CPU emitters, and both (`_jax_setup.FAST_COMPILE`),
and, where the task declares the older emitters (its `fast_compile`), a fifth: the declared
options with `_jax_setup.ONE_CORE`, as a process on one core compiles them. Each compiled
chunk runs `--updates` updates from the run's start and each evaluation program evaluates the
start's controller; the outputs are compared leaf by leaf, to the bit, with the defaults'. Printed per program: the compile
seconds and the run seconds of each way, `=` where the bits are the defaults' and `x` where
they are not, and the declared options, which must be among the `=` ones (the fifth way must
give the declared way's bits).

Where a task declares options that change a program's bits (`OTHER_BITS`: CartPole's chunk,
the trebuchet's evaluation),
`--runs` trains whole runs both ways, in this process, and compares what the docs quote: the
return in Gymnasium on reset seeds 0-99, the simulated episodes to the first evaluation point
at or above the task's threshold, the update returned, how far the weights moved and how far
the simulated evaluation points moved (a task without a Gymnasium twin, the trebuchet, has no
Gymnasium return: the same update and weights are the same run).

    taskset -c 0 python benchmarks/compile_options.py
    taskset -c 0 python benchmarks/compile_options.py --tasks cartpole,pendulum:long-windows
    taskset -c 0 python benchmarks/compile_options.py --tasks none \
        --runs cartpole,cartpole:original --seeds 5 --out benchmarks/results/compile_options_runs.json

Writes benchmarks/results/compile_options.json (machine, date, every figure). The persistent
compilation cache is off in this process, so every compile is from scratch.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path

os.environ["DIFFCONTROL_NO_COMPILE_CACHE"] = "1"

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

WAYS = {
    "default": (),
    "level 1": ("xla_backend_optimization_level",),
    "older emitters": ("xla_cpu_use_fusion_emitters",),
    "both": ("xla_backend_optimization_level", "xla_cpu_use_fusion_emitters"),
}
XLA_DEFAULTS = {"xla_backend_optimization_level": 3, "xla_cpu_use_fusion_emitters": True}
"""XLA's own defaults, named: an ``XLA_FLAGS`` in the environment does not choose for them."""
OTHER_BITS = {("cartpole", "chunk"), ("trebuchet", "evaluate")}
"""Declared options that give other bits than XLA's defaults, chosen all the same: the whole
runs (``--runs``, on one core and on two) gave the same documented results
(docs/benchmarks.md)."""
OTHER_BITS_ONE_CORE = {("trebuchet", "evaluate")}
"""Of those, the programs whose one-core compilation (``ONE_CORE``) rounds differently again:
their whole runs were checked on one core and on two."""
TASKS = (
    "pendulum",
    "pendulum:original",
    "pendulum:long-windows",
    "pendulum:grid-value",
    "pendulum-unclipped",
    "pendulum-unclipped:original",
    "cartpole",
    "cartpole:original",
    "acrobot",
    "mountain-car-continuous",
    "mountain-car-continuous:grid-value",
    "trebuchet",
    "trebuchet:original",
    "cartpole-swingup",
    "cartpole-swingup:original",
    "cartpole-swingup-limited",
    "cartpole-swingup-limited:original",
    "cartpole-swingup-friction",
    "cartpole-swingup-friction:original",
)


def _digest(tree) -> str:
    import jax
    import numpy as np

    h = hashlib.sha256()
    for leaf in jax.tree_util.tree_leaves(tree):
        h.update(np.asarray(leaf).tobytes())
    return h.hexdigest()[:16]


def programs(spec: str, updates: int):
    """``(task, program, lowered, args)`` for the evaluation program and every stage's chunk of
    ``diffcontrol train TASK[ --recipe R]`` with its defaults."""
    import jax
    import numpy as np

    from diffcontrol.tasks import make
    from diffcontrol.training import _driver, _programs

    name, _, recipe = spec.partition(":")
    task = make(name)
    config = _driver.resolve_config(task, recipe or None)
    params = _driver.task_params(task, config.params)
    kept = _programs._kept_trainer(task, config, None, params, lambda line: None)
    ts, k_eval = _programs._first_state(kept, config.seed, params)
    args = (ts.controller, params, k_eval)
    yield task, "evaluate", jax.jit(kept.trainer.evaluate).lower(*args), args
    for i, (end, stage) in enumerate(kept.stages):
        args = (ts, params, np.int32(min(end, int(ts.update) + updates)))
        lowered = jax.jit(stage.chunk).lower(ts, params, np.int32(config.updates))
        yield task, f"chunk {i}" if len(kept.stages) > 1 else "chunk", lowered, args


def measure(spec: str, updates: int) -> list[dict]:
    import jax

    from diffcontrol._jax_setup import FAST_COMPILE, ONE_CORE
    from diffcontrol.training._programs import compile_options

    rows = []
    for task, program, lowered, args in programs(spec, updates):
        declared = compile_options(task, program.split()[0])
        options = {
            w: {**XLA_DEFAULTS, **{n: FAST_COMPILE[n] for n in names}} for w, names in WAYS.items()
        }
        if "xla_cpu_use_fusion_emitters" in declared:  # as a one-core process compiles it
            declared_options = {n: FAST_COMPILE[n] for n in declared}
            options["declared, one core"] = {**XLA_DEFAULTS, **declared_options, **ONE_CORE}
        ways = {}
        for way, chosen in options.items():
            t0 = time.perf_counter()
            compiled = lowered.compile(chosen)  # named in full: not the process's own choice
            compile_s = time.perf_counter() - t0
            jax.block_until_ready(compiled(*args))  # the first call may set things up
            t0 = time.perf_counter()
            out = jax.block_until_ready(compiled(*args))
            ways[way] = {"compile_s": compile_s, "run_s": time.perf_counter() - t0}
            ways[way]["digest"] = _digest(out)
        same = {w: v["digest"] == ways["default"]["digest"] for w, v in ways.items()}
        other_bits = (task.name, program.split()[0]) in OTHER_BITS
        as_declared = next((w for w, names in WAYS.items() if set(names) == set(declared)), None)
        one_core = ways.get("declared, one core", ways[as_declared])
        one_core_same = one_core["digest"] == ways[as_declared]["digest"]
        rows.append(
            {
                "task": spec,
                "program": program,
                "ways": ways,
                "same_bits": same,
                "declared": list(declared),
                "declared_keeps_bits": bool(as_declared and same[as_declared]),
                "declared_other_bits_by_choice": other_bits,
                "one_core_keeps_declared_bits": one_core_same,
            }
        )
        cells = "  ".join(
            f"{v['compile_s']:5.2f}/{v['run_s']:6.3f}{'=' if same[w] else 'x'}"
            for w, v in ways.items()
        ) + ("" if "declared, one core" in ways else " " * 16)
        note = " (other bits: --runs)" if other_bits else ""
        print(f"{spec:36s} {program:9s} {cells}  {as_declared or '?'}{note}", flush=True)
    return rows


def whole_runs(spec: str, seeds: int) -> list[dict]:
    """``diffcontrol.train`` of ``TASK[:RECIPE]`` for seeds 0..seeds-1, with the task's
    declared options (and ``ONE_CORE`` on one core) and with XLA's defaults for every program
    of the run but its start."""
    import jax
    import numpy as np

    import diffcontrol
    from diffcontrol import _jax_setup
    from diffcontrol.evaluation import evaluate
    from diffcontrol.policies import NumpyPolicy, model_document

    name, _, recipe = spec.partition(":")
    task = diffcontrol.make(name)
    declared = dict(vars(type(task)).get("fast_compile", {}))
    rows = []
    for seed in range(seeds):
        row = {"task": spec, "seed": seed}
        weights, curves = {}, {}
        for way, options in (("declared", declared), ("default", {})):
            type(task).fast_compile = options
            one_core = _jax_setup.ONE_CORE
            if way == "default":  # XLA's defaults on any number of cores
                _jax_setup.ONE_CORE = {}
            try:
                config = diffcontrol.training.resolve_config(task, recipe or None, seed=seed)
                t0 = time.perf_counter()
                result = diffcontrol.train(task, config, progress=lambda line: None)
                seconds = time.perf_counter() - t0
            finally:
                type(task).fast_compile, _jax_setup.ONE_CORE = declared, one_core
            threshold = task.reward_threshold
            if task.gym_id is not None or threshold is not None:
                doc = model_document(task, result.controller, result.config, result.metrics)
                ev = evaluate(NumpyPolicy(doc), task, episodes=100, seed=0)
                gym = {"gymnasium_return": ev.mean, "gymnasium_std": ev.std}
            else:  # no Gymnasium twin (the trebuchet): equal weights are equal results
                gym = {"gymnasium_return": float("nan"), "gymnasium_std": float("nan")}
            first = next(
                (
                    p["simulated_episodes"]
                    for p in result.curve
                    if threshold is not None and p["eval_return"] >= threshold
                ),
                None,
            )
            weights[way] = [np.asarray(x) for x in jax.tree.leaves(result.controller)]
            curves[way] = np.array([p["eval_return"] for p in result.curve])
            row[way] = {
                **gym,
                "episodes_to_threshold": first,
                "returned_update": result.metrics["returned_update"],
                "final_eval_return": result.metrics["final_eval_return"],
                "seconds": seconds,
                "compile_seconds": result.metrics["compile_seconds"],
            }
        pairs = zip(weights["declared"], weights["default"])
        row["weights_differing"] = int(sum(np.sum(a != b) for a, b in pairs))
        row["weights_max_difference"] = float(
            max(np.max(np.abs(a - b)) for a, b in zip(weights["declared"], weights["default"]))
        )
        # the simulated evaluation points: how far the declared options move them
        row["curve_max_difference"] = float(np.max(np.abs(curves["declared"] - curves["default"])))
        rows.append(row)
        d, o = row["declared"], row["default"]
        print(
            f"{spec:20s} seed {seed}  return {d['gymnasium_return']:8.2f} / {o['gymnasium_return']:8.2f}"
            f"  to threshold {d['episodes_to_threshold']} / {o['episodes_to_threshold']}"
            f"  returned {d['returned_update']} / {o['returned_update']}"
            f"  weights differing {row['weights_differing']} (max {row['weights_max_difference']:.2g})"
            f"  evaluation points moved by {row['curve_max_difference']:.2g}"
            f"  train s {d['seconds']:.2f} / {o['seconds']:.2f}",
            flush=True,
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--tasks", default=",".join(TASKS), help="TASK or TASK:RECIPE, comma-separated"
    )
    parser.add_argument("--updates", type=int, default=20, help="updates each chunk runs")
    parser.add_argument("--runs", default="", help="TASK[:RECIPE],...: whole runs both ways")
    parser.add_argument("--seeds", type=int, default=5, help="training seeds of --runs")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "compile_options.json")
    args = parser.parse_args()
    heads = [*WAYS, "declared+1 core"]
    print(f"{'task':36s} {'program':9s} " + "  ".join(f"{w:>14s}" for w in heads) + "  declared")
    print("  (each cell: compile s / run s, '=' the defaults' bits, 'x' other bits;")
    print("   'declared+1 core': the declared older emitters with _jax_setup.ONE_CORE)")
    specs = [] if args.tasks == "none" else args.tasks.split(",")
    rows = [r for spec in specs for r in measure(spec, args.updates)]
    bad = [
        f"{r['task']} {r['program']}"
        for r in rows
        if not (r["declared_keeps_bits"] or r["declared_other_bits_by_choice"])
        or not (
            r["one_core_keeps_declared_bits"]
            or (r["task"].split(":")[0], r["program"].split()[0]) in OTHER_BITS_ONE_CORE
        )
    ]
    print("declared options keep the bits everywhere" if not bad else f"NOT KEPT: {bad}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    runs = [r for spec in args.runs.split(",") if spec for r in whole_runs(spec, args.seeds)]
    if runs:
        print("  (each: with the declared options / with XLA's defaults)")
    doc = {"machine": machine(), "updates": args.updates, "ways": WAYS, "rows": rows, "runs": runs}
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
