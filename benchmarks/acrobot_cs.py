"""Screen of `acrobot`: cost-sensitive (advantage-weighted) distillation of the rollout policy,
i.e. classification-based approximate policy iteration (CS-API), from the BPTT controller.

For each training seed: train with the task's defaults (`diffcontrol.train`), then for
`--rounds` rounds:

- visit: run the current controller from `--starts` training starts (`task.reset`) and keep
  every state before the goal;
- Q: for each visited state and each of the three actions, the steps to the goal when taking
  the action and then following the current controller (capped at `--cap` steps), optionally
  averaged over `--perturb` small perturbations of the state (`--sigma` rad, 3x that in
  rad/s); all in one vmapped, jitted program (in fixed-size chunks);
- fit (warm start from the current controller, Adam): `--loss es` minimises the expected
  excess cost under the softened policy, `sum_a softmax(z/T)_a (Q_a - min Q)`; `--loss wce`
  is cross-entropy on `argmin Q` weighted by the gap `max Q - min Q` (`--loss ce`: unweighted,
  the earlier probe). Near-ties, where the action does not matter, contribute about nothing.
  `--beta` adds a trust region, cross-entropy to the old controller's softmax. The observation
  scaling is held fixed in the fit, as the controller's own call holds it;
- evaluate the new controller in the simulator on `--eval-episodes` starts (a fixed key, not
  the training ones).

The controller returned is the best of the BPTT start and every round by that simulated
evaluation, so it can never be worse there than the start. Every returned controller is then
judged in Gymnasium's own `Acrobot-v1` on reset seeds 0-99 (`diffcontrol.evaluation`,
NumPy alone on its `model.json` document), and with `--gym-1000` also on seeds 0-999.

    taskset -c 1 python benchmarks/acrobot_cs.py --seeds 0 2
    taskset -c 1 python benchmarks/acrobot_cs.py --seeds 0 2 --variant es:T=1 wce:rounds=3

A `--variant` is `NAME:key=value,key=value` overriding the defaults in `DEFAULTS`; several
variants in one process share the BPTT controller (its seconds are counted in each) and the
compiled programs (so only the first variant's seconds include compilation). A round is
kept only if its simulated return beats the best so far by `margin` (1.0 over 1024 episodes).
`diag=1` measures how much of Q's gap is signal: two independent perturbation-averaged Q
estimates A and B, the excess (steps, under B) of argmin A, of the controller's own action
and of a random one. Each row prints the held-out (20 %) and training excess of the old and
new controller's argmax under the (averaged) Q.

The variant run on seeds 0-4 (each in a fresh process, compile cache off):

    DIFFCONTROL_NO_COMPILE_CACHE=1 taskset -c 1 python benchmarks/acrobot_cs.py --seeds S \
        --variant wceb1:rounds=2,starts=128,perturb=8,sigma=0.02,loss=wce,beta=1 --gym-1000 `seconds` is
BPTT + visiting + Q + fits + simulated evaluations (Gymnasium's evaluation left out).
Writes benchmarks/results/acrobot_cs.json (or `--out`).
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
    loss="es",  # es | wce | ce
    T=1.0,  # softmax temperature of the es loss (logits / T)
    rounds=2,
    starts=256,  # training starts per round
    cap=200,  # rollout cap (steps)
    perturb=1,  # Q averaged over this many states: the state itself, then perturbations
    sigma=0.01,  # perturbation std (rad; 3x in rad/s)
    fit_steps=1500,
    minibatch=512,
    lr=1e-3,
    aggregate=0,  # 1: fit on every round's data so far (each with its own round's Q)
    eval_episodes=1024,
    margin=1.0,  # a round is kept only if its simulated return beats the best by this much
    beta=0.0,  # weight of the cross-entropy to the old controller's softmax (a trust region)
    diag=0,  # 1: also measure how much of Q's gap is signal (two independent Q estimates)
)
CHUNK = 4096
"""States per call of the Q program (the last chunk padded), so one compilation serves all."""


def parse_variant(text: str) -> tuple[str, dict]:
    name, _, rest = text.partition(":")
    cfg = dict(DEFAULTS)
    for kv in filter(None, rest.split(",")):
        k, v = kv.split("=")
        cfg[k] = type(DEFAULTS[k])(v) if not isinstance(DEFAULTS[k], str) else v
    return name or "default", cfg


def main() -> None:
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np
    import optax

    import diffcontrol
    from diffcontrol import policies
    from diffcontrol.evaluation import evaluate

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 2])
    parser.add_argument("--variant", nargs="+", default=["es"])
    parser.add_argument("--gym-1000", action="store_true")
    parser.add_argument("--out", default=str(HERE / "results" / "acrobot_cs.json"))
    args = parser.parse_args()
    variants = [parse_variant(v) for v in args.variant]

    task = diffcontrol.make("acrobot")
    params = task.default_params()
    n_actions = task.action_size

    choice, step = discrete_choice_steps(task, params)

    def steps_to_go(ctrl, state, cap):
        """Steps the controller takes from ``state`` to the goal (at most ``cap``)."""

        def body(c):
            s, n, _ = c
            s2, _, d = step(s, choice(ctrl, s))
            return s2, n + 1, d

        _, n, _ = jax.lax.while_loop(
            lambda c: (~c[2]) & (c[1] < cap), body, (state, jnp.int32(0), jnp.bool_(False))
        )
        return n

    @eqx.filter_jit
    def q_chunk(ctrl, states, cap):
        """Q (steps to the goal) of each state (..., 4) and action: (..., 3)."""

        def one(s, a):
            s2, _, d = step(s, a)
            return 1 + jnp.where(d, 0, steps_to_go(ctrl, s2, cap))

        flat = states.reshape(-1, 4)
        q = jax.vmap(lambda s: jax.vmap(lambda a: one(s, a))(jnp.arange(n_actions)))(flat)
        return q.reshape(states.shape[:-1] + (n_actions,))

    def q_values(ctrl, states, cap, perturb, sigma, key):
        """Q of each state (N, 4): (N, 3) float, averaged over perturbations."""
        n = states.shape[0]
        scale = jnp.asarray([1.0, 1.0, 3.0, 3.0])
        noise = sigma * scale * jax.random.normal(key, (n, perturb, 4))
        noise = noise.at[:, 0].set(0.0)  # the state itself first
        batch = states[:, None, :] + noise  # (N, K, 4)
        per = max(1, CHUNK // perturb)
        out = []
        for i in range(0, n, per):
            part = batch[i : i + per]
            pad = per - part.shape[0]
            if pad:
                part = jnp.concatenate([part, jnp.zeros((pad,) + part.shape[1:])])
            out.append(np.asarray(q_chunk(ctrl, part, cap))[: per - pad])
        return np.concatenate(out).astype(np.float32).mean(1)

    @eqx.filter_jit
    def rollouts(ctrl, key, n):
        """States the controller visits from ``n`` starts, time-major, with an alive mask,
        and each episode's return (-steps, Gymnasium's)."""
        starts = jax.vmap(lambda k: task.reset(k, params))(jax.random.split(key, n))

        def body(c, _):
            s, done = c
            s2, r, d = jax.vmap(lambda x: step(x, choice(ctrl, x)))(s)
            return (s2, done | d), (s, ~done, jnp.where(done, 0.0, r))

        _, (states, alive, rewards) = jax.lax.scan(
            body, (starts, jnp.zeros(n, bool)), None, length=task.episode_length
        )
        return states, alive, rewards.sum(0)

    def sim_return(ctrl, n) -> float:
        _, _, ret = rollouts(ctrl, jax.random.PRNGKey(12345), n)
        return float(ret.mean())

    @eqx.filter_jit
    def fit(ctrl, obs, qgap, key, loss_kind, temp, steps, minibatch, lr, beta):
        trained, fixed = eqx.partition(ctrl, eqx.is_inexact_array)
        opt = optax.adam(lr)
        gap = qgap.max(1)
        wmean = gap.mean() + 1e-6
        labels = jnp.argmin(qgap, 1)
        p_old = jax.nn.softmax(jax.vmap(lambda o: ctrl.logits(o))(obs))

        def loss(t, idx):
            c = eqx.combine(t, fixed)  # its logits hold the observation scaling: no gradient
            z = jax.vmap(lambda o: c.logits(o))(obs[idx])
            trust = beta * optax.softmax_cross_entropy(z, p_old[idx]).mean()
            if loss_kind == "es":
                p = jax.nn.softmax(z / temp)
                return (p * qgap[idx]).sum(1).mean() + trust
            ce = optax.softmax_cross_entropy_with_integer_labels(z, labels[idx])
            if loss_kind == "wce":
                return (gap[idx] * ce).mean() / wmean + trust
            return ce.mean() + trust

        def body(c, k):
            t, s = c
            l, g = jax.value_and_grad(loss)(t, jax.random.randint(k, (minibatch,), 0, obs.shape[0]))
            up, s = opt.update(g, s, t)
            return (optax.apply_updates(t, up), s), l

        (t, _), ls = jax.lax.scan(body, (trained, opt.init(trained)), jax.random.split(key, steps))
        jax.debug.print("fit loss first {a} last {b}", a=ls[:50].mean(), b=ls[-50:].mean())
        return eqx.combine(t, fixed)  # the scaling, without gradient, is the controller's

    def gym_return(ctrl, episodes=100) -> float:
        pol = policies.NumpyPolicy(policies.controller_to_dict(ctrl, task))
        return float(np.mean(evaluate(pol, task, episodes=episodes).returns))

    def pad_to(x, m):
        """Pad axis 0 of ``x`` up to a multiple of ``m`` by repeating rows (fixed shapes)."""
        n = x.shape[0]
        k = (-n) % m
        return np.concatenate([x, x[:k]]) if k else x

    rows = []
    print(
        f"{'variant':>14} {'seed':>4} {'round':>5} {'states':>6} {'tie%':>5} {'q s':>5} "
        f"{'fit s':>5} {'sim':>7} {'kept':>4}",
        flush=True,
    )
    for seed in args.seeds:
        t_bptt = time.perf_counter()
        bptt = diffcontrol.train(task, task.default_config().replace(seed=seed)).controller
        bptt_s = time.perf_counter() - t_bptt
        bptt_gym = gym_return(bptt)
        for name, cfg in variants:
            t0 = time.perf_counter()
            ctrl = bptt
            best, best_sim, best_round = bptt, sim_return(bptt, cfg["eval_episodes"]), 0
            hist = [{"round": 0, "sim": best_sim}]
            print(
                f"{name:>14} {seed:>4} {0:>5} {'':>6} {'':>5} {'':>5} {'':>5} {best_sim:>7.2f}",
                flush=True,
            )
            data_obs, data_q = [], []
            key = jax.random.PRNGKey(1000 + seed)
            for r in range(1, cfg["rounds"] + 1):
                key, kv, kq, kf = jax.random.split(key, 4)
                states, alive, _ = rollouts(ctrl, kv, cfg["starts"])
                states = np.asarray(states)[np.asarray(alive)]
                tq = time.perf_counter()
                q = q_values(
                    ctrl, jnp.asarray(states), cfg["cap"], cfg["perturb"], cfg["sigma"], kq
                )
                q_s = time.perf_counter() - tq
                qgap = q - q.min(1, keepdims=True)
                if cfg["diag"]:
                    sub = jnp.asarray(states[:3000])
                    own = np.asarray(jax.vmap(lambda x: choice(ctrl, x))(sub))  # noqa: B023
                    qa = q_values(ctrl, sub, cfg["cap"], cfg["perturb"], cfg["sigma"], kq)
                    qb = q_values(
                        ctrl,
                        sub,
                        cfg["cap"],
                        cfg["perturb"],
                        cfg["sigma"],
                        jax.random.fold_in(kq, 7),
                    )
                    if cfg["perturb"] > 1:  # independent perturbations for qa too
                        qa = q_values(
                            ctrl,
                            sub + 0.0,
                            cfg["cap"],
                            cfg["perturb"],
                            cfg["sigma"],
                            jax.random.fold_in(kq, 8),
                        )
                    gb = qb - qb.min(1, keepdims=True)
                    pick = lambda a: float(np.take_along_axis(gb, a[:, None], 1).mean())  # noqa: B023, E731
                    rng = np.random.default_rng(0)
                    print(
                        f"  DIAG excess under B of: argmin A {pick(qa.argmin(1)):.2f}, own "
                        f"{pick(own):.2f}, random {pick(rng.integers(0, 3, len(own))):.2f}, "
                        f"argmin B {pick(qb.argmin(1)):.2f}; corr(A,B) of Q-mean(Q) "
                        f"{np.corrcoef((qa - qa.mean(1, keepdims=True)).ravel(), (qb - qb.mean(1, keepdims=True)).ravel())[0, 1]:.2f}",
                        flush=True,
                    )
                tie = float(np.mean(qgap.max(1) < 0.5))
                obs = np.asarray(jax.vmap(task.observe)(jnp.asarray(states)))
                if cfg["aggregate"]:
                    data_obs.append(obs)
                    data_q.append(qgap)
                    obs, qgap = np.concatenate(data_obs), np.concatenate(data_q)
                perm = np.random.default_rng(seed * 100 + r).permutation(len(obs))
                obs, qgap = obs[perm], qgap[perm]
                cut = int(0.8 * len(obs))
                ho_obs, ho_q = jnp.asarray(obs[cut:]), qgap[cut:]
                obs, qgap = pad_to(obs[:cut], 8192), pad_to(qgap[:cut], 8192)
                old_ctrl = ctrl
                tf = time.perf_counter()
                ctrl = fit(
                    ctrl, jnp.asarray(obs), jnp.asarray(qgap), kf, cfg["loss"], cfg["T"],
                    cfg["fit_steps"], cfg["minibatch"], cfg["lr"], cfg["beta"],
                )  # fmt: skip
                fit_s = time.perf_counter() - tf
                excess = []
                for c in (old_ctrl, ctrl):
                    a = np.asarray(jax.vmap(lambda o: jnp.argmax(c.logits(o)))(ho_obs))  # noqa: B023
                    excess.append(float(np.take_along_axis(ho_q, a[:, None], 1).mean()))
                tr_obs, tr_q = jnp.asarray(obs[:4096]), qgap[:4096]
                for c in (old_ctrl, ctrl):
                    a = np.asarray(jax.vmap(lambda o: jnp.argmax(c.logits(o)))(tr_obs))  # noqa: B023
                    excess.append(float(np.take_along_axis(tr_q, a[:, None], 1).mean()))
                z = np.asarray(jax.vmap(lambda o: old_ctrl.logits(o))(tr_obs))  # noqa: B023
                excess.append(float(np.mean(z.max(1) - np.median(z, 1))))
                sim = sim_return(ctrl, cfg["eval_episodes"])
                kept = sim > best_sim + cfg["margin"]
                if kept:
                    best, best_sim, best_round = ctrl, sim, r
                hist.append({"round": r, "states": int(len(states)), "tie": tie, "sim": sim,
                             "q_seconds": q_s, "fit_seconds": fit_s,
                             "heldout_excess_old": excess[0], "heldout_excess_new": excess[1],
                             "mean_gap": float(ho_q.max(1).mean())})  # fmt: skip
                print(
                    f"{name:>14} {seed:>4} {r:>5} {len(states):>6} {100 * tie:>5.1f} {q_s:>5.1f} "
                    f"{fit_s:>5.1f} {sim:>7.2f} {'*' if kept else '':>4} excess old {excess[0]:.2f} "
                    f"new {excess[1]:.2f} train old {excess[2]:.2f} new {excess[3]:.2f} "
                    f"logit margin {excess[4]:.1f} gap {ho_q.max(1).mean():.2f}",
                    flush=True,
                )
            seconds = bptt_s + time.perf_counter() - t0
            row = {
                "variant": name,
                "config": cfg,
                "seed": seed,
                "bptt_seconds": bptt_s,
                "seconds": seconds,
                "bptt_gym": bptt_gym,
                "best_round": best_round,
                "sim": best_sim,
                "gym_0_99": gym_return(best) if best_round else bptt_gym,
                "rounds": hist,
            }
            # Gymnasium returns of every round's controller are not measured (only the kept one).
            if args.gym_1000:
                row["gym_0_999"] = gym_return(best, 1000)
            rows.append(row)
            print(
                f"RESULT {name} seed {seed}: gym0-99 {row['gym_0_99']:.2f} (bptt {bptt_gym:.2f}) "
                f"sim {best_sim:.2f} round {best_round} seconds {seconds:.1f}"
                + (f" gym0-999 {row['gym_0_999']:.2f}" if args.gym_1000 else ""),
                flush=True,
            )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"runs": rows}, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
