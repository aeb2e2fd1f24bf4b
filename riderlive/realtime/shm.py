"""Seqlock'd rings of float64 records in shared memory, between two processes.

One writer, one reader per ring. Record ``k`` lives in slot ``k % capacity``; the
slot's sequence word is ``2k + 1`` while the writer fills it and ``2k + 2`` once it is
complete, and the ring's ``head`` (records ever written) is bumped last. A reader
copies a slot and accepts it only if the sequence word was ``2k + 2`` before and
after the copy, so it never sees a torn record and knows when it was lapped.

Layout of one segment (little-endian, native on every supported machine)::

    int64  header[8]      head, capacity, width, pending, 0...
    int64  seq[capacity]  per-slot sequence word
    float64 data[capacity, width]

The stores are plain NumPy writes: x86-64 and ARMv8 keep a single writer's stores
in order for a reader on another core closely enough for this protocol, because the
reader re-checks the sequence word after copying.

``pending`` is the writer's note that a record is on its way: the ``perf_counter``
nanoseconds at which the input it will carry was received (0: none). The tick reads it
to wait a moment for a frame received just before its deadline (``pacing.pickup_until``).
"""

from __future__ import annotations

import time
from multiprocessing import shared_memory

import numpy as np
import numpy.typing as npt

from riderlive.devices.shared import attach as _attach

FloatArray = npt.NDArray[np.float64]
_HEADER = 8
_PENDING = 3
"""Header word: ``perf_counter`` ns of the input the writer is turning into a record (0: none)."""


class SharedRing:
    """A ring of fixed-width float64 records in one shared-memory segment."""

    def __init__(self, capacity: int, width: int, name: str | None = None) -> None:
        """Create a ring (``name`` None) or attach to the ring called ``name``."""
        if name is None:
            size = 8 * (_HEADER + capacity + capacity * width)
            self._shm = shared_memory.SharedMemory(create=True, size=size)
            self.owner = True
        else:
            self._shm = _attach(name)
            self.owner = False
        buf = self._shm.buf
        self._header: npt.NDArray[np.int64] = np.ndarray((_HEADER,), dtype=np.int64, buffer=buf)
        if self.owner:
            self._header[:] = 0
            self._header[1] = capacity
            self._header[2] = width
        self.capacity = int(self._header[1])
        self.width = int(self._header[2])
        self._seq: npt.NDArray[np.int64] = np.ndarray((self.capacity,), dtype=np.int64, buffer=buf, offset=8 * _HEADER)
        self._data: FloatArray = np.ndarray(
            (self.capacity, self.width), dtype=np.float64, buffer=buf, offset=8 * (_HEADER + self.capacity)
        )
        if self.owner:
            self._seq[:] = 0
        self.read_next = 0
        """Index of the next record this reader expects."""
        self.lapped = 0
        """Records this reader lost because the writer overwrote them first."""

    @property
    def name(self) -> str:
        return self._shm.name

    def mark_pending(self, received: float | None) -> None:
        """The writer: a record for the input received at ``received`` (``perf_counter`` seconds)
        is on its way; None: no longer (written, or not to be written)."""
        self._header[_PENDING] = 0 if received is None else max(1, int(received * 1e9))

    def pending(self) -> float:
        """``perf_counter`` seconds at which the input the writer is working on was received; -1: none."""
        ns = int(self._header[_PENDING])
        return ns * 1e-9 if ns > 0 else -1.0

    @property
    def head(self) -> int:
        """Records written so far."""
        return int(self._header[0])

    def write(self, record: FloatArray | list[float]) -> int:
        """Append one record (``width`` floats); return its index."""
        k = int(self._header[0])
        slot = k % self.capacity
        self._seq[slot] = 2 * k + 1
        self._data[slot] = record
        self._seq[slot] = 2 * k + 2
        self._header[0] = k + 1
        return k

    def read(self, k: int) -> FloatArray | None:
        """A copy of record ``k``, or None if it is not written yet or was overwritten."""
        slot = k % self.capacity
        want = 2 * k + 2
        if self._seq[slot] != want:
            return None
        copy: FloatArray = self._data[slot].copy()
        if self._seq[slot] != want:
            return None
        return copy

    def read_new(self, limit: int | None = None) -> list[FloatArray]:
        """Every record written since the last call (at most ``limit``, the newest)."""
        head = self.head
        start = self.read_next
        oldest = head - (self.capacity - 1)
        if limit is not None:
            oldest = max(oldest, head - limit)
        if start < oldest:
            self.lapped += oldest - start
            start = oldest
        out: list[FloatArray] = []
        for k in range(start, head):
            record = self.read(k)
            if record is None:
                self.lapped += 1
            else:
                out.append(record)
        self.read_next = head
        return out

    def latest(self) -> FloatArray | None:
        """The newest complete record, or None."""
        head = self.head
        return self.read(head - 1) if head > 0 else None

    def close(self) -> None:
        """Detach; the owner also removes the segment."""
        del self._header, self._seq, self._data
        self._shm.close()
        if self.owner:
            self._shm.unlink()


class SharedCounters:
    """Named float64 counters and histogram bins in shared memory (one writer)."""

    def __init__(self, names: tuple[str, ...], name: str | None = None) -> None:
        self.names = names
        self.index = {n: i for i, n in enumerate(names)}
        if name is None:
            self._shm = shared_memory.SharedMemory(create=True, size=8 * len(names))
            self.owner = True
        else:
            self._shm = _attach(name)
            self.owner = False
        self.values: FloatArray = np.ndarray((len(names),), dtype=np.float64, buffer=self._shm.buf)
        if self.owner:
            self.values[:] = 0.0

    @property
    def name(self) -> str:
        return self._shm.name

    def snapshot(self) -> dict[str, float]:
        values = self.values.copy()
        return {n: float(v) for n, v in zip(self.names, values, strict=True)}

    def close(self) -> None:
        del self.values
        self._shm.close()
        if self.owner:
            self._shm.unlink()


class SharedBlob:
    """The latest of a stream of byte strings (e.g. a JSON status), seqlock'd.

    Layout: ``int64 seq``, ``int64 length``, then ``size`` bytes. The writer never
    blocks; the reader gets the newest complete blob or None if it changed meanwhile.
    One writer at a time, in turn (the tick generations): a writer killed between its two
    stores leaves ``seq`` odd, and the next writer starts from the next even value (without
    that, every later blob was published with the parity inverted and read as "being
    written": the status of the generations after a kill mid-write never reached the web
    process, which showed the dead one's, a rig ``running`` after its fault).
    """

    def __init__(self, size: int = 65536, name: str | None = None) -> None:
        if name is None:
            self._shm = shared_memory.SharedMemory(create=True, size=16 + size)
            self.owner = True
        else:
            self._shm = _attach(name)
            self.owner = False
        self.size = self._shm.size - 16
        self._words: npt.NDArray[np.int64] = np.ndarray((2,), dtype=np.int64, buffer=self._shm.buf)
        if self.owner:
            self._words[:] = 0

    @property
    def name(self) -> str:
        return self._shm.name

    @property
    def version(self) -> int:
        """Blobs written so far."""
        return int(self._words[0]) // 2

    def write(self, data: bytes) -> None:
        if len(data) > self.size:
            raise ValueError(f"blob of {len(data)} bytes exceeds {self.size}")
        seq = int(self._words[0])
        seq += seq % 2  # odd: a writer died between its two stores (a tick killed mid-write): skip its blob
        self._words[0] = seq + 1
        buf = self._shm.buf
        assert buf is not None
        buf[16 : 16 + len(data)] = data
        self._words[1] = len(data)
        self._words[0] = seq + 2

    def read(self, attempts: int = 5) -> bytes | None:
        """The newest complete blob; None if none was written or every attempt met a write."""
        buf = self._shm.buf
        assert buf is not None
        for _ in range(attempts):
            seq = int(self._words[0])
            if seq == 0:
                return None
            if seq % 2 == 0:
                length = int(self._words[1])
                data = bytes(buf[16 : 16 + length])
                if int(self._words[0]) == seq:
                    return data
            time.sleep(0.0001)
        return None

    def close(self) -> None:
        del self._words
        self._shm.close()
        if self.owner:
            self._shm.unlink()
