"""Probe of `acrobot`: can one step of policy iteration (Bertsekas' rollout algorithm) with the
exact simulator, distilled back into the network, lift the BPTT controller to the -80 bar?

For each training seed: train with the task's defaults (`diffcontrol.train`, the controller
that `benchmarks/acrobot.py` measures), then

- the *rollout policy* (the teacher): in a state, try each of the three actions, follow the
  trained controller after it for up to `CAP` steps in the simulator and take the action with
  the highest return (ties: the controller's own choice). For deterministic dynamics its
  return is at least the controller's from every state (Bertsekas, "Rollout algorithms",
  2005). It is a planner: it needs the simulator at every step (three rollouts per step);
- *distillation* (one DAgger round): the states the controller visits from `STARTS` training
  starts, labelled by the teacher, fitted by cross-entropy (Adam, warm start from the
  controller), exported as `model.json` is;
- *learnability*: how often a state's teacher label survives a perturbation of the state
  (`EPS`), and the held-out accuracy of the fit (30 % of the labelled states held out),
  against how often the controller already agrees with the teacher.

Every policy is judged in Gymnasium's own `Acrobot-v1` on reset seeds 0-99 (the teacher reads
the state back from the observation, `task.state_from_observation`).

    taskset -c 0 python benchmarks/acrobot_rollout.py            # training seeds 0-4
    taskset -c 0 python benchmarks/acrobot_rollout.py --seeds 2

Prints a table and writes benchmarks/results/acrobot_rollout.json. Seconds are wall clock on
a possibly shared machine (inflated by other processes' load, never the returns).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import discrete_choice_steps, machine  # noqa: E402

from diffcontrol import _gym  # noqa: E402

CAP = 300
"""Steps a teacher rollout follows the controller before it is cut off (return -CAP)."""
STARTS = 256
"""Training starts (``task.reset``) whose visited states the teacher labels."""
FIT_STEPS, MINIBATCH, LEARNING_RATE = 2000, 256, 1e-3
"""The distillation fit: Adam on minibatches of the labelled states."""
EPS = (1e-4, 1e-3, 1e-2)
"""Standard deviations (rad, and 3x that in rad/s) of the state perturbations of the label
stability check."""


def main() -> None:
    import equinox as eqx
    import gymnasium
    import jax
    import jax.numpy as jnp
    import numpy as np
    import optax

    import diffcontrol
    from diffcontrol import policies
    from diffcontrol.evaluation import evaluate

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    args = parser.parse_args()
    task = diffcontrol.make("acrobot")
    params = task.default_params()
    n_actions = task.action_size

    choice, step = discrete_choice_steps(task, params)

    def return_to_go(ctrl, state):
        """The controller's return from ``state`` over at most CAP steps (to its ``done``)."""

        def body(c):
            s, n, total, _ = c
            s2, r, d = step(s, choice(ctrl, s))
            return s2, n + 1, total + r, d

        _, _, total, _ = jax.lax.while_loop(
            lambda c: (~c[3]) & (c[1] < CAP), body, (state, 0, jnp.float32(0), jnp.bool_(False))
        )
        return total

    def q_values(ctrl, state):
        def one(a):
            s2, r, d = step(state, a)
            return r + jnp.where(d, 0.0, return_to_go(ctrl, s2))

        return jax.vmap(one)(jnp.arange(n_actions))

    @eqx.filter_jit
    def teacher(ctrl, states):
        q = jax.vmap(lambda s: q_values(ctrl, s))(states)
        own = jax.vmap(lambda s: choice(ctrl, s))(states)
        own_q = jnp.take_along_axis(q, own[:, None], 1)[:, 0]
        return jnp.where(own_q >= q.max(1), own, q.argmax(1)), own

    @eqx.filter_jit
    def visited(ctrl, key):
        starts = jax.vmap(lambda k: task.reset(k, params))(jax.random.split(key, STARTS))

        def body(c, _):
            s, done = c
            s2, _, d = jax.vmap(lambda x: step(x, choice(ctrl, x)))(s)
            return (s2, done | d), (s, ~done)

        init = (starts, jnp.zeros(STARTS, bool))
        _, (states, alive) = jax.lax.scan(body, init, None, length=task.episode_length)
        return states.reshape(-1, states.shape[-1]), alive.reshape(-1)

    @eqx.filter_jit
    def fit(ctrl, states, labels, key):
        trained, fixed = eqx.partition(ctrl, eqx.is_inexact_array)
        opt = optax.adam(LEARNING_RATE)
        obs = jax.vmap(task.observe)(states)

        def loss(t, idx):
            c = eqx.combine(t, fixed)
            z = jax.vmap(lambda o: c.logits(o))(obs[idx])
            return optax.softmax_cross_entropy_with_integer_labels(z, labels[idx]).mean()

        def body(c, k):
            t, s = c
            g = jax.grad(loss)(t, jax.random.randint(k, (MINIBATCH,), 0, states.shape[0]))
            up, s = opt.update(g, s, t)
            return (optax.apply_updates(t, up), s), None

        keys = jax.random.split(key, FIT_STEPS)
        (t, _), _ = jax.lax.scan(body, (trained, opt.init(trained)), keys)
        return eqx.combine(t, fixed)  # the scaling had no gradient: it is the controller's

    def gym_return(ctrl) -> float:
        return float(
            np.mean(
                evaluate(
                    policies.NumpyPolicy(policies.controller_to_dict(ctrl, task)), task
                ).returns
            )
        )

    def teacher_gym(ctrl) -> tuple[float, float, float]:
        """Mean and worst return of the rollout policy on seeds 0-99, and ms per step."""
        env = gymnasium.make(task.gym_id)
        one = jax.jit(lambda c, o: teacher(c, _gym.state_from_observation(task, o)[None])[0][0])
        returns, steps, t0 = [], 0, None
        for seed in range(100):
            obs, _ = env.reset(seed=seed)
            total, done = 0.0, False
            while not done:
                a = int(one(ctrl, np.asarray(obs, np.float32)))
                t0 = t0 or time.perf_counter()  # after the first call: compilation left out
                obs, r, terminated, truncated, _ = env.step(a)
                total, steps, done = total + r, steps + 1, terminated or truncated
            returns.append(total)
        env.close()
        return (
            float(np.mean(returns)),
            float(min(returns)),
            1000 * (time.perf_counter() - t0) / steps,
        )

    rows = []
    head = (
        f"{'seed':>4} {'bptt s':>6} {'bptt':>7} {'teacher':>7} {'worst':>5} {'ms/step':>7} "
        f"{'relabel':>7} "
        + " ".join(f"{'kept@' + format(e, '.0e'):>9}" for e in EPS)
        + f" {'ctrl acc':>8} {'fit acc':>7} {'distilled':>9} {'distil s':>8}"
    )
    print(head)
    for seed in args.seeds:
        t0 = time.perf_counter()
        ctrl = diffcontrol.train(task, task.default_config().replace(seed=seed)).controller
        bptt_s = time.perf_counter() - t0
        bptt = gym_return(ctrl)
        planner, worst, ms = teacher_gym(ctrl)

        t1 = time.perf_counter()
        k_states, k_fit, k_eps = jax.random.split(jax.random.PRNGKey(seed), 3)
        states, alive = visited(ctrl, k_states)
        states = np.asarray(states)[np.asarray(alive)]  # time-major: shuffled for the split
        states = jnp.asarray(np.random.default_rng(seed).permutation(states))
        labels, own = (np.asarray(x) for x in teacher(ctrl, states))
        cut = int(0.7 * len(labels))
        student = fit(ctrl, states[:cut], jnp.asarray(labels[:cut]), k_fit)
        distil_s = time.perf_counter() - t1
        pred = np.asarray(jax.vmap(choice, in_axes=(None, 0))(student, states[cut:]))

        sample = states[:2000]
        scale = jnp.asarray([1.0, 1.0, 3.0, 3.0])
        kept = []
        for e in EPS:
            noise = e * scale * jax.random.normal(k_eps, sample.shape)
            kept.append(
                float(np.mean(np.asarray(teacher(ctrl, sample + noise)[0]) == labels[:2000]))
            )
        row = {
            "seed": seed,
            "bptt_seconds": bptt_s,
            "bptt_return": bptt,
            "teacher_return": planner,
            "teacher_worst": worst,
            "teacher_ms_per_step": ms,
            "labelled_states": len(labels),
            "relabelled": float(np.mean(labels != own)),
            "label_kept": dict(zip(map(str, EPS), kept)),
            "controller_agrees_heldout": float(np.mean(own[cut:] == labels[cut:])),
            "fit_accuracy_heldout": float(np.mean(pred == labels[cut:])),
            "distilled_return": gym_return(student),
            "distil_seconds": distil_s,
        }
        rows.append(row)
        print(
            f"{seed:>4} {bptt_s:>6.1f} {bptt:>7.2f} {planner:>7.2f} {worst:>5.0f} {ms:>7.2f} "
            f"{row['relabelled']:>7.2f} "
            + " ".join(f"{k:>9.2f}" for k in kept)
            + f" {row['controller_agrees_heldout']:>8.2f} {row['fit_accuracy_heldout']:>7.2f} "
            f"{row['distilled_return']:>9.2f} {distil_s:>8.1f}",
            flush=True,
        )
    out = HERE / "results" / "acrobot_rollout.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "machine": machine(),
        "settings": {
            "cap": CAP,
            "starts": STARTS,
            "fit_steps": FIT_STEPS,
            "minibatch": MINIBATCH,
            "learning_rate": LEARNING_RATE,
            "eval_seeds": "0-99",
        },
        "runs": rows,
        "summary": {
            "worst_teacher": min(r["teacher_return"] for r in rows),
            "worst_distilled": min(r["distilled_return"] for r in rows),
            "median_distilled": statistics.median(r["distilled_return"] for r in rows),
        },
    }
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
