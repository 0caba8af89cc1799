"""Recorded trajectories: file round trips, recording from Gymnasium, every malformed file,
and ``diffcontrol record`` end to end."""

from __future__ import annotations

import io
import json

import gymnasium
import jax
import numpy as np
import pytest

import diffcontrol
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError
from diffcontrol.identify import data
from diffcontrol.identify._task import data_columns
from diffcontrol.identify.data import DataFileError, TrajectoryData, read_trajectories
from diffcontrol.io import write_json
from diffcontrol.policies import controller_to_dict

PENDULUM_OBS, PENDULUM_ACT = data.known_columns()["Pendulum-v1"]


@pytest.fixture(scope="module")
def pendulum_data():
    """Two random-action episodes of Pendulum-v1 (its 200-step limit)."""
    return diffcontrol.record("Pendulum-v1", 2, seed=0)


@pytest.fixture(scope="module")
def pendulum_model(tmp_path_factory):
    """An untrained pendulum controller saved as model.json (no training needed)."""
    task = diffcontrol.make("pendulum")
    ctrl = diffcontrol.MLPController(
        jax.random.PRNGKey(3), 3, 1, (8,), head="tanh", action_low=(-2.0,), action_high=(2.0,)
    )
    run = tmp_path_factory.mktemp("model")
    write_json(run / "model.json", controller_to_dict(ctrl, task))
    return run


def _small(**meta) -> TrajectoryData:
    """Two short Pendulum-like episodes (3 and 2 steps) with awkward floats."""
    rng = np.random.default_rng(0)
    obs = [rng.normal(size=(4, 3)) / 3, rng.normal(size=(3, 3)) * 1e-7]
    act = [rng.uniform(-2, 2, size=(3, 1)), np.array([[0.1], [-1 / 3]])]
    return TrajectoryData.from_episodes(
        obs, act, PENDULUM_OBS, PENDULUM_ACT, dt_s=0.05, metadata={"env_id": "Pendulum-v1", **meta}
    )


def _same(a: TrajectoryData, b: TrajectoryData, ignore: tuple[str, ...] = ()) -> None:
    """Equal arrays, columns, units and metadata (but the ``ignore``d metadata keys)."""
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_array_equal(a.episode, b.episode)
    np.testing.assert_array_equal(a.observations, b.observations)
    np.testing.assert_array_equal(a.actions, b.actions)  # NaN == NaN here
    assert a.episode.dtype == b.episode.dtype == np.int64
    assert a.columns == b.columns and a.units == b.units
    meta_a = {k: v for k, v in a.metadata.items() if k not in ignore}
    assert meta_a == {k: v for k, v in b.metadata.items() if k not in ignore}


# --- round trips ---------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_round_trip_is_exact(tmp_path, pendulum_data, suffix):
    for d in (pendulum_data, _small(note="ü ✓")):
        path = tmp_path / f"d{suffix}"
        data.write_trajectories(path, d)
        _same(read_trajectories(path), d)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_round_trip_of_states_discrete_actions_and_step_time(tmp_path, suffix):
    d = TrajectoryData.from_episodes(
        [np.arange(6.0).reshape(3, 2), np.ones((2, 2))],
        [np.array([[2.0], [0.0]]), np.array([[1.0]])],
        ("state.position [m]", "state.speed [?]"),
        ("action.0 [index]",),
        metadata={"env_id": "MyRobot-v0"},
    )
    path = tmp_path / f"d{suffix}"
    data.write_trajectories(path, d)
    back = read_trajectories(path)
    _same(back, d)
    assert back.holds == "state" and back.columns[0] == "time [step]"
    assert back.units["state.speed"] == "?" and back.units["action.0"] == "index"


def test_csv_text_is_the_documented_format(tmp_path):
    path = tmp_path / "d.csv"
    data.write_csv(path, _small())
    lines = path.read_text().splitlines()
    header = json.loads(lines[0][1:])
    assert header == {
        "format": "diffcontrol-trajectories",
        "version": 1,
        "metadata": {"dt_s": 0.05, "env_id": "Pendulum-v1"},
    }
    assert lines[1] == ",".join(["time [s]", "episode", *PENDULUM_OBS, *PENDULUM_ACT])
    assert len(lines) == 2 + 4 + 3
    assert lines[2].startswith("0.0,0,") and lines[6].startswith("0.0,1,")
    # the last row of each episode: the final observation, an empty action cell
    assert lines[5].endswith(",") and lines[8].endswith(",") and not lines[4].endswith(",")
    assert lines[7].endswith(",-0.3333333333333333")


def test_npz_holds_plain_arrays_and_a_json_header(tmp_path):
    path = tmp_path / "d.npz"
    data.write_npz(path, _small())
    with np.load(path, allow_pickle=False) as f:
        assert sorted(f.files) == ["actions", "episode", "header", "observations", "time"]
        assert f["header"].dtype == np.uint8 and f["observations"].shape == (7, 3)
        header = json.loads(f["header"].tobytes())
    assert header["format"] == "diffcontrol-trajectories" and header["version"] == 1
    assert header["columns"][:2] == ["time [s]", "episode"]


# --- the value -------------------------------------------------------------------------------------


def test_episodes_transitions_and_split():
    d = _small()
    assert d.num_episodes == 2 and d.num_steps == 5
    eps = list(d.episodes())
    assert [e.id for e in eps] == [0, 1]
    assert [e.observations.shape for e in eps] == [(4, 3), (3, 3)]
    assert [e.actions.shape for e in eps] == [(3, 1), (2, 1)]
    assert np.all(np.isfinite(eps[0].actions))
    x, u, x_next = d.transitions()
    assert x.shape == x_next.shape == (5, 3) and u.shape == (5, 1)
    np.testing.assert_array_equal(x_next[2], eps[0].observations[3])
    np.testing.assert_array_equal(x[3], eps[1].observations[0])
    train, held = d.split(1)
    assert (train.num_episodes, held.num_episodes) == (1, 1)
    np.testing.assert_array_equal(held.observations, eps[1].observations)
    with pytest.raises(ConfigError, match="choose 1 to 1"):
        d.split(2)
    with pytest.raises(ValueError):
        d.time[0] = 1.0  # read-only


def test_constructor_validates_and_leaves_the_callers_arrays_alone():
    d = _small()
    obs, act = d.observations.copy(), d.actions.copy()
    act[3] = 0.5  # the last row of episode 0
    with pytest.raises(DataFileError, match="^trajectory data: row 3: the last row of episode 0"):
        TrajectoryData(d.time, d.episode, obs, act, d.columns)
    TrajectoryData(d.time, d.episode, obs, d.actions, d.columns)
    assert obs.flags.writeable


# --- recording -----------------------------------------------------------------------------------


def test_record_random_pendulum(pendulum_data):
    d = pendulum_data
    assert d.env_id == "Pendulum-v1" and d.num_episodes == 2 and d.num_steps == 400
    assert d.columns == ("time [s]", "episode", *PENDULUM_OBS, *PENDULUM_ACT)
    for e in d.episodes():
        np.testing.assert_allclose(e.time, 0.05 * np.arange(201))
        assert np.all(np.abs(e.actions) <= 2.0) and np.std(e.actions) > 0.5
    assert d.metadata["ends"] == ["truncated", "truncated"]
    assert d.metadata["source"] == "random actions" and d.metadata["dt_s"] == 0.05
    again = diffcontrol.record("Pendulum-v1", 2, seed=0)
    np.testing.assert_array_equal(again.actions, d.actions)
    np.testing.assert_array_equal(again.observations, d.observations)
    other = diffcontrol.record("Pendulum-v1", 1, seed=1)
    np.testing.assert_array_equal(other.observations[0], d.observations[201])  # reset seed 0+1
    assert not np.array_equal(other.actions[:200], d.actions[201:401])  # its own action seed


def test_recorded_pendulum_pairs_reproduce_gymnasium(pendulum_data):
    env = gymnasium.make("Pendulum-v1").unwrapped
    env.reset(seed=0)
    for e, expected_return in zip(pendulum_data.episodes(), pendulum_data.metadata["returns"]):
        total = 0.0
        for x, u, x_next in zip(e.observations[:-1], e.actions, e.observations[1:]):
            env.state = np.array([np.arctan2(x[1], x[0]), x[2]])
            obs, reward, *_ = env.step(u.astype(np.float32))
            np.testing.assert_allclose(obs, x_next, atol=2e-5)
            total += reward
        assert total == pytest.approx(expected_return, rel=1e-4)


def test_recorded_cartpole_pairs_reproduce_gymnasium():
    d = diffcontrol.record("CartPole-v1", 3, seed=4)
    assert d.columns[-1] == "action.push [index]"
    assert set(np.unique(d.actions[np.isfinite(d.actions)])) == {0.0, 1.0}
    assert d.metadata["ends"] == ["terminated"] * 3  # random pushes drop the pole
    env = gymnasium.make("CartPole-v1").unwrapped
    env.reset(seed=0)
    for x, u, x_next in zip(*d.transitions()):
        env.state, env.steps_beyond_terminated = x.copy(), None
        obs, *_ = env.step(int(u[0]))
        np.testing.assert_allclose(obs, x_next, atol=1e-6)


def test_known_columns_are_the_tasks_data_columns(monkeypatch):
    from diffcontrol import tasks

    known = data.known_columns()
    pendulum = diffcontrol.make("pendulum")
    for eid in ("Pendulum-v1", "diffcontrol/Pendulum-v0", "diffcontrol/PendulumFriction-v0"):
        assert known[eid] == data_columns(pendulum)
    assert known["CartPole-v1"] == diffcontrol.make("cartpole").data_columns()
    # tasks whose data are states (not their environment's observations) name no environment
    assert "diffcontrol/Trebuchet-v0" not in known
    assert "diffcontrol/CartPoleSwingUp-v0" not in known

    class Renamed(type(pendulum)):
        name, gym_id = "pendulum-renamed", "my_module:MyPendulum-v0"

        def data_columns(self):
            return ("obs.c [1]", "obs.s [1]", "obs.w [rad/s]"), ("action.tau [N m]",)

    monkeypatch.setitem(tasks._REGISTRY, Renamed.name, Renamed())
    assert data.known_columns()["my_module:MyPendulum-v0"] == Renamed().data_columns()
    assert data.known_columns()["Pendulum-v1"] == data_columns(pendulum)  # the first task's
    # a file that says it is from that environment must have its columns
    with pytest.raises(DataFileError, match="not those of my_module:MyPendulum-v0"):
        _small(env_id="my_module:MyPendulum-v0")


def test_record_with_a_controller(pendulum_model):
    policy = diffcontrol.load(pendulum_model)
    d = diffcontrol.record("Pendulum-v1", 1, policy=policy, seed=2)
    x, u, _ = d.transitions()
    np.testing.assert_array_equal(u, np.stack([policy(obs) for obs in x.astype(np.float32)]))
    assert d.metadata["source"].startswith("policy NumpyPolicy(task='pendulum'")


def test_record_refuses_bad_requests(pendulum_model):
    with pytest.raises(ConfigError, match="episodes must be a positive integer, got 0"):
        diffcontrol.record("Pendulum-v1", 0)
    with pytest.raises(ConfigError, match="'Pendulm-v1'.*Did you mean.*Pendulum-v1"):
        diffcontrol.record("Pendulm-v1", 1)
    with pytest.raises(ConfigError, match="takes 3 observations but CartPole-v1 gives 4"):
        diffcontrol.record("CartPole-v1", 1, policy=diffcontrol.load(pendulum_model))
    with pytest.raises(ConfigError, match="returned 2 action value"):
        diffcontrol.record("Pendulum-v1", 1, policy=lambda obs: np.zeros(2))


# --- malformed files: each one a DataFileError naming the file, the place and the fix --------


def _csv(tmp_path, edit, d=None) -> str:
    """A valid CSV of ``d`` (``_small()`` by default), its lines changed by ``edit``."""
    path = tmp_path / "bad.csv"
    data.write_csv(path, d or _small())
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")
    return path


def _cell(row: int, col: int, value: str):
    def edit(lines):
        cells = lines[row].split(",")
        cells[col] = value
        lines[row] = ",".join(cells)
        return lines

    return edit


def _header_line(change):
    def edit(lines):
        header = json.loads(lines[0][1:])
        change(header)
        lines[0] = "# " + json.dumps(header)
        return lines

    return edit


def _rename(old: str, new: str):
    return lambda lines: [lines[0], lines[1].replace(old, new), *lines[2:]]


def _drop_column(col: int):
    return lambda lines: [lines[0]] + [",".join(np.delete(l.split(","), col)) for l in lines[1:]]


CSV_CASES = {
    "no action column": (_drop_column(5), "has no action.NAME"),
    "missing obs column": (_drop_column(4), r"not those of Pendulum-v1: expected .*theta_dot"),
    "degrees for radians": (
        _rename("theta_dot [rad/s]", "theta_dot [deg/s]"),
        r"'obs.theta_dot \[deg/s\]': Pendulum-v1 gives theta_dot in \[rad/s\]; convert",
    ),
    "missing unit": (_rename("theta_dot [rad/s]", "theta_dot"), "'obs.theta_dot' has no unit"),
    "time in ms": (_rename("time [s]", "time [ms]"), r"'time \[ms\]': time must be in seconds"),
    "time goes back": (_cell(4, 0, "0.01"), r"line 5, column 'time \[s\]': time goes back"),
    "time repeats": (_cell(3, 0, "0.0"), r"line 4, column 'time \[s\]': time repeats"),
    "time in ms labelled s": (
        lambda ls: (
            [ls[0], ls[1]]
            + [f"{float(l.split(',')[0]) * 1000!r}," + l.split(",", 1)[1] for l in ls[2:]]
        ),
        r"line 4, .*a time step of 50.0 s, but the metadata's dt_s is 0.05 s",
    ),
    "NaN observation": (_cell(3, 3, "nan"), r"line 4, column 'obs.sin_theta \[1\]': nan"),
    "empty observation": (_cell(6, 4, ""), r"line 7, column 'obs.theta_dot \[rad/s\]'.*missing"),
    "inf action": (_cell(2, 5, "inf"), r"line 3, column 'action.torque \[N m\]': inf"),
    "missing action": (_cell(3, 5, ""), r"line 4, column 'action.torque \[N m\]': nan"),
    "action on last row": (_cell(5, 5, "0.5"), "line 6: the last row of episode 0 has an action"),
    "ragged row": (_cell(4, 5, "1.0,2.0"), "line 5: 7 cells but 6 columns"),
    "not a number": (_cell(4, 2, "abc"), r"line 5, column 'obs.cos_theta \[1\]': 'abc' is not"),
    "unknown version": (_header_line(lambda h: h.update(version=2)), "version 2 is not supported"),
    "other format": (_header_line(lambda h: h.update(format="x")), "not a diffcontrol-traj"),
    "no header line": (lambda ls: ls[1:], "line 1: no header; the first line must be"),
    "broken header": (lambda ls: ["# {format", *ls[1:]], "line 1: the header is not valid JSON"),
    "no rows": (lambda ls: ls[:2], "holds no rows"),
    "no column names": (lambda ls: ls[:1], "no column names"),
    "episode split": (_cell(8, 1, "0"), "line 9: episode 0 starts again after other episodes"),
    "one-row episode": (
        lambda ls: [*ls[:6], ls[8].replace(",1,", ",7,", 1), *ls[6:8]],
        "line 7: episode 7 has a single row",
    ),
    "fractional episode": (_cell(2, 1, "0.5"), "episode ids must be whole numbers"),
    "duplicate column": (_rename("sin_theta", "cos_theta"), "obs.cos_theta appears twice"),
    "obs and state": (_rename("obs.sin_theta", "state.sin_theta"), "mixes obs. and state."),
    "unknown column": (_rename("obs.sin_theta", "reward"), r"'reward \[1\]' is not obs.NAME"),
    "no time column": (_rename("time [s]", "t [s]"), "the first column must be 'time"),
}


@pytest.mark.parametrize("case", list(CSV_CASES))
def test_malformed_csv(tmp_path, case):
    edit, match = CSV_CASES[case]
    path = _csv(tmp_path, edit)
    with pytest.raises(DataFileError, match=match) as exc:
        read_trajectories(path)
    assert str(exc.value).startswith(str(path))


def test_discrete_action_must_be_an_index(tmp_path):
    d = diffcontrol.record("CartPole-v1", 1, seed=0)
    path = _csv(tmp_path, _cell(2, 6, "0.5"), d)
    with pytest.raises(DataFileError, match=r"line 3, .*'action.push \[index\]': 0.5 is not a d"):
        read_trajectories(path)


def test_missing_empty_and_unknown_files(tmp_path):
    with pytest.raises(DataFileError, match="nope.csv does not exist"):
        read_trajectories(tmp_path / "nope.csv")
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(DataFileError, match="empty.npz is empty"):
        read_trajectories(tmp_path / "empty.npz")
    with pytest.raises(DataFileError, match=r"unknown trajectory file type '.txt'; use a .csv"):
        read_trajectories(tmp_path / "d.txt")


def _npz(tmp_path, **changes):
    d = _small()
    arrays = {
        "time": d.time,
        "episode": d.episode,
        "observations": d.observations,
        "actions": d.actions,
    }
    header = {"format": "diffcontrol-trajectories", "version": 1, "columns": list(d.columns)}
    header["metadata"] = d.metadata
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    arrays.update(changes)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    path = tmp_path / "bad.npz"
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path.write_bytes(buf.getvalue())
    return path


def _json(obj) -> np.ndarray:
    return np.frombuffer(json.dumps(obj).encode(), np.uint8)


NPZ_CASES = {
    "missing array": ({"actions": None}, r"missing array\(s\) \['actions'\]"),
    "object array": ({"time": np.array([1, "a"], dtype=object)}, "not a readable .npz"),
    "text array": ({"time": np.array(["a"] * 7)}, "array 'time' has dtype <U1"),
    "short array": ({"observations": np.zeros((6, 3))}, r"observations has shape \(6, 3\)"),
    "header not JSON": ({"header": np.frombuffer(b"{x", np.uint8)}, "header array is not JSON"),
    "version": ({"header": _json({"format": "diffcontrol-trajectories", "version": 7})}, "7"),
    "no columns": (
        {"header": _json({"format": "diffcontrol-trajectories", "version": 1})},
        "no list of column names",
    ),
    "NaN observation": (
        {"observations": np.where(np.arange(7)[:, None] == 2, np.nan, _small().observations)},
        r"row 2, column 'obs.cos_theta \[1\]': nan",
    ),
}


@pytest.mark.parametrize("case", list(NPZ_CASES))
def test_malformed_npz(tmp_path, case):
    changes, match = NPZ_CASES[case]
    path = _npz(tmp_path, **changes)
    with pytest.raises(DataFileError, match=match) as exc:
        read_trajectories(path)
    assert str(exc.value).startswith(str(path))


def test_npz_that_is_not_a_zip(tmp_path):
    path = tmp_path / "text.npz"
    path.write_text("time,episode\n")
    with pytest.raises(DataFileError, match="text.npz is not a readable .npz"):
        read_trajectories(path)


# --- the command line ----------------------------------------------------------------------------


def test_cli_records_csv_and_npz(tmp_path, capsys):
    out = tmp_path / "pendulum.csv"
    assert main(["record", "Pendulum-v1", "--episodes", "2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "episode 1/2 (seed 0): 200 steps" in printed and "episode 2/2" in printed
    assert f"wrote {out}: 2 episode(s), 400 steps" in printed
    again = diffcontrol.record("Pendulum-v1", 2, seed=0).select([0, 1])
    _same(read_trajectories(out), again, ignore=("recorded",))  # a timestamp, to the second
    npz = tmp_path / "cartpole.npz"
    args = ["record", "CartPole-v1", "--episodes", "2", "--seed", "5", "--out", str(npz)]
    assert main([*args, "--quiet"]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {npz}: 2 episode(s)")
    d = read_trajectories(npz)
    assert d.env_id == "CartPole-v1" and d.metadata["seed"] == 5
    heavy = tmp_path / "g20.csv"
    argv = ["record", "Pendulum-v1", "--episodes", "1", "--env-arg", "g=20", "--out", str(heavy)]
    assert main([*argv, "--quiet"]) == 0
    d = read_trajectories(heavy)
    assert d.metadata["env_kwargs"] == {"g": 20.0}
    nominal = diffcontrol.record("Pendulum-v1", 1)
    np.testing.assert_array_equal(d.observations[0], nominal.observations[0])  # same start
    assert not np.allclose(d.observations[1:], nominal.observations[1:])  # other gravity


def test_cli_records_with_a_controller(tmp_path, pendulum_model, capsys):
    out = tmp_path / "ctrl.npz"
    argv = ["record", "Pendulum-v1", "--episodes", "1", "--controller", str(pendulum_model)]
    assert main([*argv, "--out", str(out), "--max-steps", "20"]) == 0
    d = read_trajectories(out)
    assert d.num_steps == 20 and d.metadata["source"].startswith(f"controller {pendulum_model}")
    x, u, _ = d.transitions()
    policy = diffcontrol.load(pendulum_model)
    np.testing.assert_array_equal(u[:, 0], [policy(o)[0] for o in x.astype(np.float32)])


def _fails_cleanly(capsys, argv, *needles):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err


def test_cli_bad_input(tmp_path, pendulum_model, capsys):
    out = tmp_path / "d.csv"
    out.write_text("mine")
    rec = ["record", "Pendulum-v1", "--episodes", "1"]
    _fails_cleanly(capsys, [*rec, "--out", str(out)], "already exists", "--force")
    assert out.read_text() == "mine"
    assert main([*rec, "--out", str(out), "--force", "--quiet"]) == 0
    assert read_trajectories(out).num_episodes == 1
    _fails_cleanly(
        capsys,
        ["record", "Pendulm-v1", "--episodes", "1", "--out", str(tmp_path / "x.csv")],
        "'Pendulm-v1'",
        "Pendulum-v1",
    )
    _fails_cleanly(
        capsys,
        [
            "record",
            "CartPole-v1",
            "--episodes",
            "1",
            "--controller",
            str(pendulum_model),
            "--out",
            str(tmp_path / "y.csv"),
        ],
        "takes 3 observations but CartPole-v1 gives 4",
    )
    _fails_cleanly(
        capsys,
        [*rec, "--controller", str(tmp_path / "none"), "--out", str(tmp_path / "z.csv")],
        "does not exist",
    )
    _fails_cleanly(capsys, [*rec, "--out", str(out / "sub.csv")], "not a writable directory")
    _fails_cleanly(capsys, [*rec, "--out", str(tmp_path / "d.txt")], "use a .csv or .npz")
    _fails_cleanly(capsys, [*rec, "--out", str(tmp_path)], "is a directory")
    _fails_cleanly(
        capsys,
        [*rec, "--env-arg", "gravity=3", "--out", str(tmp_path / "g.csv")],
        "does not take the arguments {'gravity': 3.0}",
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv"]
    with pytest.raises(SystemExit) as exc:
        main(["record", "Pendulum-v1", "--episodes", "0"])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and len(err.splitlines()) == 1 and "--episodes" in err
