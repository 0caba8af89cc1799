"""``python -m diffcontrol.cli``."""

from . import run

run()
