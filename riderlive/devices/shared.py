"""Named float64 slots in a shared-memory segment, for state that crosses processes.

Used by the e-stop latch and the safety board (heartbeats, pids, last poses). Each
slot is one aligned 8-byte store, so a reader on another core sees either the old or
the new value; a slot that a single process writes needs no lock. Segments live in
``/dev/shm`` (Linux), where a file lock on the segment itself is also available.
"""

from __future__ import annotations

import os
import tempfile
from multiprocessing import resource_tracker, shared_memory
from pathlib import Path
from typing import Any, ClassVar, Generic, Protocol, TypeVar, overload

N = TypeVar("N", int, float)


def attach(name: str) -> shared_memory.SharedMemory:
    """Open an existing segment without registering it with this process's tracker.

    The creating process owns (and unlinks) the segment; a second registration from
    an attaching process would unlink it early or warn at exit (Python < 3.13).
    """
    register = resource_tracker.register
    resource_tracker.register = lambda *args, **kwargs: None  # type: ignore[assignment]
    try:
        return shared_memory.SharedMemory(name=name, create=False)
    finally:
        resource_tracker.register = register


def lock_path(name: str) -> Path:
    """A file to ``flock`` that belongs to segment ``name`` (the segment itself on Linux)."""
    shm = Path("/dev/shm") / name
    return shm if shm.exists() else Path(tempfile.gettempdir()) / f"{name}.lock"


class Slots:
    """``names`` float64 slots in a segment: created (``name`` None) or attached; read and
    written through a :class:`SlotBlock` subclass's typed slots (by attribute, never by name)."""

    def __init__(self, names: tuple[str, ...], name: str | None = None) -> None:
        self.names = names
        size = 8 * len(names)
        if name is None:
            self._shm = shared_memory.SharedMemory(create=True, size=size)
            self.owner = True
        else:
            self._shm = attach(name)
            self.owner = False
        self.values = _Values(self._shm, len(names))
        if self.owner:
            for i in range(len(names)):
                self.values[i] = 0.0

    def __del__(self) -> None:
        """Never closed (a test, an exiting process): the views go first, so that the
        segment's own finalizer can close it."""
        values = getattr(self, "values", None)
        if values is not None:
            values.release()

    @property
    def name(self) -> str:
        return self._shm.name

    def close(self) -> None:
        """Detach; the owner also removes the segment (and its lock file, off Linux)."""
        self.values.release()
        self._shm.close()
        if self.owner:
            path = lock_path(self._shm.name)
            self._shm.unlink()
            if path.parent != Path("/dev/shm"):
                path.unlink(missing_ok=True)


class _Values:
    """float64 slot ``i`` of a segment, read and written in place, each read and each write
    one aligned 8-byte access: another process never sees a value half written.

    Not ``struct.pack_into``: it zero-fills its target before packing (CPython's
    ``s_pack_internal``), so a reader in another process saw 0.0 in ~5 % of its reads of
    a slot written in a loop (the soak's "the guardian has not beaten for 23425072 ms":
    a beat read as 0; ``tests/devices/test_shared.py``). A ``memoryview`` cast to ``d``
    stores and loads a double with one ``memcpy`` of constant size 8 (one instruction).
    The views are released by :meth:`release` before the segment is closed."""

    def __init__(self, shm: shared_memory.SharedMemory, count: int) -> None:
        buf = shm.buf
        if buf is None:
            raise ValueError(f"shared memory {shm.name} is closed")
        self._bytes = buf[: 8 * count]
        self._view = self._bytes.cast("d")

    def __getitem__(self, i: int) -> float:
        value: float = self._view[i]
        return value

    def __setitem__(self, i: int, value: float) -> None:
        self._view[i] = value

    def release(self) -> None:
        """Drop the views (the segment can be closed after this)."""
        self._view.release()
        self._bytes.release()


def pid_alive(pid: int) -> bool:
    """True while process ``pid`` exists and has not exited (a zombie counts as dead)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True  # no /proc: trust kill(0)
    return stat.rsplit(")", 1)[-1].split()[0] not in ("Z", "X")


class _Store(Protocol):
    def __getitem__(self, i: int, /) -> Any: ...
    def __setitem__(self, i: int, value: float, /) -> None: ...


class _Holder(Protocol):
    @property
    def values(self) -> _Store: ...


class Slot(Generic[N]):
    """One named float64 slot of a :class:`SlotBlock`, read and written by attribute.

    ``kind`` is how a reader sees it (``int``: a pid, a count, a generation; ``float``: a
    time or a value); it is stored as float64 either way (exact for integers below 2**53).
    ``writer`` documents the one process that writes it (each slot has exactly one)."""

    def __init__(self, kind: type[N], writer: str, doc: str = "") -> None:
        self.kind: type[N] = kind
        self._int = kind is int
        self.writer = writer
        self.doc = doc
        self.name = ""
        self.index = -1

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @overload
    def __get__(self, obj: None, owner: type) -> Slot[N]: ...
    @overload
    def __get__(self, obj: _Holder, owner: type) -> N: ...
    def __get__(self, obj: _Holder | None, owner: type) -> Slot[N] | N:
        if obj is None:
            return self
        value = obj.values[self.index]  # a float (numpy's float64 is one): no conversion on the hot path
        out: N = int(value) if self._int else value
        return out

    def __set__(self, obj: _Holder, value: N) -> None:
        obj.values[self.index] = value


class SlotBlock:
    """A typed set of :class:`Slot` over a store of float64 (declaration order is slot order).

    A subclass declares its slots as class attributes and has a ``values`` store (a float64
    array, or :class:`Slots`' values); :meth:`slot_names` lists them (the names the store's
    segment is made with: one source for both processes)."""

    _slots: ClassVar[tuple[Slot[Any], ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        own = [v for v in vars(cls).values() if isinstance(v, Slot)]
        for i, slot in enumerate(own, start=len(cls._slots)):
            slot.index = i
        cls._slots = (*cls._slots, *own)

    @classmethod
    def slot_names(cls) -> tuple[str, ...]:
        return tuple(s.name for s in cls._slots)

    @classmethod
    def slots(cls) -> tuple[Slot[Any], ...]:
        return cls._slots

    @classmethod
    def slot(cls, name: str) -> Slot[Any]:
        """The slot called ``name`` (KeyError naming the known ones otherwise)."""
        for s in cls._slots:
            if s.name == name:
                return s
        raise KeyError(f"{cls.__name__} has no slot {name!r} (slots: {', '.join(cls.slot_names())})")
