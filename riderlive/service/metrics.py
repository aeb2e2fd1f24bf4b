"""Counters of the web process and their Prometheus text rendering (``GET /metrics``)."""

from __future__ import annotations

from collections import Counter, OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from riderlive.prometheus import Exposition, Kind
from riderlive.realtime.latency import LatencyHistogram, LatencySnapshot
from riderlive.service.clocks import ClockEvent

TICK_LATENESS = "How late each tick started after its deadline."
INGEST_TO_SEND = "Horse frame received to the first rider frame computed from it written to every client due that tick."
INGEST_TO_WIRE = "Horse frame received to the first device goal computed from it handed to the device's port."
INGEST_TO_TICK = "Horse frame received to the deadline of the tick that took it (the wait the phase lock shortens)."
MAX_PRODUCER_LABELS = 32
"""Producer names with their own ``riderlive_frames_in_total`` series; older ones are added to ``other``."""
OTHER = "other"


@dataclass
class ServiceMetrics:
    """What the web process counts; per-client figures live on each client."""

    bad_frames: Counter[str] = field(default_factory=Counter)
    frames_in: OrderedDict[str, int] = field(default_factory=OrderedDict)
    """Accepted horse frames per producer name, least recently counted first (``count_frame_in``)."""
    rest_rejected: Counter[int] = field(default_factory=Counter)
    """REST answers 4xx, by status code."""
    clock_jumps: Counter[str] = field(default_factory=Counter)
    """Producer clock jumps by direction (``forward``, ``backward``): new stream segments."""
    ticks_published: int = 0
    ticks_coalesced: int = 0
    """Ticks not sent: the web process fell more than ``publish.CATCH_UP`` seconds behind."""
    clients_cut_off: int = 0
    ingest_to_send: LatencyHistogram = field(default_factory=LatencyHistogram)
    """Horse frame received (decoded) to the first rider frame computed from it written to every
    client due that tick (``Hub.publish``)."""
    timecode: Counter[str] = field(default_factory=Counter)
    """Unusable or jumping timecodes by reason (``service.timecodes``; docs/timecode.md)."""
    vmc: Counter[str] = field(default_factory=Counter)
    """VMC bundles by outcome: ``sent``, ``dropped`` (send buffer full), ``error`` (send failed),
    ``skipped`` (a chosen tick that got none)."""

    def count_disconnect(self, message: Mapping[str, Any]) -> None:
        """A websocket closed; uvicorn closes with 1009 a message beyond ``ws_max_size``: count it."""
        if message.get("code") == 1009:
            self.bad_frames["oversize"] += 1

    def count_frame_in(self, producer: str) -> None:
        """One accepted frame; the label set stays bounded however many names producers choose.

        The ``MAX_PRODUCER_LABELS`` most recently counted names keep their series; the
        least recently counted one gives its count to ``other`` when a new name comes.
        """
        frames_in = self.frames_in
        if producer in frames_in:
            frames_in.move_to_end(producer)
        elif len(frames_in) >= MAX_PRODUCER_LABELS + (OTHER in frames_in):
            oldest = next(name for name in frames_in if name != OTHER)
            frames_in[OTHER] = frames_in.get(OTHER, 0) + frames_in.pop(oldest)
        frames_in[producer] = frames_in.get(producer, 0) + 1


SADDLE_COUNTERS: tuple[tuple[str, str], ...] = (
    ("samples", "Saddle samples stepped through the estimator."),
    ("missing", "Saddle samples with an axis missing (left out of the frame): excluded from the fits, held."),
    ("empty", "Saddle samples ignored: no usable axis."),
    ("gaps", "Waits longer than 0.2 s between saddle samples (a 1 Hz stream: every sample)."),
    ("glitches", "Saddle samples dropped as a jump (tens of cm or degrees off the last)."),
    ("rebases", "Saddle jumps that stayed (a re-zeroed sensor): absorbed into an offset."),
    ("locks", "Saddle estimator locks gained (a gait, its frequency and phase)."),
    ("losses", "Saddle estimator locks let go (the hooves ease to standing)."),
    ("stale", "Driving saddle streams that stopped: the rider eased to neutral."),
)
"""The tick's ``saddle_*`` counters (``riderlive.realtime.saddle_input``), as ``riderlive_saddle_*_total``."""
CLOCK_RATES: tuple[tuple[str, str], ...] = (("horse", "input_clock_rate"), ("saddle", "saddle_clock_rate"))
"""``riderlive_input_clock_rate``'s ``kind`` label -> the tick's counter slot (``resample.ClockMap.rate``)."""

PHASE_GAUGES: tuple[tuple[str, str], ...] = (
    ("locked", "1 while the tick's deadlines are phase-locked to the driving producer's frames."),
    ("lead", "Seconds from the expected arrival of a frame to the deadline after it (-1: no phase known)."),
    ("margin", "Seconds of lead the phase lock aims at: tick.phase_margin or the arrival jitter (-1: none)."),
    ("resultant", "How regular the driving producer's arrival phase is: 1 steady, ~0 irregular or another rate."),
)
PHASE_COUNTERS: tuple[tuple[str, str], ...] = (
    ("slews", "Ticks whose deadlines the phase lock moved (by at most 2 % of a period each)."),
    ("locks", "Phase locks gained."),
    ("losses", "Phase locks let go (input stopped, irregular, another rate or producer); the phase is held."),
)
"""The tick's ``phase_*`` values (``riderlive.realtime.phase_lock``), as ``riderlive_tick_phase_*``."""


TICK_COUNTERS: tuple[tuple[str, str], ...] = (
    ("ticks", "Ticks run."),
    ("overruns", "Ticks that started more than one period late."),
    ("skipped", "Deadlines skipped after overruns."),
    ("input_frames", "Horse frames taken by the tick."),
    ("input_lapped", "Horse frames overwritten in the ring before the tick read them."),
    ("input_pickup_waits", "Ticks that waited (<= 0.3 ms) for a frame received before their deadline."),
    ("input_out_of_order", "Horse frames dropped by the tick as not newer than the last."),
    ("step_errors", "Ticks whose step raised (the last good frame was repeated)."),
    ("nonfinite_outputs", "Ticks whose rider had NaN or inf (the last good frame was repeated)."),
    ("physics_errors", "Tail physics restarts from rest after a failed or non-finite step."),
    ("physics_skipped_steps", "Tail physics steps skipped after a stall (time jumped instead)."),
    ("state_resets", "Stateful stages (smoothing, blends) reset after going non-finite (eased from neutral)."),
    ("outputs_clamped", "Rider values clamped to their plausible range."),
    ("hands_full_reach", "Ticks whose hands were at full reach, the reins outrunning them (reins.slip > 0)."),
)
"""The tick's counters, as ``riderlive_tick_*_total``."""
CLIENT_COUNTERS: tuple[tuple[str, str], ...] = (
    ("riderlive_frames_out_total", "Frames sent per client."),
    ("riderlive_frames_dropped_total", "Frames replaced in a slow client's slot."),
    (
        "riderlive_frames_skipped_total",
        "Ticks a client's decimation wanted that never reached it (skipped by the tick, coalesced or missed).",
    ),
)
"""Per-client counters, in the order of ``render``'s client tuples after (id, path)."""


def render(
    metrics: ServiceMetrics,
    tick: dict[str, float],
    clients: list[tuple[str, str, int, int, int]],
    producers: int,
    saddle_producers: int = 0,
    *,
    latency: Mapping[str, LatencySnapshot] | None = None,
    handovers: Mapping[str, int] | None = None,
) -> str:
    """Prometheus text exposition; ``clients`` are (id, path, sent, dropped, skipped); ``producers``
    counts every input connection, ``saddle_producers`` those of them on ``/ws/saddle``;
    ``latency``: snapshots of ``tick_lateness``, ``ingest_to_send``, ``ingest_to_wire`` (``Service.latency``);
    ``handovers``: changes of driver by reason (``arbiter.Handover``)."""
    latency = latency or {}
    out = Exposition()
    for name, histogram, help_text in (
        ("riderlive_tick_lateness_seconds", latency.get("tick_lateness"), TICK_LATENESS),
        ("riderlive_ingest_to_send_seconds", latency.get("ingest_to_send"), INGEST_TO_SEND),
        ("riderlive_ingest_to_wire_seconds", latency.get("ingest_to_wire"), INGEST_TO_WIRE),
        ("riderlive_ingest_to_tick_seconds", latency.get("ingest_to_tick"), INGEST_TO_TICK),
    ):
        if histogram is not None:
            out.family(name, Kind.HISTOGRAM, help_text, histogram.samples(name))
    out.one("riderlive_tick_lateness_max_seconds", Kind.GAUGE, "Worst tick lateness.", tick.get("lateness_max", 0.0))
    for key, help_text in TICK_COUNTERS:
        out.one(f"riderlive_tick_{key}_total", Kind.COUNTER, help_text, int(tick.get(key, 0)))
    out.one("riderlive_tick_realtime", Kind.GAUGE, "1 when the tick runs at SCHED_FIFO.", int(tick.get("realtime", 0)))
    for key, help_text in PHASE_GAUGES:
        out.one(f"riderlive_tick_phase_{key}", Kind.GAUGE, help_text, tick.get(f"phase_{key}", 0.0))
    for key, help_text in PHASE_COUNTERS:
        out.one(f"riderlive_tick_phase_{key}_total", Kind.COUNTER, help_text, int(tick.get(f"phase_{key}", 0)))
    connected = (
        ("/ws/rider", len(clients)),
        ("/ws/horse", producers - saddle_producers),
        ("/ws/saddle", saddle_producers),
    )
    out.by_label("riderlive_clients_connected", Kind.GAUGE, "Connected websocket clients.", "path", connected)
    if handovers is not None:
        out.by_label(
            "riderlive_arbiter_handovers_total",
            Kind.COUNTER,
            "Changes of the driving producer by reason (vacant, priority, silence: docs/protocol.md).",
            "reason",
            handovers.items(),
        )
    for key, help_text in SADDLE_COUNTERS:
        out.one(f"riderlive_saddle_{key}_total", Kind.COUNTER, help_text, int(tick.get(f"saddle_{key}", 0)))
    out.by_label(
        "riderlive_input_clock_rate",
        Kind.GAUGE,
        "The producer clock rate in use per input kind (engine s per producer s, 0.9-1.1; 0 before the first tick).",
        "kind",
        ((kind, tick.get(key, 0.0)) for kind, key in CLOCK_RATES),
    )
    ids = [c[0] for c in clients]
    per_client = ([c[2] for c in clients], [c[3] for c in clients], [c[4] for c in clients])
    for (name, help_text), counts in zip(CLIENT_COUNTERS, per_client, strict=True):
        out.by_label(name, Kind.COUNTER, help_text, "client", zip(ids, counts, strict=True))
    frames_in = sorted(metrics.frames_in.items())
    out.by_label(
        "riderlive_frames_in_total", Kind.COUNTER, "Horse frames accepted per producer.", "producer", frames_in
    )
    bad = sorted(metrics.bad_frames.items())
    out.by_label("riderlive_bad_frames_total", Kind.COUNTER, "Rejected messages by reason.", "reason", bad)
    rejected = sorted(metrics.rest_rejected.items())
    out.by_label(
        "riderlive_rest_rejected_total", Kind.COUNTER, "REST requests answered 4xx, by status.", "status", rejected
    )
    out.by_label(
        "riderlive_clock_jumps_total",
        Kind.COUNTER,
        "Producer clock jumps, steps back, pauses and resumes (a new stream segment each), by direction.",
        "direction",
        ((e.direction, metrics.clock_jumps[e.direction]) for e in ClockEvent),
    )
    out.one(
        "riderlive_clients_cut_off_total", Kind.COUNTER, "Clients closed after a send timeout.", metrics.clients_cut_off
    )
    out.one(
        "riderlive_ticks_coalesced_total",
        Kind.COUNTER,
        "Ticks not sent because the web process fell more than 0.25 s behind (publish.CATCH_UP).",
        metrics.ticks_coalesced,
    )
    out.by_label(
        "riderlive_timecode_errors_total",
        Kind.COUNTER,
        "Producer or stage timecodes unusable (malformed, another rate) or jumping, by reason.",
        "reason",
        sorted(metrics.timecode.items()),
    )
    if metrics.vmc:
        out.by_label(
            "riderlive_vmc_bundles_total",
            Kind.COUNTER,
            "VMC bundles by outcome (sent, dropped: send buffer full, error: send failed, skipped: a chosen tick "
            "that got none).",
            "outcome",
            ((o, metrics.vmc[o]) for o in ("sent", "dropped", "error", "skipped")),
        )
    return out.text()
