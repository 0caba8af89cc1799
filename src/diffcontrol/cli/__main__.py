"""``python -m diffcontrol.cli``."""

from . import main

raise SystemExit(main())
