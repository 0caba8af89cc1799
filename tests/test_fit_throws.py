"""The trebuchet's throws and grey box (``builtin.trebuchet``: ``throws``, ``record``,
``fit``; ``diffcontrol record/fit/loop trebuchet``): a throw is a one-step episode.

The "real" trebuchet has drag coefficient 1.5 and wind factor 1.5 (the nominal model has 1 and
1). Every throw batch has 15 or 12 throws, so that the compiled throw programs are shared
between the tests (a new batch size compiles the trebuchet again, about 10 s).
"""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

import diffcontrol
from diffcontrol.builtin.trebuchet import fit as ft
from diffcontrol.builtin.trebuchet import record as rec
from diffcontrol.builtin.trebuchet import system as tb
from diffcontrol.builtin.trebuchet.throws import Throws, read_throws, throws_of, throws_table
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, DataFileError, InsufficientDataError
from diffcontrol.identify import fit, read_trajectories
from diffcontrol.identify.data import TrajectoryData, write_trajectories

TRUTH = {"drag_coefficient": 1.5, "wind_factor": 1.5}
REAL_ARGS = [f"--env-arg={n}={v}" for n, v in TRUTH.items()]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """15 noise-free throws of the real trebuchet, recorded by the CLI (shared, read-only)."""
    path = tmp_path_factory.mktemp("throws") / "real.csv"
    argv = ["record", "trebuchet", "--episodes", "15", "--out", str(path), "--quiet"]
    assert main([*argv, *REAL_ARGS, "--seed", "3"]) == 0
    return path


def _throws(n=4, **meta) -> TrajectoryData:
    rng = np.random.default_rng(0)
    wind, angle, weight = rng.normal(0, 5, n), rng.uniform(20, 70, n), rng.uniform(50, 450, n)
    return throws_table(Throws(wind, rng.uniform(10, 90, n), angle, weight), meta)


def test_wind_factor_one_leaves_shoot_unchanged_and_scales_the_wind():
    assert tb.TrebuchetParams().wind_factor == 1.0
    wind = np.array([-7.0, -2.0, 0.0, 3.0])
    shoot = jax.jit(jax.vmap(tb.shoot, (0, None, None, None)))
    nominal = np.asarray(shoot(wind, 45.0, 200.0, tb.TrebuchetParams()))
    assert nominal[1] == pytest.approx(74.758, abs=2e-3)  # the blog's throw, as before
    stronger = np.asarray(shoot(wind, 45.0, 200.0, tb.TrebuchetParams(wind_factor=1.5)))
    scaled = np.asarray(shoot(1.5 * wind, 45.0, 200.0, tb.TrebuchetParams()))
    np.testing.assert_array_equal(stronger, scaled)
    assert stronger[2] == nominal[2] and stronger[0] < nominal[0] and stronger[3] > nominal[3]


COLUMNS = (
    "state.wind [m/s]",
    "state.distance [m]",
    "action.release_angle [deg]",
    "action.counterweight [lb]",
)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_throws_are_one_step_episodes_of_the_trajectory_file(tmp_path, suffix):
    data = _throws(5, system="trebuchet", params={"drag_coefficient": 1.5}, noise_m=0.5)
    assert data.columns == ("time [step]", "episode", *COLUMNS)
    assert data.columns[2:] == sum(diffcontrol.make("trebuchet").data_columns(), ())
    assert data.num_episodes == data.num_steps == 5
    path = tmp_path / f"t{suffix}"
    write_trajectories(path, data)
    back = read_throws(path)
    np.testing.assert_array_equal(back.observations, data.observations)
    np.testing.assert_array_equal(back.actions, data.actions)
    assert back.metadata == data.metadata and read_trajectories(path).columns == data.columns
    x, u, x_next = back.transitions()  # before the throw, the aim, the outcome
    throws = throws_of(back)
    np.testing.assert_array_equal(x[:, 0], throws.wind)
    np.testing.assert_array_equal(x[:, 1], 0.0)
    np.testing.assert_array_equal(u, np.stack([throws.release_angle, throws.counterweight], 1))
    np.testing.assert_array_equal(x_next, np.stack([throws.wind, throws.distance], 1))
    if suffix == ".csv":
        lines = path.read_text().splitlines()
        assert lines[1] == ",".join(["time [step]", "episode", *COLUMNS])
        wind, distance, angle, weight = (float(x[0]) for x in throws)
        assert lines[2] == f"0.0,0,{wind!r},0.0,{angle!r},{weight!r}"
        assert lines[3] == f"1.0,0,{wind!r},{distance!r},,"


OLD_HEADER = '# {"format": "diffcontrol-throws", "version": 1, "metadata": {"noise_m": 0.5}}'
OLD = "wind [m/s],release_angle [deg],counterweight [lb],distance [m]"


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_old_throws_files_are_read_as_one_step_episodes(tmp_path, suffix):
    """A diffcontrol-throws file (one row a throw, the columns in any order) is converted."""
    wind, angle, weight, distance = [-2.0, 3.5], [45.0, 30.0], [200.0, 350.5], [74.81, 90.25]
    path = tmp_path / f"old{suffix}"
    if suffix == ".csv":
        rows = "\n".join(f"{d},{w},{a},{m}" for w, a, m, d in zip(wind, angle, weight, distance))
        order = "distance [m],wind [m/s],release_angle [deg],counterweight [lb]"
        path.write_text(f"{OLD_HEADER}\n{order}\n{rows}\n")
    else:
        header = json.dumps({**json.loads(OLD_HEADER[2:]), "columns": OLD.split(",")})
        arrays = dict(wind=wind, release_angle=angle, counterweight=weight, distance=distance)
        np.savez(path, **arrays, header=np.frombuffer(header.encode(), dtype=np.uint8))
    data = read_throws(path)
    assert data.columns == ("time [step]", "episode", *COLUMNS) and data.metadata["noise_m"] == 0.5
    np.testing.assert_array_equal(data.episode, [0, 0, 1, 1])
    np.testing.assert_array_equal(data.observations, [[-2, 0], [-2, 74.81], [3.5, 0], [3.5, 90.25]])
    np.testing.assert_array_equal(data.actions[[0, 2]], [[45, 200], [30, 350.5]])
    assert np.isnan(data.actions[[1, 3]]).all()


@pytest.mark.parametrize(
    "body, expected",
    [
        (f"{OLD_HEADER}\nwind [m/s],release_angle [deg],distance [m]\n1,45,60\n", "missing column"),
        (
            f"{OLD_HEADER}\n{OLD}\n1,45,200,80\n2,nan,200,70\n",
            "line 4, column 'release_angle [deg]'",
        ),
        (f"{OLD_HEADER}\n{OLD}\n1,45,200,80\n2,,200,70\n", "line 4, column 'release_angle [deg]'"),
        (f"{OLD_HEADER}\n{OLD}\n1,45,200,80\n2,120,200,70\n", "outside (0, 90] degrees"),
        (f"{OLD_HEADER}\n{OLD}\n1,45,800,80\n", "line 3, column 'counterweight [lb]'"),
        (f"{OLD_HEADER}\n{OLD}\n25,45,200,80\n", "line 3, column 'wind [m/s]'"),
        (f"{OLD_HEADER}\n{OLD.replace('[m]', '[ft]')}\n1,45,200,80\n", "multiply by 0.3048"),
        (f"{OLD_HEADER}\n{OLD.replace('[m/s]', '[km/h]')}\n1,45,200,80\n", "divide by 3.6"),
        (f"{OLD_HEADER}\n{OLD.replace('[deg]', '[rad]')}\n1,0.7,200,80\n", "must be in [deg]"),
        (f"{OLD_HEADER}\n{OLD},note [1]\n1,45,200,80,0\n", "unknown column 'note [1]'"),
        (f"{OLD_HEADER}\n{OLD}\n1,45,200,far\n", "line 3, column 'distance [m]': 'far'"),
        (f"{OLD_HEADER}\n{OLD}\n1,45,200\n", "line 3: 3 cells but 4 columns"),
        (f"{OLD_HEADER}\n{OLD}\n", "holds no throws"),
        (f"{OLD}\n1,45,200,80\n", "no header"),
        (OLD_HEADER.replace('"version": 1', '"version": 7') + f"\n{OLD}\n", "version 7"),
    ],
)
def test_malformed_old_throws_csv_is_refused_by_name(tmp_path, body, expected):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(DataFileError) as e:
        read_throws(path)
    assert expected in str(e.value) and str(path) in str(e.value)


HEADER = '# {"format": "diffcontrol-trajectories", "version": 1, "metadata": {}}'
GOOD = ",".join(["time [step]", "episode", *COLUMNS])


@pytest.mark.parametrize(
    "rows, expected",
    [
        ("0,0,1,0,45,200\n1,0,1,80,45,200\n2,0,1,90,,", "episode 0 has 2 steps"),
        ("0,0,1,5,45,200\n1,0,1,80,,", "episode 0: its first row's distance is not 0"),
        ("0,7,1,0,45,200\n1,7,2,80,,", "episode 7: its two rows have different winds"),
        ("0,0,1,0,45,200\n1,0,1,80,,\n0,1,1,0,95,200\n1,1,1,80,,", "episode 1, column 'action"),
        ("0,0,25,0,45,200\n1,0,25,80,,", "column 'state.wind [m/s]': 25.0 is outside [-20, 20]"),
    ],
)
def test_throw_tables_that_are_not_throws_are_refused_by_name(tmp_path, rows, expected):
    path = tmp_path / "bad.csv"
    path.write_text(f"{HEADER}\n{GOOD}\n{rows}\n")
    with pytest.raises(DataFileError) as e:
        read_throws(path)
    assert expected in str(e.value) and str(path) in str(e.value)


def test_throw_tables_with_other_columns_are_refused_with_the_fix(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text(
        f"{HEADER}\n{GOOD.replace('distance [m]', 'distance [ft]')}\n0,0,1,0,45,200\n1,0,1,80,,\n"
    )
    with pytest.raises(DataFileError, match=r"state.distance \[ft\].*multiply by 0.3048"):
        read_throws(path)
    pendulum = diffcontrol.record("Pendulum-v1", 1, seed=0, max_steps=3)
    write_trajectories(tmp_path / "pendulum.csv", pendulum)
    with pytest.raises(DataFileError, match="unknown column 'obs.cos_theta"):
        read_throws(tmp_path / "pendulum.csv")


def test_malformed_old_throws_npz_and_paths_are_refused(tmp_path):
    good = tmp_path / "good.npz"
    header = json.dumps({**json.loads(OLD_HEADER[2:]), "columns": OLD.split(",")})
    arrays = dict(wind=[1.0, 2.0, 0.0, 0.0], release_angle=[45.0] * 4, counterweight=[200.0] * 4)
    arrays.update(distance=[80.0] * 4, header=np.frombuffer(header.encode(), dtype=np.uint8))
    np.savez(good, **arrays)
    assert read_throws(good).num_episodes == 4
    missing = {k: v for k, v in arrays.items() if k != "distance"}
    np.savez(tmp_path / "missing.npz", **missing)
    with pytest.raises(DataFileError, match=r"missing array\(s\) \['distance'\].*distance \[m\]"):
        read_throws(tmp_path / "missing.npz")
    arrays["wind"] = np.array([1.0, np.inf, 0.0, 0.0])
    np.savez(tmp_path / "inf.npz", **arrays)
    with pytest.raises(DataFileError, match=r"row 1, column 'wind \[m/s\]'"):
        read_throws(tmp_path / "inf.npz")
    with pytest.raises(DataFileError, match="does not exist"):
        read_throws(tmp_path / "nowhere.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(DataFileError, match="is empty"):
        read_throws(tmp_path / "empty.csv")


@pytest.mark.slow
def test_fit_recovers_drag_and_wind_from_noise_free_throws(recorded):
    data = read_throws(recorded)
    assert data.metadata["params"]["wind_factor"] == 1.5 and data.metadata["noise_m"] == 0
    result = fit(diffcontrol.make("trebuchet"), data.select(range(12)), "params", steps=100)
    assert not result.diverged
    for name, truth in TRUTH.items():
        assert result.values[name] == pytest.approx(truth, rel=1e-4)  # the issue asks 2 %
        assert np.isfinite(result.standard_errors[name])
    assert result.loss < 1e-6 < 100 < result.nominal_loss
    assert ft.distance_errors(result.params, data)["rmse_m"] < 1e-3


@pytest.mark.slow
def test_a_diverging_fit_keeps_the_best_parameters(recorded):
    data = read_throws(recorded).select(range(12))
    # a step of 1000 in log space sends the drag to exp(1000) = inf: a non-finite loss
    result = ft.fit_throws(data, learning_rate=1000.0, steps=20, lm_steps=5)
    assert result.diverged and "kept the best parameters so far" in result.message
    assert result.values == result.nominal  # the best seen: the starting values
    assert np.isfinite(result.loss) and np.all(np.isfinite(result.loss_history))
    assert all(np.isfinite(v) for v in result.standard_errors.values())


def test_too_few_throws_or_bad_names_are_refused():
    with pytest.raises(InsufficientDataError, match="9 recorded throw.*at least 10 are needed"):
        ft.fit_throws(_throws(9))
    with pytest.raises(ConfigError, match="unknown parameter.*'mass'.*drag_coefficient"):
        ft.fit_throws(_throws(12), ("mass",))
    with pytest.raises(ConfigError, match="max_steps"):  # static: not fittable
        ft.fit_throws(_throws(12), ("drag_coefficient", "max_steps"))
    with pytest.raises(ConfigError, match="must be finite, and positive"):
        ft.fit_throws(_throws(12), init={"drag_coefficient": -1.0})
    with pytest.raises(ConfigError, match="noise_m"):
        rec.record_throws(3, noise_m=-1.0)
    with pytest.raises(ConfigError, match="weight_lb"):
        rec.record_throws(3, inputs=(0.0, 45.0, 900.0))


@pytest.mark.slow
def test_cli_fit_trebuchet_end_to_end(recorded, tmp_path, capsys):
    out = tmp_path / "fit"
    argv = ["fit", "trebuchet", "--data", str(recorded), "--model", "params", "--out", str(out)]
    assert main([*argv, "--steps", "100", "--lm-steps", "10"]) == 0
    doc = json.loads((out / "fitted.json").read_text())
    assert doc["format"] == "diffcontrol-fitted-model" and doc["task"] == "trebuchet"
    for name, truth in TRUTH.items():
        assert doc["parameters"][name]["value"] == pytest.approx(truth, rel=1e-3)
        assert doc["all_parameters"][name] == doc["parameters"][name]["value"]
    assert set(doc["all_parameters"]) == set(rec.parameter_names())  # floats only
    err = doc["prediction_error"]
    assert doc["data"]["held_out_throws"] == 3
    assert err["fitted"]["rmse_m"] < 1e-2 < 5 < err["nominal"]["rmse_m"]
    assert (out / "prediction.png").stat().st_size > 0
    assert "held-out RMS distance error over 3 throw(s)" in capsys.readouterr().out

    assert main([*argv, "--model", "hybrid"]) == 2
    assert "not supported for aiming tasks" in capsys.readouterr().err
    assert main([*argv, "--force", "--holdout", "0.4"]) == 2
    assert "leaves 9 to fit" in capsys.readouterr().err


def test_cli_record_trebuchet_refuses_bad_requests(tmp_path, capsys):
    out = str(tmp_path / "t.csv")
    assert (
        main(["record", "trebuchet", "--episodes", "3", "--env-arg", "mass=2", "--out", out]) == 2
    )
    assert "no parameter 'mass'" in capsys.readouterr().err
    argv = ["record", "Pendulum-v1", "--episodes", "1", "--noise-m", "0.5", "--out", out]
    assert main(argv) == 2
    assert "--noise-m does not apply to recording Pendulum-v1" in capsys.readouterr().err
    argv = ["record", "Pendulum-v1", "--task", "trebuchet", "--episodes", "12", "--out", out]
    assert main(argv) == 2
    assert "an environment id does not apply to the trebuchet" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_loop_trebuchet_records_throws_fits_and_aims(tmp_path, capsys):
    out = tmp_path / "loop"
    argv = ["loop", "trebuchet", *REAL_ARGS, "--rounds", "2", "--episodes", "10"]
    argv += ["--updates", "20", "--eval-episodes", "20", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    data = read_throws(out / "data.csv")
    assert data.num_episodes == data.num_steps == 20
    sources = data.metadata["sources"]
    assert sources[0] == "simulated trebuchet, random inputs"
    assert sources[1] == f"controller {out / 'round_1' / 'run'}"
    doc = json.loads((out / "loop.json").read_text())
    for r in doc["rounds"]:  # noise-free throws: the real parameters
        for name, truth in TRUTH.items():
            assert r["fitted_parameters"][name] == pytest.approx(truth, rel=1e-4)
    metrics = json.loads((out / "round_2" / "run" / "metrics.json").read_text())
    assert metrics["model"]["real_system"]["params"]["drag_coefficient"] == 1.5
