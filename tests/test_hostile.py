"""Bad input and damaged files, as a hostile user would try them: each gets one line and exit
status 2 (or a one-line exception in the library), and nothing existing is changed."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

import diffcontrol
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, ModelFileError
from diffcontrol.training import _checkpoint

PENDULUM = diffcontrol.make("pendulum")


def _one_line(capsys, argv, *needles):
    try:
        code = main(argv)
    except SystemExit as e:  # a usage error of the parser
        code = e.code
    assert code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err


# --- configuration values, in the library ------------------------------------------------------


@pytest.mark.parametrize(
    "change, needle",
    [
        (dict(learning_rate="0.1"), "learning_rate must be a number"),
        (dict(learning_rate=None), "learning_rate must be a number"),
        (dict(grad_clip=None), "grad_clip must be a number"),
        (dict(hidden=8), "hidden must be positive layer widths"),
        (dict(params={"g": 9.8}), "params must be (name, value) pairs"),
        (dict(seed="0"), "seed must be an integer"),
        (dict(seed=1.5), "seed must be an integer"),
        (dict(seed=10**23), "seed must be in"),
        (dict(activation=5), "activation must be text"),
        (dict(activation="nope"), "activation must be one of"),
        (dict(head="nope"), "head must be empty"),
        (dict(target_return=-math.inf), "target_return must be a finite number, or nan"),
        (dict(batch=10**13), "batch must be in"),
        (dict(updates=10**13), "updates must be in"),
        (dict(hidden=(64, 10**13)), "hidden must be layer widths of at most 1,048,576"),
    ],
)
def test_config_values_of_the_wrong_type_or_size(change, needle):
    with pytest.raises(ConfigError) as e:
        PENDULUM.default_config().replace(**change)
    assert needle in str(e.value)


def test_numbers_given_as_integers_and_lists_are_converted():
    c = PENDULUM.default_config().replace(learning_rate=1, hidden=[8, 8], params=[["g", 10]])
    assert c.learning_rate == 1.0 and c.hidden == (8, 8) and c.params == (("g", 10.0),)


@pytest.mark.parametrize(
    "param, needle",
    [("dt=0", "dt=0"), ("m=-1", "m=-1"), ("l=-1", "l=-1"), ("l=0", "l=0")],
)
def test_physical_parameters_out_of_range(capsys, tmp_path, param, needle):
    out = tmp_path / "x"
    _one_line(capsys, ["train", "pendulum", "--out", str(out), "--param", param], needle, "> 0")
    assert not out.exists()


def test_a_head_that_does_not_fit_the_task(capsys, tmp_path):
    out = tmp_path / "x"
    _one_line(capsys, ["train", "pendulum", "--out", str(out), "--head", "sign"], "'sign'")
    assert not out.exists()


def test_huge_numbers_on_the_command_line(capsys, tmp_path):
    for option in ("--updates", "--batch", "--hidden", "--seed"):
        _one_line(capsys, ["train", "pendulum", "--out", str(tmp_path / "x"), option, "10" * 12])
    _one_line(capsys, ["train", "pendulum", "--out", str(tmp_path / "x"), "--target-return=-inf"])
    assert not (tmp_path / "x").exists()


# --- runs and model files --------------------------------------------------------------------


def test_evaluate_and_animate_refuse_bad_targets(capsys, cartpole_run, tmp_path):
    _one_line(capsys, ["evaluate", str(cartpole_run), "--seed", "-1"], "--seed")
    _one_line(
        capsys, ["evaluate", str(cartpole_run), "--env", "no_such_mod_q:X-v0"], "no_such_mod_q"
    )
    _one_line(capsys, ["animate", str(cartpole_run), "--out", str(tmp_path / "no" / "a.gif")])
    _one_line(capsys, ["animate", str(cartpole_run), "--out", str(tmp_path)], ".gif")


def _corrupt_model(tmp_path, cartpole_run, edit):
    doc = json.loads((cartpole_run / "model.json").read_text())
    edit(doc)
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize(
    "edit, needle",
    [
        (lambda d: d["observation"].update(offset=[None] * 4), "offset"),
        (lambda d: d["observation"].update(scale=[float("nan")] * 4), "scale"),
        (lambda d: d["observation"].update(size=2), "offset"),
        (lambda d: d["network"].update(layers=[]), "no layers"),
        (lambda d: d["action"].update(head="tanh", low=None, high=None), "tanh head needs"),
        (lambda d: d["action"].update(head="tanh", low=[-1, -1], high=[1, 1]), "tanh head needs"),
        (lambda d: d["action"].update(size="1"), "action size"),
    ],
)
def test_damaged_model_files(tmp_path, cartpole_run, edit, needle):
    path = _corrupt_model(tmp_path, cartpole_run, edit)
    with pytest.raises(ModelFileError) as e:
        diffcontrol.load(path)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_a_deeply_nested_model_file(tmp_path):
    path = tmp_path / "model.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ModelFileError, match="nested too deeply"):
        diffcontrol.load(path)


def test_a_policy_names_the_observation_it_needs(cartpole_run):
    policy = diffcontrol.load(cartpole_run)
    with pytest.raises(ValueError, match="size 4"):
        policy(np.zeros(3))
    with pytest.raises(ValueError, match="size 4"):
        policy(np.float64(1.0))
    with pytest.raises(ValueError, match="NaN"):
        policy(np.array([0.0, np.nan, 0.0, 0.0]))


@pytest.fixture
def resumable(cartpole_run, tmp_path):
    """A copy of a finished run made resumable again (as if stopped after its last chunk)."""
    out = tmp_path / "run"
    shutil.copytree(cartpole_run, out)
    doc = json.loads((out / "run.json").read_text())
    doc.pop("complete")
    (out / "run.json").write_text(json.dumps(doc))
    return out


def _damaged_checkpoints(path):
    good = path.read_bytes()
    yield "empty", b""
    yield "truncated", good[: len(good) // 2]
    arrays = dict(np.load(path, allow_pickle=False))
    header = json.loads(bytes(arrays["header"]).decode())

    def with_header(h):
        a = dict(arrays, header=np.frombuffer(json.dumps(h).encode(), np.uint8))
        return a

    yield "list header", with_header([1, 2])
    yield "no meta", with_header({k: v for k, v in header.items() if k != "meta"})
    yield "bad curve", with_header({**header, "meta": {**header["meta"], "curve": "oops"}})
    yield "bad best", with_header({**header, "meta": {**header["meta"], "best_index": 99}})
    huge = dict(arrays)
    huge["leaf_0000"] = np.lib.stride_tricks.as_strided(np.zeros(1), (10**6,), (0,))
    yield "huge claim", huge
    nan = {k: np.full_like(v, np.nan) if k.startswith("leaf_") and v.dtype.kind == "f" else v
           for k, v in arrays.items()}  # fmt: skip
    yield "NaN weights", nan


def test_damaged_checkpoints_get_one_line(resumable, capsys):
    ckpt = resumable / "checkpoint.npz"
    original = ckpt.read_bytes()
    for what, damage in _damaged_checkpoints(ckpt):
        if isinstance(damage, bytes):
            ckpt.write_bytes(damage)
        else:
            with open(ckpt, "wb") as f:
                np.savez(f, **damage)
        before = {p.name: p.read_bytes() for p in resumable.iterdir()}
        _one_line(capsys, ["train", "--out", str(resumable), "--resume"], "checkpoint")
        after = {p.name: p.read_bytes() for p in resumable.iterdir()}
        assert before == after, what
        ckpt.write_bytes(original)
    with pytest.raises(ModelFileError):
        _checkpoint.load_checkpoint(resumable / "missing.npz", None)


# --- data files ------------------------------------------------------------------------------


def test_a_csv_field_beyond_the_csv_limit(tmp_path, capsys):
    from diffcontrol.identify.data import read_trajectories

    path = tmp_path / "big.csv"
    header = '# {"format": "diffcontrol-trajectories", "version": 1, "metadata": {}}'
    path.write_text(header + "\ntime,episode,obs.x [m],action.u [N]\n" + "1" * 200_000 + ",0,0,0\n")
    with pytest.raises(diffcontrol.errors.DataFileError) as e:
        read_trajectories(path)
    assert "\n" not in str(e.value)


def test_an_npz_that_claims_a_huge_array_is_refused_unread(tmp_path):
    import io as _io
    import zipfile

    from diffcontrol.identify.data import read_trajectories

    path = tmp_path / "huge.npz"
    with zipfile.ZipFile(path, "w") as z:
        for name, shape in [("time", (10**12,)), ("episode", (1,)), ("observations", (1, 1))]:
            buf = _io.BytesIO()
            np.lib.format.write_array_header_1_0(
                buf, {"descr": "<f8", "fortran_order": False, "shape": shape}
            )
            z.writestr(f"{name}.npy", buf.getvalue())
        for name in ("actions", "header"):
            buf = _io.BytesIO()
            np.save(buf, np.zeros(1))
            z.writestr(f"{name}.npy", buf.getvalue())
    with pytest.raises(diffcontrol.errors.DataFileError, match="claims shape"):
        read_trajectories(path)
