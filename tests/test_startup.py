"""Start-up: the command line's help and the package's import do not import JAX, the public
names are still there when used, and the programs that run once compile faster and keep their
results (the start's bits, the reference solve's loss and the drawn throw to rounding)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from diffcontrol.tasks import controller_kwargs

HEAVY = ("jax", "equinox", "diffrax", "matplotlib", "imageio", "stable_baselines3", "torch")
COMMANDS = (
    "list",
    "train",
    "plan",
    "evaluate",
    "animate",
    "aim",
    "compare",
    "record",
    "fit",
    "loop",
)


def _imported_after(code: str) -> set[str]:
    """The heavy top-level modules imported in a fresh interpreter after running ``code``."""
    probe = f"{code}\nimport sys\nprint(sorted({{m.split('.')[0] for m in sys.modules}}))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    return set(eval(out.strip().splitlines()[-1])) & set(HEAVY)  # noqa: S307 (our own print)


def test_import_and_every_help_without_jax():
    code = (
        "import contextlib, io\n"
        "import diffcontrol\n"
        "from diffcontrol.cli import main\n"
        f"for argv in [['--help'], *[[c, '--help'] for c in {COMMANDS!r}]]:\n"
        "    with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "        try:\n"
        "            main(argv)\n"
        "        except SystemExit as e:\n"
        "            assert e.code == 0, (argv, e.code)\n"
        "    assert 'usage:' in out.getvalue(), argv\n"
    )
    assert _imported_after(code) == set()


def test_gymnasium_ids_registered_by_import_without_jax():
    code = (
        "import diffcontrol, gymnasium\n"
        "assert 'diffcontrol/CartPole-v0' in gymnasium.registry\n"
        "assert 'diffcontrol/PendulumFriction-v0' in gymnasium.registry\n"
    )
    assert _imported_after(code) == set()


def test_public_names_load_when_used():
    import diffcontrol

    for name in diffcontrol.__all__:
        assert getattr(diffcontrol, name) is not None, name
    from diffcontrol import TrainConfig, envs, make, train  # noqa: F401

    assert make("cartpole").name == "cartpole"
    assert diffcontrol.tasks.make("pendulum").name == "pendulum"  # a submodule, when used
    with pytest.raises(AttributeError):
        diffcontrol.no_such_name  # noqa: B018


def test_a_submodule_is_an_attribute_in_a_fresh_interpreter():
    """``diffcontrol.controllers`` after a bare ``import diffcontrol``, where nothing else has
    imported ``importlib.util`` (``help(diffcontrol.controllers)`` reads the attribute)."""
    code = (
        "import diffcontrol\n"
        "assert diffcontrol.controllers.MLPController is diffcontrol.MLPController\n"
        "assert diffcontrol.envs.__name__ == 'diffcontrol.envs'\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_builtin_gymnasium_ids_match_the_tasks():
    """The ids registered without JAX at import are those the tasks themselves give."""
    import gymnasium

    from diffcontrol import _registry, envs, tasks

    ids = set(envs.register_all())
    for row in _registry.BUILTIN:
        task = tasks.make(row.name)
        assert f"{type(task).__module__}:{type(task).__qualname__}" == row.path
        env_id = envs.env_id(task)
        assert env_id == f"diffcontrol/{row.env_name}-v0" and env_id in ids
        spec = gymnasium.registry[env_id]
        assert (spec.entry_point, spec.kwargs, spec.max_episode_steps, spec.reward_threshold) == (
            f"diffcontrol.envs:{row.env}",
            {"task": row.name},
            row.steps,
            row.threshold,
        ), env_id


def test_list_without_jax_names_every_builtin_task():
    code = (
        "import contextlib, io\n"
        "from diffcontrol.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "    assert main(['list']) == 0\n"
        "names = [line.split()[0] for line in out.getvalue().splitlines()]\n"
        "assert names[:3] == ['pendulum', 'pendulum-unclipped', 'cartpole'], names\n"
    )
    assert _imported_after(code) == set()


def test_the_list_table_is_the_tasks_own():
    """``list`` reads a JAX-free table: it must say what the tasks themselves say."""
    from diffcontrol import _registry, tasks

    table = [(r.name, r.summary, r.losses, r.recipes) for r in _registry.BUILTIN]
    own = [tasks.make(r.name) for r in _registry.BUILTIN]
    assert table == [(t.name, t.summary, tuple(t.losses), tuple(t.recipes())) for t in own]
    assert tasks.names()[: len(table)] == [row[0] for row in table]


def test_list_in_a_process_with_the_tasks_imported_shows_registered_ones_too(capsys):
    from diffcontrol import tasks
    from diffcontrol.cli import main

    class Renamed(type(tasks.make("pendulum"))):
        name = "pendulum-listed"
        summary = "a task registered in this process"

    import gymnasium

    from diffcontrol import envs

    task = tasks.register(Renamed())
    try:
        assert main(["list"]) == 0
        assert (
            "pendulum-listed            a task registered in this process"
            in capsys.readouterr().out
        )
    finally:  # leave both registries as they were
        tasks._REGISTRY.pop("pendulum-listed")
        gymnasium.registry.pop(envs.env_id(task), None)


@pytest.mark.slow  # a CartPole run in a fresh interpreter: about 5 s
def test_a_discrete_time_run_does_not_load_diffrax(tmp_path):
    """Diffrax (with lineax and optimistix) is for ODE solves: a discrete-time training run,
    its save and its Gymnasium evaluation never import it (a quarter of a second of start-up)."""
    code = (
        "import pathlib\n"
        "import diffcontrol\n"
        "task = diffcontrol.make('cartpole')\n"
        "cfg = task.default_config().replace(updates=2, eval_every=1, eval_episodes=1)\n"
        f"out = pathlib.Path({str(tmp_path / 'run')!r})\n"
        "diffcontrol.train(task, cfg).save(out, final_eval=1, animation=False)\n"
        "assert (out / 'model.json').exists()\n"
    )
    imported = _imported_after(code)
    assert "jax" in imported and "diffrax" not in imported, imported


_DEFAULTS = {"xla_backend_optimization_level": 3, "xla_cpu_use_fusion_emitters": True}
"""XLA's defaults, as a user's process compiles (the session's XLA_FLAGS choose others)."""


@pytest.mark.slow  # the start compiled at two levels: 2.5 s (cartpole) on one core
@pytest.mark.parametrize("name", ["cartpole", "cartpole-swingup"])
def test_the_start_program_at_its_level_gives_the_default_levels_bits(name):
    """``START_COMPILER_OPTIONS`` compiles the start faster with the same weights, resets and
    keys as XLA's defaults (a discrete-time and a continuous-time trainer)."""
    import jax
    import numpy as np

    import diffcontrol
    from diffcontrol import _jax_setup
    from diffcontrol.training import _driver, _programs
    from diffcontrol.training._bptt import make_trainer
    from diffcontrol.training._ode import make_ode_trainer

    task = diffcontrol.make(name)
    config = task.default_config()
    maker = make_ode_trainer if isinstance(task, diffcontrol.ContinuousTask) else make_trainer
    args = (maker(task, config, None), np.int32(3), _driver.task_params(task, config.params))
    lowered = _programs._START.lower(*args)

    def leaves(options):
        out = lowered.compile(options)(*args)
        return [
            np.asarray(
                jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
            )
            for x in jax.tree.leaves(out)
        ]

    # The users' compiler: XLA's defaults (level 3, the fusion emitters), named, since the
    # session's XLA_FLAGS (conftest.py) choose others
    fast = {n: _jax_setup.FAST_COMPILE[n] for n in _programs.START_COMPILER_OPTIONS}
    ours = leaves(fast)
    default = leaves(_DEFAULTS)
    assert len(ours) == len(default) > 5
    for a, b in zip(ours, default):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow  # the evaluation program compiled twice: about 2.5 s on one core
def test_a_tasks_fast_compile_options_give_the_defaults_bits():
    """A built-in task's declared ``fast_compile`` options give XLA's defaults' bits: the
    limited swing-up's evaluation of its untrained controller, a float loss that level 1
    changes (benchmarks/compile_options.py checks every task's programs; a small chunk, or
    CartPole's and the Acrobot's step-count returns, come out the same under any option)."""
    import jax
    import numpy as np

    import diffcontrol
    from diffcontrol import _jax_setup
    from diffcontrol.training import _driver, _programs

    task = diffcontrol.make("cartpole-swingup-limited")
    config = task.default_config()
    params = _driver.task_params(task, config.params)
    kept = _programs._kept_trainer(task, config, None, params, lambda line: None)
    ts, k_eval = _programs._first_state(kept, config.seed, params)
    args = (ts.controller, params, k_eval)
    lowered = jax.jit(kept.trainer.evaluate).lower(*args)
    declared = _programs.compile_options(task, "evaluate")
    fast = {**_DEFAULTS, **{n: _jax_setup.FAST_COMPILE[n] for n in declared}}
    ours, default = (np.asarray(lowered.compile(o)(*args)) for o in (fast, _DEFAULTS))
    assert declared and ours.size > 0 and np.isfinite(ours).all()
    np.testing.assert_array_equal(ours, default)


def test_fast_compile_options_are_read_from_the_tasks_own_class_and_kept_apart():
    """A subclass (another system, a fitted model) compiles with XLA's defaults unless it
    declares its own; a program kept by ``compiled_once`` is kept per set of options."""
    import jax
    import jax.numpy as jnp

    import diffcontrol
    from diffcontrol.training import _programs

    cartpole = diffcontrol.make("cartpole")
    options = _programs.compile_options
    assert options(cartpole, "chunk") and options(cartpole, "evaluate")
    assert options(type("Heavier", (type(cartpole),), {})(), "chunk") == ()
    assert options(diffcontrol.make("mountain-car-continuous"), "chunk") == ()
    for wrong in ({"evaluate": "xla_backend_optimization_level"}, {"chunks": ()}):
        typo = type("Typo", (type(cartpole),), {"fast_compile": wrong})()
        with pytest.raises(diffcontrol.ConfigError, match="declares fast_compile"):
            options(typo, "chunk")
    lowered = jax.jit(lambda x: x * 3).lower(jnp.ones(2))
    level = ("xla_backend_optimization_level",)
    assert _programs.compiled_once(lowered, *level) is _programs.compiled_once(lowered, *level)
    assert _programs.compiled_once(lowered) is not _programs.compiled_once(lowered, *level)


class _Lowered:
    """Records the options it is compiled with; ``refuse`` names an option it does not know."""

    def __init__(self, refuse: str = ""):
        self.refuse, self.calls = refuse, []

    def compile(self, options=None):
        import jax

        self.calls.append(options)
        if options and self.refuse in options:
            raise jax.errors.JaxRuntimeError(
                f"INVALID_ARGUMENT: No such compile option: '{self.refuse}'"
            )
        return "compiled"


def test_compile_with_passes_the_named_fast_options_unless_xla_flags_name_them(monkeypatch):
    from diffcontrol import _jax_setup

    level, emitters = "xla_backend_optimization_level", "xla_cpu_use_fusion_emitters"
    monkeypatch.setenv("XLA_FLAGS", "")
    monkeypatch.setattr(_jax_setup, "_one_core", lambda: False)
    lowered = _Lowered()
    assert _jax_setup.compile_with(lowered, level, emitters) == "compiled"
    assert _jax_setup.compile_with(lowered, emitters) == "compiled"
    monkeypatch.setenv("XLA_FLAGS", f"--{level}=0")
    _jax_setup.compile_with(lowered, level, emitters)
    _jax_setup.compile_with(lowered, level)
    monkeypatch.setenv("XLA_FLAGS", "")
    monkeypatch.setattr("jax.default_backend", lambda: "gpu")  # CPU options for CPUs only
    _jax_setup.compile_with(lowered, level, emitters)
    assert lowered.calls == [
        {level: 1, emitters: False},
        {emitters: False},
        {emitters: False},
        None,
        {level: 1},
    ]


def test_on_one_core_the_older_emitters_compile_unsplit(monkeypatch):
    """With one core, a program with the older emitters gets ``ONE_CORE`` (XLA's parallel
    codegen split has no second core to run on); one with the fusion emitters does not, nor
    does any program where ``XLA_FLAGS`` names the split."""
    from diffcontrol import _jax_setup

    level, emitters = "xla_backend_optimization_level", "xla_cpu_use_fusion_emitters"
    split = "xla_cpu_parallel_codegen_split_count"
    monkeypatch.setenv("XLA_FLAGS", "")
    monkeypatch.setattr(_jax_setup, "_one_core", lambda: True)
    assert _jax_setup.fast_options(level, emitters) == {level: 1, emitters: False, split: 1}
    assert _jax_setup.fast_options(emitters) == {emitters: False, split: 1}
    assert _jax_setup.fast_options(level) == {level: 1}
    assert _jax_setup.fast_options() is None
    monkeypatch.setenv("XLA_FLAGS", f"--{split}=4")
    assert _jax_setup.fast_options(emitters) == {emitters: False}
    monkeypatch.setattr(_jax_setup, "_one_core", lambda: False)
    monkeypatch.setenv("XLA_FLAGS", "")
    assert _jax_setup.fast_options(emitters) == {emitters: False}


def test_compile_with_falls_back_to_xlas_defaults_where_jaxlib_lacks_an_option(monkeypatch):
    import jax
    import jax.numpy as jnp
    import numpy as np

    from diffcontrol import _jax_setup

    monkeypatch.setenv("XLA_FLAGS", "")
    monkeypatch.setitem(_jax_setup.FAST_COMPILE, "xla_no_such_option", 1)
    lowered = _Lowered(refuse="xla_no_such_option")
    _jax_setup.compile_with(lowered, "xla_no_such_option")
    assert lowered.calls == [{"xla_no_such_option": 1}, None]
    # jaxlib's own refusal is the one caught, by compile_with and by FastJit
    plus_two = _jax_setup.FastJit(lambda x: x + 2, "xla_no_such_option")
    assert np.asarray(plus_two(jnp.ones(2))).tolist() == [3, 3]
    assert plus_two.jitted is not None and plus_two(jnp.ones(2)).shape == (2,)
    real = jax.jit(lambda x: x + 1).lower(jnp.ones(2))
    assert np.asarray(
        _jax_setup.compile_with(real, "xla_no_such_option")(jnp.ones(2))
    ).tolist() == [2, 2]


def _compiled_as_users(fast: bool, seen: list):
    """A ``compile_with`` that compiles as a user's process would: with its options if
    ``fast``, with XLA's defaults otherwise."""
    from diffcontrol import _jax_setup

    def compile_with(lowered, *names):
        seen.append(names)
        chosen = {n: _jax_setup.FAST_COMPILE[n] for n in names} if fast else {}
        return lowered.compile({**_DEFAULTS, **chosen})

    return compile_with


@pytest.mark.slow  # the reference solve compiled twice: about 4 s on one core
def test_the_reference_solve_compiled_for_speed_reports_the_defaults_loss(monkeypatch):
    import jax

    import diffcontrol
    from diffcontrol import _jax_setup
    from diffcontrol.controllers import MLPController
    from diffcontrol.evaluation import simulate_continuous

    task = diffcontrol.make("cartpole-swingup-friction")
    controller = MLPController(jax.random.PRNGKey(1), **controller_kwargs(task), hidden=(8,))
    seen, recordings = [], []
    for fast in (True, False):
        monkeypatch.setattr(_jax_setup, "compile_with", _compiled_as_users(fast, seen))
        recordings.append(simulate_continuous(task, controller))
    assert seen == [("xla_cpu_use_fusion_emitters",)] * 2
    fast, default = recordings
    assert fast.loss == pytest.approx(default.loss, rel=1e-12, abs=0)
    np.testing.assert_allclose(fast.y, default.y, rtol=1e-12, atol=1e-12)


@pytest.mark.slow  # the throw compiled twice: about 2 s on one core
def test_the_drawn_throw_compiled_for_speed_lands_where_the_defaults_do(monkeypatch):
    import types

    import jax

    import diffcontrol
    from diffcontrol import _jax_setup
    from diffcontrol.builtin.trebuchet import system as tb
    from diffcontrol.builtin.trebuchet import task as trebuchet

    seen = []

    def as_users(*names):  # the options a user's process gets (the session names its own)
        seen.append(names)
        return {**_DEFAULTS, **{n: _jax_setup.FAST_COMPILE[n] for n in names}}

    monkeypatch.setattr(_jax_setup, "fast_options", as_users)
    old = trebuchet._SIMULATE
    monkeypatch.setattr(trebuchet, "_SIMULATE", _jax_setup.FastJit(old.fn, *old.names))
    task = diffcontrol.make("trebuchet")
    run = types.SimpleNamespace(policy=lambda target, wind: (44.0, 210.0), params=None, real=False)
    fast = task.throw(run, *task.EXAMPLE_THROW)
    args = (task.EXAMPLE_THROW[1], 44.0, 210.0, None)
    default = jax.jit(tb.simulate).lower(*args).compile(_DEFAULTS)(*args)
    assert seen == [("xla_cpu_use_fusion_emitters",)]
    assert float(fast.distance) == pytest.approx(float(default.distance), rel=1e-6, abs=0)
    np.testing.assert_allclose(fast.projectile, default.projectile, rtol=1e-5, atol=1e-4)


@pytest.mark.parametrize("init", ["equinox", "glorot"])
def test_a_network_made_outside_a_trace_is_one_kept_program_with_the_op_by_op_weights(init):
    """A controller or a model's network made from a concrete key draws its weights in one
    compiled program (``controllers._DRAW_LAYERS``) that the next network of that shape
    reuses, the same to the bit as Equinox's layers drawn op by op and as the same network
    made inside a ``jit`` (with a traced final scale too); under ``jax.disable_jit`` it is
    still made. (Under
    XLA's defaults, as users compile, 105 networks were compared with the op-by-op code:
    docs/benchmarks.md.)"""
    import equinox as eqx
    import jax

    from diffcontrol import controllers
    from diffcontrol.controllers import MLPController, _glorot

    key, sizes = jax.random.PRNGKey(7), (5, 23, 19, 3)  # a shape no other test draws

    def make(k, scale=0.3):
        return MLPController(k, 5, 3, (23, 19), final_scale=scale, init=init)

    def programs():
        jitted = controllers._DRAW_LAYERS.jitted
        return 0 if jitted is None else jitted._cache_size()

    before = programs()
    made = make(key)
    assert programs() == before + 1  # one program for the shape...
    make(jax.random.PRNGKey(8))
    assert programs() == before + 1  # ...kept for the next key
    keys = jax.random.split(key, 3)
    ref = [eqx.nn.Linear(a, b, key=k) for a, b, k in zip(sizes[:-1], sizes[1:], keys)]
    if init == "glorot":
        ref = [_glorot(l, k) for l, k in zip(ref, jax.random.split(keys[0], 3))]
    expected = [(l.weight, l.bias) for l in ref[:-1]] + [(ref[-1].weight * 0.3, ref[-1].bias * 0)]
    for net in (made, jax.jit(make)(key), jax.jit(lambda s: make(key, s))(0.3)):
        got = [(l.weight, l.bias) for l in net.layers]
        assert [np.asarray(a).tobytes() for pair in got for a in pair] == [
            np.asarray(a).tobytes() for pair in expected for a in pair
        ]
    with jax.disable_jit():  # op by op, primitive by primitive: to float32 rounding
        unjitted = make(key)
    for layer, (weight, bias) in zip(unjitted.layers, expected):
        np.testing.assert_allclose(layer.weight, weight, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(layer.bias, bias, rtol=1e-6, atol=1e-7)
