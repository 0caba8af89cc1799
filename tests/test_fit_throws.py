"""The trebuchet's grey box (``diffcontrol.fit_throws``, ``diffcontrol record/fit trebuchet``).

The "real" trebuchet has drag coefficient 1.5 and wind factor 1.5 (the nominal model has 1 and
1). Every throw batch has 15 or 12 throws, so that the compiled throw programs are shared
between the tests (a new batch size compiles the trebuchet again, about 10 s).
"""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, DataFileError, InsufficientDataError
from diffcontrol.identify import throws as ft
from diffcontrol.identify.data import THROW_COLUMNS, ThrowData, read_throws, write_throws
from diffcontrol.systems import trebuchet as tb

TRUTH = {"drag_coefficient": 1.5, "wind_factor": 1.5}
REAL_ARGS = [f"--env-arg={n}={v}" for n, v in TRUTH.items()]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """15 noise-free throws of the real trebuchet, recorded by the CLI (shared, read-only)."""
    path = tmp_path_factory.mktemp("throws") / "real.csv"
    argv = ["record", "trebuchet", "--episodes", "15", "--out", str(path), "--quiet"]
    assert main([*argv, *REAL_ARGS, "--seed", "3"]) == 0
    return path


def _throws(n=4, **meta):
    rng = np.random.default_rng(0)
    return ThrowData(
        rng.normal(0, 5, n),
        rng.uniform(20, 70, n),
        rng.uniform(50, 450, n),
        rng.uniform(10, 90, n),
        meta,
    )


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


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_throws_file_round_trip(tmp_path, suffix):
    data = _throws(5, system="trebuchet", params={"drag_coefficient": 1.5}, noise_m=0.5)
    path = tmp_path / f"t{suffix}"
    write_throws(path, data)
    back = read_throws(path)
    for name in ("wind", "release_angle", "counterweight", "distance"):
        np.testing.assert_array_equal(getattr(back, name), getattr(data, name))
    assert back.metadata == data.metadata
    if suffix == ".csv":
        assert path.read_text().splitlines()[1] == ",".join(THROW_COLUMNS)


HEADER = '# {"format": "diffcontrol-throws", "version": 1, "metadata": {}}'
GOOD = "wind [m/s],release_angle [deg],counterweight [lb],distance [m]"


@pytest.mark.parametrize(
    "body, expected",
    [
        (f"{HEADER}\nwind [m/s],release_angle [deg],distance [m]\n1,45,60\n", "missing column"),
        (f"{HEADER}\n{GOOD}\n1,45,200,80\n2,nan,200,70\n", "line 4, column 'release_angle [deg]'"),
        (f"{HEADER}\n{GOOD}\n1,45,200,80\n2,,200,70\n", "line 4, column 'release_angle [deg]'"),
        (f"{HEADER}\n{GOOD}\n1,45,200,80\n2,120,200,70\n", "outside (0, 90] degrees"),
        (f"{HEADER}\n{GOOD}\n1,45,800,80\n", "line 3, column 'counterweight [lb]'"),
        (f"{HEADER}\n{GOOD}\n25,45,200,80\n", "line 3, column 'wind [m/s]'"),
        (f"{HEADER}\n{GOOD.replace('[m]', '[ft]')}\n1,45,200,80\n", "multiply by 0.3048"),
        (f"{HEADER}\n{GOOD.replace('[m/s]', '[km/h]')}\n1,45,200,80\n", "divide by 3.6"),
        (f"{HEADER}\n{GOOD.replace('[deg]', '[rad]')}\n1,0.7,200,80\n", "must be in [deg]"),
        (f"{HEADER}\n{GOOD},note [1]\n1,45,200,80,0\n", "unknown column 'note [1]'"),
        (f"{HEADER}\n{GOOD}\n1,45,200,far\n", "line 3, column 'distance [m]': 'far'"),
        (f"{HEADER}\n{GOOD}\n1,45,200\n", "line 3: 3 cells but 4 columns"),
        (f"{HEADER}\n{GOOD}\n", "holds no throws"),
        (f"{GOOD}\n1,45,200,80\n", "no header"),
        (
            '# {"format": "diffcontrol-trajectories", "version": 1}\n' + GOOD,
            "it holds trajectories",
        ),
        (HEADER.replace('"version": 1', '"version": 7') + f"\n{GOOD}\n", "version 7"),
    ],
)
def test_malformed_throws_csv_is_refused_by_name(tmp_path, body, expected):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(DataFileError) as e:
        read_throws(path)
    assert expected in str(e.value) and str(path) in str(e.value)


def test_malformed_throws_npz_and_paths_are_refused(tmp_path):
    good = tmp_path / "good.npz"
    write_throws(good, _throws())
    arrays = dict(np.load(good))
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
    with pytest.raises(DataFileError, match="use a .csv or .npz"):
        write_throws(tmp_path / "t.txt", _throws())
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(DataFileError, match="is empty"):
        read_throws(tmp_path / "empty.csv")


@pytest.mark.slow
def test_fit_recovers_drag_and_wind_from_noise_free_throws(recorded):
    data = read_throws(recorded)
    assert data.metadata["params"]["wind_factor"] == 1.5 and data.metadata["noise_m"] == 0
    result = ft.fit_throws(data.select(slice(0, 12)), steps=100)
    assert not result.diverged
    for name, truth in TRUTH.items():
        assert result.values[name] == pytest.approx(truth, rel=1e-4)  # the issue asks 2 %
        assert np.isfinite(result.standard_errors[name])
    assert result.loss < 1e-6 < 100 < result.nominal_loss
    assert ft.distance_errors(result.params, data)["rmse_m"] < 1e-3


@pytest.mark.slow
def test_a_diverging_fit_keeps_the_best_parameters(recorded):
    data = read_throws(recorded).select(slice(0, 12))
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
        ft.record_throws(3, noise_m=-1.0)
    with pytest.raises(ConfigError, match="weight_lb"):
        ft.record_throws(3, inputs=(0.0, 45.0, 900.0))


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
    assert set(doc["all_parameters"]) == set(ft.parameter_names())  # floats only
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
    assert "--noise-m applies to `diffcontrol record trebuchet` only" in capsys.readouterr().err
