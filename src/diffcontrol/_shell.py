"""Commands the library prints for the user to run next, quoted for a POSIX shell."""

from __future__ import annotations

import os
import shlex


def command(*words: str | os.PathLike) -> str:
    """``diffcontrol WORDS...`` as one line that a POSIX shell reads back as exactly these
    words (``shlex.join``): a path with a space, a ``;`` or a ``$(...)`` is quoted, so pasting
    a printed resume command runs nothing but diffcontrol."""
    return shlex.join(["diffcontrol", *map(os.fspath, words)])
