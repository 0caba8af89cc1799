"""Benchmark of the neural-ODE cart-pole swing-up (the second seed post) and its gradients.

Each training run is the real command line, `diffcontrol train TASK --out DIR --seed S`, in a
fresh process pinned to one core (`taskset -c 0`) with the persistent compilation cache off,
so the times include compiling everything. Every figure of a trained controller comes from
the run's reference solve (float64, dopri8 at 1e-9, 100 Hz; `metrics.json` "swingup"): the
end state at the horizon, the peak |F| on the 100 Hz grid, the swings (pole reversals before
it first comes within 0.1 rad of upright).

Parts (`--parts`, default all):

- `swingup`: `cartpole-swingup` defaults; the bar is |wrap theta| < 0.1 rad and |x_dot| < 0.5
  m/s at t = 1 s, trained in under 20 s wall-clock on one core including compilation.
- `limited`: `cartpole-swingup-limited` defaults; the bar is |wrap theta| < 0.1 rad and
  |theta_dot| < 0.5 rad/s at t = 10 s, with a peak |F| at least 5x below the swing-up's.
- `limited_post`: the same with the post's own loss (`--loss limited`), 3 seeds.
- `friction`: `cartpole-swingup-friction` with its energy loss and with the plain swing-up
  loss: the energy dissipated by friction, and the end state.
- `gradients`: the three gradient methods on the 1 s and 10 s closed loops of a 3-8-1
  controller trained for 300 updates: compile time, time and memory per gradient (XLA's temporary buffers of
  the compiled gradient) at the training settings (float32, rtol 1e-3, atol 1e-6), and the
  error of the directional derivatives against central finite differences of a float64 solve
  at rtol = atol = 1e-10: at the training settings, in float32 at rtol 1e-5 / atol 1e-8, and
  in float64 at the tight settings.

    taskset -c 0 python benchmarks/swingup.py
    taskset -c 0 python benchmarks/swingup.py --parts gradients

Prints tables and writes benchmarks/results/swingup.json (machine, date, every figure).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, train_cli  # noqa: E402

PARTS = ("swingup", "limited", "limited_post", "friction", "gradients")


def train_rows(task: str, seeds: int, extra: list[str], label: str, tmp: Path) -> list[dict]:
    rows = []
    for seed in range(seeds):
        m, process_s = train_cli(task, seed, tmp / f"{task}-{label}-{seed}", extra)
        s = m["swingup"]
        row = {
            "task": task,
            "variant": label,
            "seed": seed,
            "process_seconds": process_s,
            "train_seconds": m["train_seconds"],
            "compile_seconds": m["compile_seconds"],
            "solves": m["simulated_episodes"],
            "solver_steps": m["simulated_steps"],
            "population": m["config"]["population"],
            **{k: s[k] for k in s if k != "task"},
        }
        rows.append(row)
        print(
            f"{task:<26} {label:<10} {seed:>4} {process_s:>7.1f} {m['train_seconds']:>7.1f} "
            f"{m['compile_seconds']:>7.1f} {abs(s['final_theta']):>8.4f} "
            f"{s['final_theta_dot']:>+7.3f} {s['final_x_dot']:>+7.3f} {s['peak_force']:>7.1f} "
            f"{s['swings']:>6} {s['dissipated_energy']:>8.2f}",
            flush=True,
        )
    return rows


def header() -> None:
    line = (
        f"{'task':<26} {'variant':<10} {'seed':>4} {'proc s':>7} {'train s':>7} {'comp s':>7} "
        f"{'|theta|':>8} {'th_dot':>7} {'x_dot':>7} {'peak F':>7} {'swings':>6} {'E_fric J':>8}"
    )
    print(line)
    print("-" * len(line))


def _trained(task, seed: int, updates: int = 300):
    """A controller trained briefly with the task's defaults.

    Not an untrained one: that leaves the pole near hanging down, where the loss's
    ``wrap(theta)`` flips the sign of ``d theta^2 / d theta`` (its slope jumps at +-pi), so
    a float32 trajectory a hair on the other side of pi than the float64 reference would
    measure the wrap, not the gradient method.
    """
    import diffcontrol

    config = task.default_config().replace(updates=updates, seed=seed, population=1)
    return diffcontrol.train(task, config).controller


def _loss_of_weights(task, controller, gradient: str, tight: bool, **tolerances):
    """``controller``'s loss as a function of its layers, and those layers.

    ``tight``: float64 at rtol = atol = 1e-10; else float32 at the training settings, or at
    ``tolerances`` (rtol, atol) where given.
    """
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from diffcontrol.training import make_ode_trainer

    tol = dict(rtol=1e-10, atol=1e-10, max_steps=100_000) if tight else dict(tolerances)
    cfg = task.default_config().replace(gradient=gradient, **tol)
    trainer = make_ode_trainer(task, cfg)
    dtype = jnp.float64 if tight else jnp.float32

    def cast(tree):
        return jax.tree.map(lambda x: jnp.asarray(x, dtype), tree)

    params = cast(task.default_params())
    ctrl = cast(controller)
    spec = jax.tree.map(lambda _: False, ctrl)
    spec = eqx.tree_at(lambda c: c.layers, spec, replace=jax.tree.map(lambda _: True, ctrl.layers))
    diff, static = eqx.partition(ctrl, spec)
    horizon = jnp.asarray(cfg.horizon_s, dtype)

    def loss(d):
        value, (ok, _, steps) = trainer.member_loss(eqx.combine(d, static), params, horizon)
        return value, (ok, steps)

    return loss, diff


def _fd_reference(task, controller, directions: int = 3):
    """Unit directions in weight space and the float64 central differences (1e-10) along them."""
    import jax

    with jax.enable_x64(True):
        loss, diff = _loss_of_weights(task, controller, "checkpoint", True)
        x0, unravel = jax.flatten_util.ravel_pytree(diff)
        dirs = np.random.default_rng(0).normal(size=(directions, x0.size))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        f = jax.jit(lambda d: loss(d)[0])
        fd = [float(f(unravel(x0 + 1e-6 * d)) - f(unravel(x0 - 1e-6 * d))) / 2e-6 for d in dirs]
    return dirs, np.asarray(fd)


def _fd_error(grad, dirs: np.ndarray, fd: np.ndarray) -> float:
    """Largest error of the directional derivatives, relative to the FD gradient's size."""
    import jax

    flat = np.asarray(jax.flatten_util.ravel_pytree(grad)[0], np.float64)
    return float(np.max(np.abs(dirs @ flat - fd)) / np.linalg.norm(fd))


def gradient_table(seed: int = 0) -> list[dict]:
    """Time, memory and accuracy of the three gradient methods (see the module docstring)."""
    import equinox as eqx
    import jax

    import diffcontrol
    from diffcontrol import rollout

    rows = []
    for task_name in ("cartpole-swingup", "cartpole-swingup-limited"):
        task = diffcontrol.make(task_name)
        controller = _trained(task, seed)
        dirs, fd = _fd_reference(task, controller)
        for gradient in ("checkpoint", "backsolve", "forward"):
            loss, diff = _loss_of_weights(task, controller, gradient, False)
            t0 = time.perf_counter()
            vg = rollout.value_and_grad(loss, gradient)
            compiled = jax.jit(lambda d, vg=vg: vg(d)).lower(diff).compile()
            compile_s = time.perf_counter() - t0
            memory = compiled.memory_analysis()
            (_, (ok, steps)), grad = compiled(diff)
            times = []
            for _ in range(30):
                t0 = time.perf_counter()
                jax.block_until_ready(compiled(diff))
                times.append(time.perf_counter() - t0)
            loss_5, diff_5 = _loss_of_weights(
                task, controller, gradient, False, rtol=1e-5, atol=1e-8
            )
            _, grad_5 = eqx.filter_jit(rollout.value_and_grad(loss_5, gradient))(diff_5)
            with jax.enable_x64(True):
                loss_t, diff_t = _loss_of_weights(task, controller, gradient, True)
                _, grad_t = eqx.filter_jit(rollout.value_and_grad(loss_t, gradient))(diff_t)
                error_tight = _fd_error(grad_t, dirs, fd)
            row = {
                "task": task_name,
                "horizon_s": task.default_config().horizon_s,
                "gradient": gradient,
                "ok": bool(ok),
                "solver_steps": int(steps),
                "compile_seconds": compile_s,
                "ms_per_gradient": 1e3 * statistics.median(times),
                "temp_bytes": getattr(memory, "temp_size_in_bytes", None),
                "error_vs_fd_training_settings": _fd_error(grad, dirs, fd),
                "error_vs_fd_rtol_1e-5": _fd_error(grad_5, dirs, fd),
                "error_vs_fd_tight_float64": error_tight,
            }
            rows.append(row)
            print(
                f"{task_name:<26} {gradient:<11} {row['solver_steps']:>6} {compile_s:>7.1f} "
                f"{row['ms_per_gradient']:>8.2f} {(row['temp_bytes'] or 0) / 1024:>9.1f} "
                f"{row['error_vs_fd_training_settings']:>10.2e} "
                f"{row['error_vs_fd_rtol_1e-5']:>10.2e} {error_tight:>10.2e}",
                flush=True,
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--parts", default=",".join(PARTS), help=f"comma-separated: {PARTS}")
    parser.add_argument("--seeds", type=int, default=5, help="training seeds (default 5)")
    parser.add_argument(
        "--limited-seeds", type=int, default=3, help="seeds of the 10 s variants (default 3)"
    )
    parser.add_argument("--out", type=Path, default=HERE / "results" / "swingup.json")
    args = parser.parse_args()
    parts = args.parts.split(",")
    unknown = set(parts) - set(PARTS)
    if unknown:
        parser.error(f"unknown parts {sorted(unknown)}; choose from {PARTS}")

    result: dict = {"machine": machine(), "runs": [], "gradients": []}
    if args.out.exists():  # keep the parts not rerun
        old = json.loads(args.out.read_text())
        result["runs"] = [r for r in old.get("runs", []) if r["part"] not in parts]
        result["gradients"] = [] if "gradients" in parts else old.get("gradients", [])
    no_anim = ["--no-animation"]
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        if set(parts) & {"swingup", "limited", "limited_post", "friction"}:
            header()
        plan = {
            "swingup": [("cartpole-swingup", args.seeds, no_anim, "defaults")],
            "limited": [("cartpole-swingup-limited", args.limited_seeds, no_anim, "defaults")],
            "limited_post": [
                ("cartpole-swingup-limited", 3, [*no_anim, "--loss", "limited"], "post-loss")
            ],
            "friction": [
                ("cartpole-swingup-friction", args.seeds, no_anim, "energy"),
                (
                    "cartpole-swingup-friction",
                    args.seeds,
                    [*no_anim, "--loss", "swingup"],
                    "no-energy",
                ),
            ],
        }
        for part in parts:
            for task, seeds, extra, label in plan.get(part, []):
                for row in train_rows(task, seeds, extra, label, tmp):
                    result["runs"].append({"part": part, **row})
    if "gradients" in parts:
        print(
            f"\n{'closed loop':<26} {'method':<11} {'steps':>6} {'comp s':>7} {'ms/grad':>8} "
            f"{'temp KiB':>9} {'err train':>10} {'err 1e-5':>10} {'err tight':>10}"
        )
        result["gradients"] = gradient_table()

    summary = {}
    for part in ("swingup", "limited", "limited_post", "friction"):
        for label in sorted({r["variant"] for r in result["runs"] if r["part"] == part}):
            group = [r for r in result["runs"] if r["part"] == part and r["variant"] == label]
            summary[f"{part}/{label}"] = {
                "seeds": len(group),
                "median_process_seconds": statistics.median(r["process_seconds"] for r in group),
                "max_process_seconds": max(r["process_seconds"] for r in group),
                "median_peak_force": statistics.median(r["peak_force"] for r in group),
                "median_abs_final_theta": statistics.median(abs(r["final_theta"]) for r in group),
                "median_dissipated_energy": statistics.median(
                    r["dissipated_energy"] for r in group
                ),
            }
    if "swingup/defaults" in summary and "limited/defaults" in summary:
        ratio = summary["swingup/defaults"]["median_peak_force"] / max(
            summary["limited/defaults"]["median_peak_force"], 1e-9
        )
        summary["peak_force_ratio_swingup_over_limited"] = ratio
        print(f"\npeak |F| ratio, swing-up / limited (medians): {ratio:.1f}x")
    result["summary"] = summary
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
