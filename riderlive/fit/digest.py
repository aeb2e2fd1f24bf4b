"""A take file's SHA-256, for the provenance a fitted preset carries (read in 1 MiB blocks)."""

from __future__ import annotations

import hashlib
from pathlib import Path


def sha256(path: str) -> str:
    """The hex SHA-256 of the file at ``path``."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
