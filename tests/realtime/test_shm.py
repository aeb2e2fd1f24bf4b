"""Shared-memory rings and blobs: order, lapping, torn-record detection, across processes."""

from __future__ import annotations

import multiprocessing

import numpy as np
import pytest

from riderlive.realtime.shm import SharedBlob, SharedCounters, SharedRing


def test_ring_reads_what_was_written_in_order() -> None:
    ring = SharedRing(8, 3)
    try:
        reader = SharedRing(0, 0, name=ring.name)
        for k in range(5):
            ring.write([k, k * 2.0, -k])
        got = reader.read_new()
        assert [r.tolist() for r in got] == [[k, k * 2.0, -k] for k in range(5)]
        assert reader.read_new() == []
        assert reader.latest().tolist() == [4.0, 8.0, -4.0]  # type: ignore[union-attr]
        reader.close()
    finally:
        ring.close()


def test_the_writer_notes_a_record_on_its_way_for_the_reader() -> None:
    ring = SharedRing(8, 3)
    try:
        reader = SharedRing(0, 0, name=ring.name)
        assert reader.pending() == -1.0
        ring.mark_pending(1234.567890123)
        assert reader.pending() == pytest.approx(1234.567890123, abs=1e-9)
        ring.write([1.0, 2.0, 3.0])
        ring.mark_pending(None)
        assert reader.pending() == -1.0
        assert [r.tolist() for r in reader.read_new()] == [[1.0, 2.0, 3.0]]
        reader.close()
    finally:
        ring.close()


def test_a_lapped_reader_counts_what_it_lost_and_gets_the_newest() -> None:
    ring = SharedRing(8, 1)
    try:
        for k in range(30):
            ring.write([k])
        got = ring.read_new()
        assert [int(r[0]) for r in got] == list(range(23, 30))
        assert ring.lapped == 23
        assert ring.read(5) is None, "overwritten records are refused, not returned wrong"
    finally:
        ring.close()


def test_a_record_being_written_is_not_read() -> None:
    ring = SharedRing(4, 2)
    try:
        ring.write([1.0, 1.0])
        ring._seq[1] = 2 * 1 + 1  # the writer is half-way through record 1
        ring._header[0] = 2
        assert ring.read(1) is None
    finally:
        ring.close()


def _child_writes(name: str, n: int) -> None:
    ring = SharedRing(0, 0, name=name)
    for k in range(n):
        ring.write(np.full(ring.width, float(k)))
    ring.close()


def test_across_a_spawned_process_no_torn_records() -> None:
    ring = SharedRing(64, 64)
    try:
        proc = multiprocessing.get_context("spawn").Process(target=_child_writes, args=(ring.name, 20000))
        proc.start()
        seen = 0
        while proc.is_alive() or ring.read_next < ring.head:
            for record in ring.read_new():
                assert np.all(record == record[0]), "a record is never a mix of two writes"
                seen += 1
        proc.join()
        assert seen + ring.lapped == 20000
    finally:
        ring.close()


def test_blob_and_counters() -> None:
    blob = SharedBlob(64)
    counters = SharedCounters(("a", "b"))
    try:
        assert blob.read() is None
        blob.write(b'{"x":1}')
        other = SharedBlob(name=blob.name)
        assert other.read() == b'{"x":1}' and other.version == 1
        with pytest.raises(ValueError):
            blob.write(b"x" * 65)
        counters.values[1] = 3.0
        assert SharedCounters(("a", "b"), name=counters.name).snapshot() == {"a": 0.0, "b": 3.0}
        other.close()
    finally:
        blob.close()
        counters.close()


def test_blob_after_a_writer_killed_mid_write() -> None:
    """A tick killed between a blob's two stores (``seq`` left odd): the next generation's
    blobs are read again, each in full. The old code wrote them with the parity inverted:
    every read gave None, and the web process kept showing the dead generation's status."""
    blob = SharedBlob(64)
    writer = SharedBlob(name=blob.name)  # the next generation attaches
    try:
        blob.write(b'{"state":"running"}')
        blob._words[0] += 1  # its next write began (seq odd) and the process died there
        assert blob.read(attempts=2) is None  # being written: nothing complete to read yet
        for n in range(3):
            data = b'{"state":"fault","n":%d}' % n
            writer.write(data)
            assert blob.read() == data
            assert int(blob._words[0]) % 2 == 0
    finally:
        writer.close()
        blob.close()
