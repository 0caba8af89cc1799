"""The settings of fit, loop and compare: checked on construction, and the command line's flags
are their fields (the name, the default, the bounds and the help come from one place)."""

from __future__ import annotations

import dataclasses

import pytest

from diffcontrol.cli import COMMANDS, build_parser
from diffcontrol.cli import _args as a
from diffcontrol.config import ODETrainConfig, TrainConfig
from diffcontrol.errors import ConfigError
from diffcontrol.settings import CompareConfig, FitConfig, LoopConfig

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
        (CompareConfig, dict(seeds=2**21), "seeds must be at most 1,048,576"),
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
