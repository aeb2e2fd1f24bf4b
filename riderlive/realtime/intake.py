"""The tick's intake: each tick, the input ring's new records into the core (the "read
input" step of ``TickLoop.run``, docs/architecture.md), after waiting briefly for a frame
the web process is still writing."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from riderlive.realtime import layout as L
from riderlive.realtime.pacing import pickup_until

if TYPE_CHECKING:
    from riderlive.realtime.core import TickCore
    from riderlive.realtime.counters import TickCounters
    from riderlive.realtime.latency import LatencyHistogram
    from riderlive.realtime.output import TickDevices
    from riderlive.realtime.shm import SharedRing


@dataclass
class Intake:
    """Reads ``inputs`` into ``core``, counting in ``counter`` and ``ingest_to_tick`` (s);
    ``period``: the tick's (s), the longest a pending frame is waited for."""

    inputs: SharedRing
    core: TickCore
    counter: TickCounters
    ingest_to_tick: LatencyHistogram
    period: float
    arrivals: list[float] = field(default_factory=list)
    """Receive times of the driving producer's horse frames taken this tick (the phase lock's input)."""

    def read(self, now: float, deadline: float, devices: TickDevices | None) -> float:
        """Take the new input records into the core at engine time ``now`` (the tick's
        ``deadline``, ``perf_counter`` s); the newest receive time (-1: none)."""
        newest_rx = -1.0
        arrivals, counter, core = self.arrivals, self.counter, self.core
        arrivals.clear()
        self._await_pending(deadline, devices)
        for record in self.inputs.read_new():
            frame = L.InputRecord.of(record)
            switched = frame.producer != core.producer
            if core.push_record(frame):
                counter.input_frames += 1
                if switched:  # only the new driver's frames count for the phase lock
                    arrivals.clear()
                if frame.kind is L.InputKind.HORSE:
                    arrivals.append(frame.received)
            else:
                counter.input_out_of_order += 1
            newest_rx = max(newest_rx, frame.received)
        counter.input_lapped = self.inputs.lapped
        if newest_rx >= 0.0:
            self.ingest_to_tick.observe(now - newest_rx)
        return newest_rx

    def _await_pending(self, deadline: float, devices: TickDevices | None) -> None:
        """A frame the web process received before this deadline (``perf_counter`` seconds) and is
        still writing: spin until its record is in the ring, at most ``pacing.PICKUP_GRACE``.
        An e-stop requested meanwhile is acted on at once (as in the clock's spin)."""
        inputs = self.inputs
        received = inputs.pending()
        until = pickup_until(deadline, received, self.period)
        if until < 0.0:
            return
        self.counter.input_pickup_waits += 1
        while inputs.pending() == received and time.perf_counter() < until:
            if devices is not None and devices.stop_pending():
                devices.act_on_stop(time.perf_counter())
