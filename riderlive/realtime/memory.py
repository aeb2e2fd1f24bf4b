"""The shared memory a tick attaches to, created by the side that drives it.

:class:`TickMemory` holds every segment a :class:`~riderlive.realtime.tick.TickLoop` is
built on: the input and output rings, the counters, the latency histograms, the status
blob, the hand-over snapshot (optional), the e-stop latch and the safety board. The web
process's :class:`~riderlive.realtime.link.TickLink` creates it (it outlives any tick
process); so does ``riderlive rig --drive`` (``riderlive/rig_drive.py``), which runs the
same loop in its own process. :meth:`attach` names the segments in a
:class:`~riderlive.realtime.setup.TickSetup`: what the tick opens.
"""

from __future__ import annotations

import dataclasses

from riderlive.devices.board import SafetyBoard
from riderlive.devices.latch import StopLatch
from riderlive.realtime import handover, latency
from riderlive.realtime import layout as L
from riderlive.realtime.counters import COUNTERS
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.shm import SharedBlob, SharedCounters, SharedRing


class TickMemory:
    """The segments (created here, removed by :meth:`close`); ``width``: float64 slots of one
    output record (``RecordLayout.width``), ``output_capacity``: records the output ring
    holds, ``handover``: keep a hand-over blob (a warm spare takes over from it)."""

    def __init__(self, width: int, output_capacity: int = L.OUTPUT_CAPACITY, handover_blob: bool = True) -> None:
        self.inputs = SharedRing(L.INPUT_CAPACITY, L.INPUT_WIDTH)
        self.outputs = SharedRing(output_capacity, width)
        self.counters = SharedCounters(COUNTERS)
        self.histogram_block = SharedCounters(latency.slot_names(latency.TICK_HISTOGRAMS))
        self.histograms = latency.views(self.histogram_block.values, latency.TICK_HISTOGRAMS)
        """Filled by the tick: ``tick_lateness``, ``ingest_to_wire``, ``ingest_to_tick`` (``realtime.latency``)."""
        self.status_blob = SharedBlob()
        self.handover_blob = SharedBlob(handover.SNAPSHOT_BYTES) if handover_blob else None
        self.latch = StopLatch()
        self.board = SafetyBoard()

    def attach(self, setup: TickSetup) -> TickSetup:
        """``setup`` naming these segments: the tick it starts attaches to them."""
        names = {
            "input": self.inputs.name,
            "output": self.outputs.name,
            "counters": self.counters.name,
            "histograms": self.histogram_block.name,
            "status": self.status_blob.name,
        }
        if self.handover_blob is not None:
            names["handover"] = self.handover_blob.name
        return dataclasses.replace(setup, shm_names=names, latch_name=self.latch.name, board_name=self.board.name)

    def close(self) -> None:
        """Remove every segment (after the tick has detached)."""
        self.histograms.clear()
        for shared in (self.inputs, self.outputs, self.counters, self.histogram_block, self.status_blob):
            shared.close()
        if self.handover_blob is not None:
            self.handover_blob.close()
        self.latch.close()
        self.board.close()
