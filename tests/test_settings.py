"""Every configuration (training, record, fit, loop, compare, plan): checked on construction,
and the command line's flags are their fields (the name, the default, the bounds and the help
come from one place, the fields' metadata)."""

from __future__ import annotations

import argparse
import dataclasses
import math

import pytest

from diffcontrol.cli import COMMANDS, build_parser
from diffcontrol.cli import _args as a
from diffcontrol.config import ODETrainConfig, TrainConfig
from diffcontrol.errors import ConfigError
from diffcontrol.settings import CompareConfig, FitConfig, LoopConfig, PlanConfig, RecordConfig

SETTINGS = (FitConfig, LoopConfig, CompareConfig)


@pytest.mark.parametrize(
    "cls, changes, message",
    [
        (LoopConfig, dict(rounds=0), "rounds must be a positive integer, got 0"),
        (LoopConfig, dict(seed=-1), "seed must be an integer >= 0, got -1"),
        (LoopConfig, dict(explore_noise=1.5), "explore_noise must be in [0, 1], got 1.5"),
        (LoopConfig, dict(model="grey"), "model must be one of params, hybrid, neural"),
        (LoopConfig, dict(names="g"), "names must be names such as"),
        (FitConfig, dict(hidden=(32, 0)), "hidden must be positive layer widths"),
        (FitConfig, dict(window=True), "window must be a positive integer"),
        (CompareConfig, dict(seeds=2**21), "seeds must be in 1 ... 1,048,576"),
        (CompareConfig, dict(torch_threads=0), "torch_threads must be a positive integer"),
    ],
)
def test_bad_settings_are_refused_with_their_name(cls, changes, message):
    with pytest.raises(ConfigError, match="^" + message.replace("[", r"\[").replace("(", r"\(")):
        cls(**changes)


def test_settings_round_trip_through_their_flags():
    """Every field of each settings class is a flag; the flags given make those settings,
    the others keep the field's default."""
    parser = a.Parser(prog="t")
    sub = parser.add_subparsers(dest="command")
    for cls in SETTINGS:
        a.add(sub.add_parser(cls.__name__), *a.config_specs(cls))
    args = parser.parse_args(["LoopConfig", "--params", "g,friction", "--start", "g=8",
                              "--rounds", "4", "--explore-noise", "0.1"])  # fmt: skip
    config = a.config_of(LoopConfig, args)
    assert config == LoopConfig(names=("g", "friction"), start={"g": 8.0}, rounds=4,
                                explore_noise=0.1)  # fmt: skip
    args = parser.parse_args(["FitConfig", "--hidden", "8,8", "--holdout", "0"])
    assert a.config_of(FitConfig, args) == FitConfig(hidden=(8, 8), holdout=0.0)
    args = parser.parse_args(["CompareConfig"])
    assert a.config_of(CompareConfig, args) == CompareConfig()


def test_every_training_field_is_a_train_flag_and_every_command_runs_a_function():
    parser = build_parser()
    sub = next(act for act in parser._actions if act.dest == "command")
    assert set(sub.choices) == set(COMMANDS)
    train = {opt for act in sub.choices["train"]._actions for opt in act.option_strings}
    for cls in (TrainConfig, ODETrainConfig):
        for f in dataclasses.fields(cls):
            flag = "--param" if f.name == "params" else "--" + f.name.replace("_", "-")
            assert flag in train, flag


CONFIGS = (
    TrainConfig,
    ODETrainConfig,
    RecordConfig,
    FitConfig,
    LoopConfig,
    CompareConfig,
    PlanConfig,
)
# rules between fields, which the flags (one value each) cannot know
_BETWEEN_FIELDS = {(c, "value_grid", n) for c in ("TrainConfig", "PlanConfig") for n in (1, 2)}


def _accepts(parse, text: str) -> bool:
    try:
        parse(text)
    except argparse.ArgumentTypeError:
        return False
    return True


@pytest.mark.parametrize("cls", CONFIGS, ids=lambda c: c.__name__)
def test_the_flags_and_the_configs_take_the_same_numbers(cls):
    """One rule per field, read by both sides: every number a field's flag refuses, the
    configuration refuses too (naming the field), and every number the flag takes, the
    configuration takes."""
    required = {"episodes": 1} if cls is RecordConfig else {}
    specs = {spec[0]: spec for spec in a.config_specs(cls, skip=("params",))}
    checked = 0
    for f in (f for f in dataclasses.fields(cls) if f.name != "params"):
        parse = specs["--" + f.metadata.get("flag", f.name).replace("_", "-")][1]
        declared = str(f.type).removesuffix(" | None")
        if declared == "int":
            low, high = a.int_bounds(f)
            values = [low - 1, low, low + 1, high, high + 1, 2**40]
        elif declared == "float":
            values = [-1.0, 0.0, 1e-9, 0.5, 1.0, 2.0, 1e7, math.inf, -math.inf, math.nan]
        else:
            continue
        for value in values:
            if (cls.__name__, f.name, value) in _BETWEEN_FIELDS:
                continue
            flag_takes = _accepts(parse, repr(value) if declared == "float" else str(value))
            try:
                cls(**{**required, f.name: value})
                config_takes = True
            except ConfigError as e:
                assert str(e).startswith(f.name + " must be"), str(e)
                config_takes = False
            assert flag_takes == config_takes, (cls.__name__, f.name, value, flag_takes)
            checked += 1
    assert checked >= 6 * 3


def test_a_config_round_trips_through_json():
    config = TrainConfig(target_return=100.0, hidden=(8, 4), params=(("g", 9.0),))
    doc = config.to_json()
    assert doc["hidden"] == [8, 4] and doc["params"] == [["g", 9.0]]
    assert TrainConfig.from_json(doc) == config
    nan = TrainConfig().to_json()
    assert nan["target_return"] is None and math.isnan(TrainConfig.from_json(nan).target_return)
    assert PlanConfig.from_json(PlanConfig(dt=0.05).to_json()) == PlanConfig(dt=0.05)
    with pytest.raises(ConfigError, match="unknown PlanConfig keys"):
        PlanConfig.from_json({"horizonn": 3})
    with pytest.raises(ConfigError, match="PlanConfig must be an object"):
        PlanConfig.from_json([3])
