"""Names that users give things (takes, presets): plain words, never paths.

A name is 1-64 characters of ``A-Z a-z 0-9 _ -``, starting with a letter or a digit:
no dots, no slashes, so ``directory / (name + suffix)`` never leaves its directory and
never names a hidden or special file.
"""

from __future__ import annotations

import re

NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$"
"""The pattern of every user-given name (also in the REST schema)."""
_NAME = re.compile(NAME_PATTERN)


def check_name(name: str, what: str) -> str:
    """``name`` if it is a name, else ValueError saying the pattern."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        shown = repr(name[:70]) if isinstance(name, str) else type(name).__name__
        raise ValueError(f"bad {what} name {shown}: 1-64 of A-Z a-z 0-9 _ -, starting with a letter or digit")
    return name
