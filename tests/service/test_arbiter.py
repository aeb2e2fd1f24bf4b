"""Arbitration and ingest in process: the real Arbiter and IngestEndpoint.handle on a fake tick
port and a virtual clock (no server, no sleeps). The same rules over real websockets are in
tests/service/test_ingest.py's smoke tests."""

from __future__ import annotations

import math

import pytest

from riderlive.channels import HORSE_NAMES, SADDLE_NAMES
from riderlive.configfile import validate
from riderlive.realtime import commands as cmd
from riderlive.realtime.layout import InputKind
from riderlive.service.arbiter import HORSE_INPUT, SADDLE_INPUT, Handover, HandoverEvent, Producer, next_producer_id
from riderlive.service.codecs import BadFrame
from riderlive.service.config import ServiceConfig
from riderlive.service.ingest import IngestEndpoint
from tests.service.fakes import FakeService

TIMEOUT = 0.5  # input.producer_timeout's default


def setup(config: ServiceConfig | None = None) -> tuple[FakeService, IngestEndpoint, IngestEndpoint]:
    service = FakeService(config)
    ranges = service.config.ranges.ranges()
    return service, IngestEndpoint(service, ranges), IngestEndpoint(service, ranges, SADDLE_INPUT)


def join(service: FakeService, endpoint: IngestEndpoint, priority: int = 0) -> Producer:
    pid = next_producer_id()
    producer = Producer(id=pid, name=f"p{pid}", priority=priority, spec=endpoint.spec)
    service.arbiter.producers[pid] = producer
    return producer


def frame(t: float, **values: float) -> dict[str, object]:
    return {"t": t, "values": {k.replace("_", "."): v for k, v in values.items()}}


def test_the_incumbent_keeps_control_until_it_falls_silent() -> None:
    service, horse, _ = setup()
    clock = service.clock
    a, b = join(service, horse), join(service, horse)
    assert horse.handle(a, frame(0.0), clock.now) is True
    assert horse.handle(b, frame(0.0), clock.advance(0.01)) is False  # equal priority: a keeps it
    assert horse.handle(a, frame(0.02), clock.advance(0.01)) is True
    clock.advance(TIMEOUT - 1e-6)  # a silent for just under the timeout
    assert horse.handle(b, frame(0.1), clock.now) is False
    clock.advance(2e-6)  # ... and just over: b takes over at its next frame
    assert horse.handle(b, frame(0.2), clock.now) is True
    assert horse.handle(a, frame(0.6), clock.advance(0.001)) is False  # a is the one waiting now
    assert [p.producer for p in service.link.pushed] == [a.stream, a.stream, b.stream]


def test_a_higher_priority_takes_over_at_its_next_frame_and_a_lower_never() -> None:
    service, horse, saddle = setup()
    clock = service.clock
    low, high = join(service, horse, priority=0), join(service, saddle, priority=5)
    lower = join(service, horse, priority=-1)
    assert horse.handle(low, frame(0.0), clock.now) is True
    assert saddle.handle(high, frame(0.0), clock.advance(0.005)) is True  # a saddle competes like a horse
    assert horse.handle(low, frame(0.01), clock.advance(0.005)) is False
    clock.advance(10.0)  # everyone silent: the first to speak drives, whatever its priority
    assert horse.handle(lower, frame(10.0), clock.now) is True
    kinds = [p.kind for p in service.link.pushed]
    assert kinds == [InputKind.HORSE, InputKind.SADDLE, InputKind.HORSE]


def test_each_change_of_driver_is_counted_by_its_reason_and_the_last_is_kept() -> None:
    """docs/protocol.md "Several producers": who took over from whom, and why; a takeover by
    silence says how long the driver had been silent (virtual clock: exact)."""
    service, horse, _ = setup()
    clock, arbiter = service.clock, service.arbiter
    a, b, high = join(service, horse), join(service, horse), join(service, horse, priority=3)
    assert horse.handle(a, frame(0.0), clock.now) is True
    assert arbiter.last_handover == HandoverEvent(a.name, Handover.VACANT)
    horse.handle(b, frame(0.0), clock.advance(0.25))  # refused: a is live
    assert sum(arbiter.handovers.values()) == 1
    assert horse.handle(b, frame(0.1), clock.advance(0.375)) is True  # a silent 0.625 s > 0.5
    assert arbiter.last_handover == HandoverEvent(b.name, Handover.SILENCE, a.name, 0.625)
    assert horse.handle(high, frame(0.0), clock.advance(0.125)) is True
    assert arbiter.last_handover == HandoverEvent(high.name, Handover.PRIORITY, b.name)
    assert arbiter.remove(high.id) is True
    assert horse.handle(a, frame(1.0), clock.advance(0.125)) is True  # the driver left
    assert arbiter.last_handover == HandoverEvent(a.name, Handover.VACANT)
    assert arbiter.handovers == {Handover.VACANT: 2, Handover.SILENCE: 1, Handover.PRIORITY: 1}
    status = arbiter.status()
    assert status["handovers"] == {"vacant": 2, "priority": 1, "silence": 1}
    assert status["last_handover"] == {"to": a.name, "reason": "vacant", "previous": None, "silent_for": None}
    assert [p["name"] for p in status["producers"]] == [a.name, b.name] and status["active"] == a.id


def test_replay_and_procedural_selections() -> None:
    service, horse, _ = setup()
    clock = service.clock
    live, replay = join(service, horse), join(service, horse)
    arbiter = service.arbiter
    arbiter.selection, arbiter.replay_id = "replay", replay.id
    assert horse.handle(live, frame(0.0), clock.now) is False
    assert horse.handle(replay, frame(0.0), clock.advance(0.01)) is True
    arbiter.selection = "procedural"
    assert horse.handle(replay, frame(0.01), clock.advance(0.01)) is False
    assert horse.handle(live, frame(0.01), clock.now) is False
    assert live.accepted == 2 and replay.accepted == 2  # validated and counted all the same
    assert service.metrics.frames_in == {live.name: 2, replay.name: 2}
    assert len(service.link.pushed) == 1
    assert arbiter.remove(replay.id) is False  # not driving under procedural...
    arbiter.selection = "live"
    assert horse.handle(live, frame(0.02), clock.advance(0.01)) is True
    assert arbiter.remove(live.id) is True and arbiter.active is None  # ... the live one was


def test_a_frame_reaches_the_tick_in_service_units_stamped_in_engine_time() -> None:
    config = validate(ServiceConfig, {"tick": {"length_scale": 2.5}}, "test")  # decimetres
    service, horse, _ = setup(config)
    producer = join(service, horse)
    horse.hello(producer, {"length_scale": 25.0, "name": "mocap"})  # the producer speaks metres
    service.clock.advance(3.25)
    assert horse.handle(producer, frame(7.0, rearPivot_ty=0.05, rearPivot_rz=4.0), service.clock.now)
    (pushed,) = service.link.pushed
    assert pushed.t == 7.0 and pushed.received == pytest.approx(3.25)  # engine seconds
    values = dict(zip(HORSE_NAMES, pushed.values, strict=True))
    assert values["rearPivot.ty"] == pytest.approx(0.5) and values["rearPivot.rz"] == 4.0  # dm, deg
    assert service.metrics.frames_in == {"mocap": 1}
    # an omitted horse channel keeps its last value
    assert horse.handle(producer, frame(7.01, rearPivot_rz=5.0), service.clock.advance(0.01))
    assert dict(zip(HORSE_NAMES, service.link.pushed[-1].values, strict=True))["rearPivot.ty"] == pytest.approx(0.5)


def test_a_saddle_sample_leaves_what_it_omits_missing() -> None:
    service, _, saddle = setup()
    producer = join(service, saddle)
    assert saddle.handle(producer, frame(1.0, saddle_ty=0.02), service.clock.now)
    values = service.link.pushed[-1].values
    assert values[SADDLE_NAMES.index("saddle.ty")] == 0.02
    assert all(math.isnan(v) for i, v in enumerate(values) if i != SADDLE_NAMES.index("saddle.ty"))


def test_a_value_outside_its_range_rejects_the_whole_frame_and_nothing_reaches_the_tick() -> None:
    service, horse, _ = setup()
    producer = join(service, horse)
    with pytest.raises(BadFrame, match=r"rearPivot.ty = 50.0 is outside its plausible range \[-2, 2\]"):
        horse.handle(producer, frame(0.0, rearPivot_rz=3.0, rearPivot_ty=50.0), service.clock.now)
    assert service.link.pushed == [] and producer.accepted == 0
    assert producer.last == [0.0] * len(HORSE_NAMES)  # the good value of the bad frame is not kept either


def test_the_rate_limit_counts_a_virtual_second() -> None:
    config = validate(ServiceConfig, {"input": {"max_rate": 10.0}}, "test")
    service, horse, _ = setup(config)
    producer = join(service, horse)
    clock = service.clock
    for i in range(10):
        horse.handle(producer, frame(i * 0.01), clock.advance(0.01))
    with pytest.raises(BadFrame, match="more than 10 frames per second"):
        horse.handle(producer, frame(0.1), clock.advance(0.01))
    clock.advance(1.0)  # a new window
    assert horse.handle(producer, frame(1.2), clock.now) is True


def test_a_clock_jump_starts_a_new_stream_and_tells_the_producer() -> None:
    service, horse, _ = setup()
    producer = join(service, horse)
    clock = service.clock
    horse.handle(producer, frame(10.0), clock.now)
    first = producer.stream
    horse.handle(producer, frame(10.01), clock.advance(0.01))
    assert producer.stream == first and producer.outbox == []
    horse.handle(producer, frame(2.0), clock.advance(0.01))  # the producer's clock went back 8 s
    assert producer.stream != first and service.metrics.clock_jumps == {"backward": 1}
    (segment,) = producer.outbox
    assert segment["type"] == "segment" and segment["reason"] == "clock_backward"
    assert segment["jump"] == pytest.approx(-8.02)
    assert [p.producer for p in service.link.pushed] == [first, first, producer.stream]


def test_a_producer_gone_is_told_to_a_tick_that_is_up() -> None:
    service, horse, _ = setup()
    producer = join(service, horse)
    horse.handle(producer, frame(0.0), service.clock.now)
    if service.arbiter.remove(producer.id):  # what the endpoint does when the socket closes
        service.link.tell(cmd.ProducerGone(producer.stream))
    assert service.link.told == [cmd.ProducerGone(producer.stream)]


def test_hello_settings_are_checked() -> None:
    service, horse, _ = setup()
    producer = join(service, horse)
    for bad, reason in (
        ({"priority": 5000}, "wrong_type"),
        ({"priority": True}, "wrong_type"),
        ({"name": ""}, "wrong_type"),
        ({"length_scale": 0.0}, "out_of_range"),
        ({"length_scale": "25"}, "wrong_type"),
    ):
        with pytest.raises(BadFrame) as err:
            horse.handle(producer, {"type": "hello", **bad}, service.clock.now)
        assert err.value.reason == reason
    assert producer.priority == 0 and producer.length_gain == 1.0 and producer.name.startswith("p")
    assert HORSE_INPUT.kind is InputKind.HORSE
