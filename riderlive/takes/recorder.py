"""Recording a take: one CSV row per tick, ``t`` then the horse then the rider channels.

The file is a frame file (:func:`riderlive.framefile.read_frames`), so ``bake`` and
``plot`` read it as it is. Rows are buffered and written with one ``write`` of whole
lines at least every ``flush_interval`` seconds. ``t`` is the take's own time
(seconds from the first row).

Nothing is lost or overwritten without being asked:

- a new take never replaces a file (``O_EXCL``; :class:`TakeExists`), unless
  ``overwrite``: then it is recorded beside (``.NAME.recording.csv``) and renamed over
  the old take only when it is complete, so a failure keeps the old one;
- the sidecar ``NAME.json`` (session, tick rate, preset, length scale, engine time and
  ``CLOCK_MONOTONIC`` time of the first row, rows, ``complete``) is written at the
  start and replaced (atomically) at every flush, so a killed server (even
  ``kill -9``) leaves a take and a sidecar that say what they hold; at most the last
  ``flush_interval`` plus one tick is lost. :func:`recover_take` trims a last line
  that a kill cut short (the service does it at start and before a replay).
"""

from __future__ import annotations

import fcntl
import os
import time
from collections.abc import Callable, Iterable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import orjson

from riderlive.channels import HORSE_GROUND, HORSE_NAMES, HORSE_OPTIONAL, RIDER_NAMES
from riderlive.names import check_name

COLUMNS: tuple[str, ...] = ("t", *HORSE_NAMES, *RIDER_NAMES)


class TakeExists(FileExistsError):
    """A take of that name is on disk already (pass ``overwrite`` to replace it)."""


def take_path(directory: str | Path, name: str) -> Path:
    """The file of take ``name`` (:data:`riderlive.names.NAME_PATTERN`; never a path)."""
    return Path(directory) / f"{check_name(name, 'take')}.csv"


def sidecar_path(path: Path) -> Path:
    return path.with_suffix(".json")


def read_sidecar(path: Path) -> dict[str, Any] | None:
    """The sidecar of take file ``path`` (None when missing or unreadable)."""
    try:
        meta = orjson.loads(sidecar_path(path).read_bytes())
    except (OSError, orjson.JSONDecodeError):
        return None
    return meta if isinstance(meta, dict) else None


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def replay_path(directory: str | Path, name: str) -> Path:
    """The file to replay for take ``name``: ``NAME.csv``, or ``NAME.parquet`` when only that exists."""
    if name.endswith(".parquet"):
        return take_path(directory, name[: -len(".parquet")]).with_suffix(".parquet")
    path = take_path(directory, name)
    parquet = path.with_suffix(".parquet")
    return parquet if not path.exists() and parquet.exists() else path


def list_takes(directory: str | Path, order: str = "modified") -> list[dict[str, object]]:
    """Takes in ``directory``: name, bytes, modification time, rows, complete and the start
    timecode (sidecar). ``order``: ``modified`` (newest first) or ``timecode`` (earliest
    start label first, as seconds of the day; takes without a timecode last)."""
    folder = Path(directory)
    if not folder.is_dir():
        return []
    out: list[tuple[float, dict[str, object]]] = []
    for path in [*folder.glob("*.csv"), *folder.glob("*.parquet")]:
        if path.name.startswith("."):
            continue
        try:
            stat = path.stat()
        except OSError:  # removed meanwhile
            continue
        meta = read_sidecar(path) or {}
        entry = {"name": path.stem, "bytes": stat.st_size, "modified": stat.st_mtime}
        entry |= {"rows": meta.get("rows"), "complete": meta.get("complete")}
        entry |= {key: meta.get(key) for key in ("timecode", "timecode_rate", "timecode_source")}
        out.append((stat.st_mtime, entry))
    newest = [entry for _, entry in sorted(out, key=lambda item: item[0], reverse=True)]
    return newest if order == "modified" else sorted(newest, key=_timecode_key)


def _timecode_key(entry: dict[str, object]) -> tuple[float, str]:
    """Seconds of the day of a listed take's start label (inf: none or unreadable), then the name."""
    from riderlive.takes.stamp import take_timecode
    from riderlive.timecode import TimecodeError, frames_to_seconds

    try:
        stamp = take_timecode(entry)
    except TimecodeError:
        stamp = None
    seconds = float("inf") if stamp is None else frames_to_seconds(stamp.frames, stamp.rate)
    return seconds, str(entry["name"])


def recover_take(path: Path) -> bool:
    """Make a take that a kill interrupted whole again: trim a cut last line, count rows.

    Returns True when the sidecar said the take was incomplete (it is marked
    ``recovered`` and ``complete`` now). A take being recorded must not be passed.
    """
    meta = read_sidecar(path)
    if meta is None or meta.get("complete", True):
        return False
    with path.open("rb+") as fh:
        data = fh.read()
        end = data.rfind(b"\n") + 1
        if end < len(data):
            fh.truncate(end)
    rows = max(0, data.count(b"\n", 0, end) - 1)
    _write_atomic(sidecar_path(path), orjson.dumps({**meta, "rows": rows, "complete": True, "recovered": True}))
    return True


_BEFORE_OPTIONAL = (len(HORSE_NAMES) - len(HORSE_OPTIONAL), len(HORSE_NAMES) - len(HORSE_GROUND))
"""Horse frames of these lengths lack the optional channels (``channels.HORSE_OPTIONAL``): from
before the neck and head, or before the ground. They are recorded at rest (0: on the trunk, flat)."""


class TakeRecorder:
    """An open take; ``add`` a row per tick, ``close`` at the end."""

    def __init__(
        self,
        path: Path,
        flush_interval: float = 0.25,
        meta: dict[str, object] | None = None,
        extra: tuple[str, ...] = (),
        overwrite: bool = False,
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``extra``: channels after the rider's (the tail's); ``add`` takes them at the end of ``rider``.
        ``clock``: seconds for ``flush_interval`` (``CLOCK_MONOTONIC``; a test's own clock).

        Raises :class:`TakeExists` when ``path`` exists and not ``overwrite``.
        """
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.flush_interval = flush_interval
        self._clock = clock
        self._file = path.with_name(f".{path.stem}.recording.csv") if overwrite else path
        flags = os.O_WRONLY | os.O_CREAT | (0 if overwrite else os.O_EXCL)
        try:
            self._fd = os.open(self._file, flags, 0o644)
        except FileExistsError:
            raise TakeExists(f"take {path.stem!r} exists; choose another name or pass overwrite") from None
        try:  # "being recorded" for readers (riderlive export); gone with the process. Never waits:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # a recorder of this very file holds it
        except BlockingIOError:
            os.close(self._fd)
            raise TakeExists(f"take {path.stem!r} is being recorded (overwrite it once it has stopped)") from None
        os.ftruncate(self._fd, 0)  # only now: an overwrite that is refused truncates nothing
        os.write(self._fd, (",".join((*COLUMNS, *extra)) + "\n").encode())
        self._lines: list[str] = []
        self._last_flush = self._clock()
        self._t0: float | None = None
        self.rows = 0
        self.meta: dict[str, object] = {
            "name": path.stem,
            "started": datetime.now(UTC).isoformat(timespec="seconds"),
            **(meta or {}),
            "rows": 0,
            "complete": False,
        }
        self._write_sidecar()

    def _write_sidecar(self) -> None:
        _write_atomic(sidecar_path(self._file), orjson.dumps({**self.meta, "rows": self.rows}))

    def add(self, engine_t: float, horse: Iterable[float], rider: Iterable[float], monotonic: float = 0.0) -> None:
        """One tick; ``monotonic``: the ``CLOCK_MONOTONIC`` time of ``engine_t`` (for the sidecar)."""
        if self._t0 is None:
            self._t0 = engine_t
            self.meta["engine_t0"] = engine_t
            if monotonic:
                self.meta["monotonic_t0"] = monotonic
        horse = list(horse)
        if len(horse) in _BEFORE_OPTIONAL:  # a frame from before the optional channels: at rest
            horse += [0.0] * (len(HORSE_NAMES) - len(horse))
        row = [engine_t - self._t0, *horse, *rider]
        self._lines.append(",".join(map(repr, map(float, row))))
        self.rows += 1
        if self._clock() - self._last_flush >= self.flush_interval:
            self.flush()

    def flush(self) -> None:
        """Write every complete buffered row with one system call, then the sidecar."""
        if self._lines:
            data = ("\n".join(self._lines) + "\n").encode()
            self._lines.clear()
            view = memoryview(data)
            while view:
                written = os.write(self._fd, view)
                view = view[written:]
            self._write_sidecar()
        self._last_flush = self._clock()

    def close(self) -> None:
        """Flush, mark complete, and (``overwrite``) put the new take in place of the old."""
        self.flush()
        os.close(self._fd)
        self.meta["complete"] = True
        self._write_sidecar()
        if self._file != self.path:
            os.replace(sidecar_path(self._file), sidecar_path(self.path))
            os.replace(self._file, self.path)
