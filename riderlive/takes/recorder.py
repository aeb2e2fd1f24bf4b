"""Recording a take: one CSV row per tick, ``t`` then the horse then the rider channels.

The file is a frame file (:func:`riderlive.framefile.read_frames`), so ``bake`` and
``plot`` read it as it is. Rows are buffered and written with one ``write`` of whole
lines at least every ``flush_interval`` seconds, so a killed server (even ``kill -9``)
leaves a readable file that lacks at most the last interval. ``t`` is the take's own
time (seconds from the first row); the engine time of the first row is in a sidecar
``.json`` beside it.
"""

from __future__ import annotations

import fcntl
import os
import re
import time
from collections.abc import Iterable
from pathlib import Path

import orjson

from riderlive.channels import HORSE_NAMES, RIDER_NAMES

COLUMNS: tuple[str, ...] = ("t", *HORSE_NAMES, *RIDER_NAMES)
_SAFE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")


def take_path(directory: str | Path, name: str) -> Path:
    """The file of take ``name`` (letters, digits, ``_ . -``; no paths)."""
    stem = name[:-4] if name.endswith(".csv") else name
    if not _SAFE.match(stem) or ".." in stem:
        raise ValueError(f"bad take name {name!r}: use letters, digits, '_', '.', '-'")
    return Path(directory) / f"{stem}.csv"


def list_takes(directory: str | Path) -> list[dict[str, object]]:
    """Takes in ``directory``, newest first: name, bytes, modification time."""
    folder = Path(directory)
    if not folder.is_dir():
        return []
    files = sorted(folder.glob("*.csv"), key=lambda p: p.stat().st_mtime, reverse=True)
    return [{"name": p.stem, "bytes": p.stat().st_size, "modified": p.stat().st_mtime} for p in files]


class TakeRecorder:
    """An open take; ``add`` a row per tick, ``close`` at the end."""

    def __init__(
        self,
        path: Path,
        flush_interval: float = 0.5,
        meta: dict[str, object] | None = None,
        extra: tuple[str, ...] = (),
    ) -> None:
        """``extra``: channels after the rider's (the tail's); ``add`` takes them at the end of ``rider``."""
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.flush_interval = flush_interval
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        fcntl.flock(self._fd, fcntl.LOCK_EX)  # "being recorded" for readers (riderlive export); gone with the process
        os.write(self._fd, (",".join((*COLUMNS, *extra)) + "\n").encode())
        self._lines: list[str] = []
        self._last_flush = time.monotonic()
        self._t0: float | None = None
        self.rows = 0
        self.meta = dict(meta or {})

    def add(self, engine_t: float, horse: Iterable[float], rider: Iterable[float]) -> None:
        if self._t0 is None:
            self._t0 = engine_t
            self.meta["engine_t0"] = engine_t
        row = [engine_t - self._t0, *horse, *rider]
        self._lines.append(",".join(map(repr, map(float, row))))
        self.rows += 1
        if time.monotonic() - self._last_flush >= self.flush_interval:
            self.flush()

    def flush(self) -> None:
        """Write every complete buffered row with one system call."""
        if self._lines:
            data = ("\n".join(self._lines) + "\n").encode()
            self._lines.clear()
            view = memoryview(data)
            while view:
                written = os.write(self._fd, view)
                view = view[written:]
        self._last_flush = time.monotonic()

    def close(self) -> None:
        self.flush()
        os.close(self._fd)
        self.path.with_suffix(".json").write_bytes(orjson.dumps({**self.meta, "rows": self.rows}))
