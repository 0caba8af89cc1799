"""Screen of `acrobot`: evolution-strategies (OpenAI-ES) fine-tuning of the BPTT controller on
the true objective, the simulated Gymnasium return.

For each training seed: train with the task's defaults (`diffcontrol.train`), then run ES on
the controller's weights (the layers' weights and biases; the observation scaling is held):

- each iteration draws `pairs` antithetic Gaussian perturbations `theta +- sigma eps` (with
  `rel=1`, `eps` of each leaf scaled by that leaf's std in the BPTT controller) and `starts`
  Gymnasium starts (`task.reset`), common to every member of the iteration;
- every member runs every start in the task's simulator to the goal or 500 steps (the argmax
  head, Gymnasium's return: -1 per step, 0 on the goal step); a member's fitness is its mean
  return; the fitnesses are rank-shaped (centered ranks in [-0.5, 0.5]) and the estimate
  `g = sum_i (r+_i - r-_i) eps_i / (2 pairs sigma)` is ascended with Adam (`lr`);
  `wd` adds OpenAI-ES's L2 decay of the weights (coefficient on `-theta`);
  `alpha` > 0 mixes in the BPTT gradient of the `pump` loss (an alpha-order mix: the
  direction is `(1 - alpha) g / |g| + alpha gb / |gb|`, `gb` minus the pump loss's gradient
  over `bptt_batch` windows of `window` steps from states visited by the current weights);
- one iteration (population x starts x steps, a while loop that stops when every episode is
  done) is one jitted program;
- every `every` iterations the current weights are evaluated on `eval` simulated starts (a
  fixed key, not the training ones); the controller returned is the best of the BPTT start and
  every evaluated point, a point kept only if it beats the best so far by `margin`.

ES runs for `iters` iterations or until `budget` seconds of ES (compile included) have passed.
The returned controller is judged in Gymnasium's own `Acrobot-v1` on reset seeds 0-99
(`diffcontrol.evaluation`, NumPy alone on its `model.json` document).

    taskset -c 1 python benchmarks/acrobot_es.py --seeds 0 2
    taskset -c 1 python benchmarks/acrobot_es.py --seeds 0 2 --variant s01:sigma=0.01 \
        s02:sigma=0.02,lr=0.005

A `--variant` is `NAME:key=value,...` overriding `DEFAULTS`; several variants in one process
share the BPTT controller (its seconds counted in each) and, where shapes agree, the compiled
programs. The run on seeds 0-4, each in a fresh process:

    DIFFCONTROL_NO_COMPILE_CACHE=1 taskset -c 0 python benchmarks/acrobot_es.py --seeds S \
        --variant s02b45:budget=45,iters=1000 --out /tmp/es2/sS.json

(benchmarks/results/acrobot_es.json holds those five runs together; docs/benchmarks.md,
"Acrobot"). ES stops on its seconds, not its iterations, so how far it gets depends on the
machine and on what else runs: the iterations reached are in each row; a run to the same
iteration is the same run (the keys are fixed).

`seconds` is BPTT + ES (compile and the simulated evaluations included; Gymnasium's
evaluation left out). Writes benchmarks/results/acrobot_es.json (or `--out`).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import discrete_choice_steps  # noqa: E402

DEFAULTS = dict(
    sigma=0.02,  # perturbation std (absolute, or relative to each leaf's std with rel=1)
    rel=0,
    pairs=32,  # antithetic pairs per iteration (population 2 * pairs)
    starts=64,  # simulated starts per iteration, common to all members
    lr=3e-3,  # Adam learning rate
    wd=0.0,  # L2 decay coefficient
    iters=300,
    budget=40.0,  # seconds of ES at most (compile included)
    every=10,  # evaluate the current weights every this many iterations
    eval=1024,  # simulated starts of the keep-best evaluation
    margin=0.5,
    alpha=0.0,  # weight of the BPTT pump-loss direction (0: plain ES)
    window=40,
    bptt_batch=32,
    cap=500,  # steps of a fitness episode at most (its return then -cap); Gymnasium's 500
    last=0,  # 1: perturb and move only the output layer's weights and bias (the rest held)
)


def parse_variant(text: str) -> tuple[str, dict]:
    name, _, rest = text.partition(":")
    cfg = dict(DEFAULTS)
    for kv in filter(None, rest.split(",")):
        k, v = kv.split("=")
        cfg[k] = type(DEFAULTS[k])(v)
    return name or "default", cfg


def main() -> None:
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np
    import optax
    from jax.flatten_util import ravel_pytree

    import diffcontrol
    from diffcontrol import policies
    from diffcontrol.evaluation import evaluate

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 2])
    parser.add_argument("--variant", nargs="+", default=["default"])
    parser.add_argument("--out", default=str(HERE / "results" / "acrobot_es.json"))
    args = parser.parse_args()
    variants = [parse_variant(v) for v in args.variant]

    task = diffcontrol.make("acrobot")
    params = task.default_params()
    choice, step = discrete_choice_steps(task, params)
    horizon = task.episode_length
    pump = task.step_loss("pump")

    def with_theta(ctrl, unravel, theta):
        return eqx.tree_at(lambda c: c.layers, ctrl, unravel(theta))

    def returns(ctrl, unravel, thetas, starts, limit=horizon):
        """Gymnasium returns (M, N) of the controllers ``thetas`` (M, D) from ``starts`` (N, 4),
        stopping when every episode is done or after ``limit`` steps."""
        m, n = thetas.shape[0], starts.shape[0]

        def act(theta, s):
            c = with_theta(ctrl, unravel, theta)
            return jax.vmap(lambda x: choice(c, x))(s)

        def body(c):
            t, s, done, ret = c
            a = jax.vmap(act)(thetas, s)
            s2, r, d = jax.vmap(jax.vmap(step))(s, a)
            ret = ret + jnp.where(done, 0.0, r)
            s2 = jnp.where(done[..., None], s, s2)
            return t + 1, s2, done | d, ret

        s0 = jnp.broadcast_to(starts, (m, n, 4))
        init = (jnp.int32(0), s0, jnp.zeros((m, n), bool), jnp.zeros((m, n)))
        _, _, _, ret = jax.lax.while_loop(lambda c: (c[0] < limit) & ~jnp.all(c[2]), body, init)
        return ret

    @eqx.filter_jit
    def evaluate_theta(ctrl, unravel, theta, key, n):
        starts = jax.vmap(lambda k: task.reset(k, params))(jax.random.split(key, n))
        return returns(ctrl, unravel, theta[None], starts)[0].mean()

    def bptt_grad(ctrl, unravel, theta, key, batch, window):
        """Minus the gradient of the pump loss summed over ``window`` steps from ``batch`` states
        visited by the current controller (starts rolled a random 0-99 steps first)."""
        k1, k2 = jax.random.split(key)
        starts = jax.vmap(lambda k: task.reset(k, params))(jax.random.split(k1, batch))
        c0 = with_theta(ctrl, unravel, theta)
        pre = jax.random.randint(k2, (batch,), 0, 100)

        def warm(s, p):
            def b(i, x):
                return jnp.where(i < p, step(x, choice(c0, x))[0], x)

            return jax.lax.fori_loop(0, 100, b, s)

        s0 = jax.lax.stop_gradient(jax.vmap(warm)(starts, pre))

        def loss(th):
            c = with_theta(ctrl, unravel, th)

            def one(s):
                def b(x, _):
                    a = c(task.observe(x))
                    x2, r, _ = task.step(params, x, a)
                    return x2, pump(params, x, a, x2, r)

                _, ls = jax.lax.scan(b, s, None, length=window)
                return ls.sum()

            return jax.vmap(one)(s0).mean()

        return -jax.grad(loss)(theta)

    @eqx.filter_jit
    def es_iter(ctrl, unravel, theta, opt_state, key, scale, sigma, pairs, nstarts, lr, wd,
                alpha, batch, window, cap):  # fmt: skip
        ke, ks, kb = jax.random.split(key, 3)
        eps = jax.random.normal(ke, (pairs, theta.shape[0])) * scale
        starts = jax.vmap(lambda k: task.reset(k, params))(jax.random.split(ks, nstarts))
        thetas = jnp.concatenate([theta + sigma * eps, theta - sigma * eps])
        fit = returns(ctrl, unravel, thetas, starts, cap).mean(1)  # (2P,)
        ranks = jnp.argsort(jnp.argsort(fit)).astype(jnp.float32)
        shaped = ranks / (2 * pairs - 1) - 0.5
        unit = jnp.where(scale > 0, eps / jnp.where(scale > 0, scale, 1.0), 0.0)
        g = (shaped[:pairs] - shaped[pairs:]) @ unit / (2 * pairs * sigma)
        g = g * scale  # the search-space gradient back in weight units
        if alpha:
            gb = bptt_grad(ctrl, unravel, theta, kb, batch, window)
            g = (1 - alpha) * g / (jnp.linalg.norm(g) + 1e-12) + alpha * gb / (
                jnp.linalg.norm(gb) + 1e-12
            )
        g = g - wd * theta
        opt = optax.adam(lr)
        up, opt_state = opt.update(-g, opt_state, theta)
        return optax.apply_updates(theta, up), opt_state, fit.mean(), fit.max()

    def gym_return(ctrl, episodes=100) -> float:
        pol = policies.NumpyPolicy(policies.controller_to_dict(ctrl, task))
        return float(np.mean(evaluate(pol, task, episodes=episodes).returns))

    rows = []
    eval_key = jax.random.PRNGKey(987654)
    for seed in args.seeds:
        t_bptt = time.perf_counter()
        bptt = diffcontrol.train(task, task.default_config().replace(seed=seed)).controller
        bptt_s = time.perf_counter() - t_bptt
        bptt_gym = gym_return(bptt)
        print(f"seed {seed}: BPTT {bptt_s:.1f} s, Gymnasium 0-99 {bptt_gym:.2f}", flush=True)
        theta0, unravel = ravel_pytree(bptt.layers)
        leaves = jax.tree.leaves(bptt.layers)
        leaf_std = jnp.concatenate([jnp.full(l.size, jnp.std(l)) for l in leaves])
        for name, cfg in variants:
            t0 = time.perf_counter()
            scale = leaf_std if cfg["rel"] else jnp.ones_like(theta0)
            if cfg["last"]:  # the output layer is the last two leaves (weight, bias)
                n_last = sum(leaf.size for leaf in leaves[-2:])
                scale = scale.at[: theta0.size - n_last].set(0.0)
            best_sim = float(evaluate_theta(bptt, unravel, theta0, eval_key, cfg["eval"]))
            sim0 = best_sim
            best_theta, best_it = theta0, 0
            theta = theta0
            opt_state = optax.adam(cfg["lr"]).init(theta)
            key = jax.random.PRNGKey(10_000 + seed)
            hist = [{"iter": 0, "sim": sim0, "t": time.perf_counter() - t0}]
            print(f"  {name} iter 0 sim {sim0:.2f}", flush=True)
            it = 0
            while it < cfg["iters"] and time.perf_counter() - t0 < cfg["budget"]:
                key, k = jax.random.split(key)
                theta, opt_state, fmean, fmax = es_iter(
                    bptt, unravel, theta, opt_state, k, scale, cfg["sigma"], cfg["pairs"],
                    cfg["starts"], cfg["lr"], cfg["wd"], cfg["alpha"], cfg["bptt_batch"],
                    cfg["window"], cfg["cap"],
                )  # fmt: skip
                it += 1
                if it % cfg["every"] == 0:
                    sim = float(evaluate_theta(bptt, unravel, theta, eval_key, cfg["eval"]))
                    kept = sim > best_sim + cfg["margin"]
                    if kept:
                        best_sim, best_theta, best_it = sim, theta, it
                    el = time.perf_counter() - t0
                    hist.append({"iter": it, "sim": sim, "pop_mean": float(fmean), "t": el})
                    print(
                        f"  {name} iter {it:4d} t {el:5.1f} pop mean {float(fmean):7.2f} "
                        f"max {float(fmax):7.2f} sim {sim:7.2f} {'*' if kept else ''} "
                        f"|d| {float(jnp.linalg.norm(theta - theta0)):.3f}",
                        flush=True,
                    )
            es_s = time.perf_counter() - t0
            best = with_theta(bptt, unravel, best_theta)
            es_gym = gym_return(best) if best_it else bptt_gym
            row = {
                "variant": name, "config": cfg, "seed": seed, "bptt_seconds": bptt_s,
                "es_seconds": es_s, "seconds": bptt_s + es_s, "iters": it, "bptt_gym": bptt_gym,
                "es_gym": es_gym, "sim_before": sim0, "sim_after": best_sim, "best_iter": best_it,
                "curve": hist,
            }  # fmt: skip
            rows.append(row)
            print(
                f"RESULT {name} seed {seed}: gym0-99 bptt {bptt_gym:.2f} es {es_gym:.2f}; sim "
                f"{sim0:.2f} -> {best_sim:.2f} (iter {best_it}/{it}); seconds {bptt_s:.1f} + "
                f"{es_s:.1f} = {bptt_s + es_s:.1f}",
                flush=True,
            )
    print(
        f"\n{'variant':>12} {'seed':>4} {'bptt gym':>8} {'es gym':>7} {'sim0':>7} {'sim*':>7} "
        f"{'it*':>4} {'iters':>5} {'s':>5}"
    )
    for r in rows:
        print(
            f"{r['variant']:>12} {r['seed']:>4} {r['bptt_gym']:>8.2f} {r['es_gym']:>7.2f} "
            f"{r['sim_before']:>7.2f} {r['sim_after']:>7.2f} {r['best_iter']:>4} "
            f"{r['iters']:>5} {r['seconds']:>5.1f}"
        )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"runs": rows}, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
