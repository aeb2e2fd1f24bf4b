"""Counters of the web process and their Prometheus text rendering (``GET /metrics``)."""

from __future__ import annotations

from collections import Counter, OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

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


def _escape(value: str) -> str:
    return value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


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


def render(
    metrics: ServiceMetrics,
    tick: dict[str, float],
    clients: list[tuple[str, str, int, int, int]],
    producers: int,
    saddle_producers: int = 0,
    *,
    latency: Mapping[str, LatencySnapshot] | None = None,
) -> str:
    """Prometheus text exposition; ``clients`` are (id, path, sent, dropped, skipped); ``producers``
    counts every input connection, ``saddle_producers`` those of them on ``/ws/saddle``;
    ``latency``: snapshots of ``tick_lateness``, ``ingest_to_send``, ``ingest_to_wire`` (``Service.latency``)."""
    latency = latency or {}
    out: list[str] = []

    def metric(name: str, kind: str, help_text: str, lines: list[str]) -> None:
        out.append(f"# HELP {name} {help_text}")
        out.append(f"# TYPE {name} {kind}")
        out.extend(lines)

    for name, histogram, help_text in (
        ("riderlive_tick_lateness_seconds", latency.get("tick_lateness"), TICK_LATENESS),
        ("riderlive_ingest_to_send_seconds", latency.get("ingest_to_send"), INGEST_TO_SEND),
        ("riderlive_ingest_to_wire_seconds", latency.get("ingest_to_wire"), INGEST_TO_WIRE),
        ("riderlive_ingest_to_tick_seconds", latency.get("ingest_to_tick"), INGEST_TO_TICK),
    ):
        if histogram is not None:
            out.extend(histogram.prometheus(name, help_text))
    metric(
        "riderlive_tick_lateness_max_seconds",
        "gauge",
        "Worst tick lateness.",
        [f"riderlive_tick_lateness_max_seconds {tick.get('lateness_max', 0.0)}"],
    )
    for key, help_text in (
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
    ):
        metric(
            f"riderlive_tick_{key}_total", "counter", help_text, [f"riderlive_tick_{key}_total {int(tick.get(key, 0))}"]
        )
    metric(
        "riderlive_tick_realtime",
        "gauge",
        "1 when the tick runs at SCHED_FIFO.",
        [f"riderlive_tick_realtime {int(tick.get('realtime', 0))}"],
    )
    for key, help_text in PHASE_GAUGES:
        name = f"riderlive_tick_phase_{key}"
        metric(name, "gauge", help_text, [f"{name} {tick.get(f'phase_{key}', 0.0)}"])
    for key, help_text in PHASE_COUNTERS:
        name = f"riderlive_tick_phase_{key}_total"
        metric(name, "counter", help_text, [f"{name} {int(tick.get(f'phase_{key}', 0))}"])
    metric(
        "riderlive_clients_connected",
        "gauge",
        "Connected websocket clients.",
        [
            f'riderlive_clients_connected{{path="/ws/rider"}} {len(clients)}',
            f'riderlive_clients_connected{{path="/ws/horse"}} {producers - saddle_producers}',
            f'riderlive_clients_connected{{path="/ws/saddle"}} {saddle_producers}',
        ],
    )
    for key, help_text in SADDLE_COUNTERS:
        name = f"riderlive_saddle_{key}_total"
        metric(name, "counter", help_text, [f"{name} {int(tick.get(f'saddle_{key}', 0))}"])
    metric(
        "riderlive_input_clock_rate",
        "gauge",
        "The producer clock rate in use per input kind (engine s per producer s, 0.9-1.1; 0 before the first tick).",
        [f'riderlive_input_clock_rate{{kind="{kind}"}} {tick.get(key, 0.0)}' for kind, key in CLOCK_RATES],
    )
    metric(
        "riderlive_frames_out_total",
        "counter",
        "Frames sent per client.",
        [f'riderlive_frames_out_total{{client="{_escape(c)}"}} {sent}' for c, _, sent, _, _ in clients],
    )
    metric(
        "riderlive_frames_dropped_total",
        "counter",
        "Frames replaced in a slow client's slot.",
        [f'riderlive_frames_dropped_total{{client="{_escape(c)}"}} {dropped}' for c, _, _, dropped, _ in clients],
    )
    metric(
        "riderlive_frames_skipped_total",
        "counter",
        "Ticks a client's decimation wanted that never reached it (skipped by the tick, coalesced or missed).",
        [f'riderlive_frames_skipped_total{{client="{_escape(c)}"}} {skipped}' for c, _, _, _, skipped in clients],
    )
    metric(
        "riderlive_frames_in_total",
        "counter",
        "Horse frames accepted per producer.",
        [f'riderlive_frames_in_total{{producer="{_escape(p)}"}} {n}' for p, n in sorted(metrics.frames_in.items())],
    )
    metric(
        "riderlive_bad_frames_total",
        "counter",
        "Rejected messages by reason.",
        [f'riderlive_bad_frames_total{{reason="{_escape(r)}"}} {n}' for r, n in sorted(metrics.bad_frames.items())],
    )
    metric(
        "riderlive_rest_rejected_total",
        "counter",
        "REST requests answered 4xx, by status.",
        [f'riderlive_rest_rejected_total{{status="{c}"}} {n}' for c, n in sorted(metrics.rest_rejected.items())],
    )
    metric(
        "riderlive_clock_jumps_total",
        "counter",
        "Producer clock jumps, steps back, pauses and resumes (a new stream segment each), by direction.",
        [
            f'riderlive_clock_jumps_total{{direction="{e.direction}"}} {metrics.clock_jumps[e.direction]}'
            for e in ClockEvent
        ],
    )
    metric(
        "riderlive_clients_cut_off_total",
        "counter",
        "Clients closed after a send timeout.",
        [f"riderlive_clients_cut_off_total {metrics.clients_cut_off}"],
    )
    metric(
        "riderlive_ticks_coalesced_total",
        "counter",
        "Ticks not sent because the web process fell more than 0.25 s behind (publish.CATCH_UP).",
        [f"riderlive_ticks_coalesced_total {metrics.ticks_coalesced}"],
    )
    metric(
        "riderlive_timecode_errors_total",
        "counter",
        "Producer or stage timecodes unusable (malformed, another rate) or jumping, by reason.",
        [f'riderlive_timecode_errors_total{{reason="{_escape(r)}"}} {n}' for r, n in sorted(metrics.timecode.items())],
    )
    if metrics.vmc:
        metric(
            "riderlive_vmc_bundles_total",
            "counter",
            "VMC bundles by outcome (sent, dropped: send buffer full, error: send failed, skipped: a chosen tick "
            "that got none).",
            [
                f'riderlive_vmc_bundles_total{{outcome="{o}"}} {metrics.vmc[o]}'
                for o in ("sent", "dropped", "error", "skipped")
            ],
        )
    return "\n".join(out) + "\n"
