"""Print the lowest versions pyproject.toml allows, one ``name==floor`` a line, for pip's
``-c``: every direct dependency of the package and of the extras named on the command line
at the floor of its range (what ``uv pip install --resolution lowest-direct`` picks), so that
a test run on them checks the floors the pins claim.

Usage: python .ci/floors.py EXTRA [EXTRA ...] > floors.txt
"""

import re
import sys
import tomllib
from pathlib import Path

project = tomllib.loads((Path(__file__).parent.parent / "pyproject.toml").read_text())["project"]
requirements = list(project["dependencies"])
for extra in sys.argv[1:]:
    requirements += project["optional-dependencies"][extra]
for requirement in requirements:
    match = re.match(r"\s*([A-Za-z0-9_.-]+)(?:\[[^\]]*\])?\s*>=\s*([^,;\s]+)", requirement)
    if match is None:
        sys.exit(f"{requirement!r} has no floor (>=): give it one")
    print(f"{match[1]}=={match[2]}")
