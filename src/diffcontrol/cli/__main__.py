"""``python -m diffcontrol.cli``."""

from . import run

raise SystemExit(run())
