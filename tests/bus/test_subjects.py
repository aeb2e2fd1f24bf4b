"""The subject scheme and the [nats] config: pure, no broker."""

from __future__ import annotations

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from riderlive.bus.inbound import parse_payload
from riderlive.bus.subjects import VERSION, Kind, Stage, check_name, parse
from riderlive.configfile import ConfigError, validate
from riderlive.service.codecs import BadFrame
from riderlive.service.config import ServiceConfig

names = st.from_regex(r"[A-Za-z0-9_-]{1,64}", fullmatch=True)


@given(names, names, names)
def test_every_subject_parses_back_to_what_built_it(stage: str, rig: str, producer: str) -> None:
    subjects = Stage(stage).rig(rig)
    for kind in (Kind.FRAME, Kind.STATUS, Kind.CONTROL):
        parsed = parse(subjects.subject(kind))
        assert parsed is not None and (parsed.version, parsed.stage, parsed.rig, parsed.kind) == (
            VERSION,
            stage,
            rig,
            kind,
        )
    for kind, subject in ((Kind.HORSE, subjects.horse(producer)), (Kind.SADDLE, subjects.saddle(producer))):
        parsed_input = parse(subject)
        assert parsed_input is not None and parsed_input.known_version
        assert (parsed_input.rig, parsed_input.kind, parsed_input.producer) == (rig, kind, producer)
    for kind in (Kind.ESTOP, Kind.HEARTBEAT, Kind.DISCOVER):
        whole = parse(Stage(stage).subject(kind))
        assert whole is not None and whole.rig == "" and whole.kind == kind
    assert parse(Stage(stage).subject(Kind.ESTOP, "v7")).known_version is False  # type: ignore[union-attr]


@given(st.text(max_size=80))
@example("r1\n")  # `$` matches before a trailing newline: the case that passed once
def test_a_name_is_never_a_subject_fragment(text: str) -> None:
    try:
        check_name(text, "rig")
    except ValueError:
        return
    assert not any(c in text for c in ".*> \t\n") and 1 <= len(text) <= 64


def test_the_scheme_is_what_the_docs_say() -> None:
    stage = Stage("A")
    assert stage.rig("r1").subject(Kind.FRAME) == "riderlive.v1.A.r1.frame"
    assert stage.rig("r1").horse("mocap") == "riderlive.v1.A.r1.horse.mocap"
    assert stage.rig("r1").horse_any() == "riderlive.*.A.r1.horse.*"
    assert stage.rig("r1").saddle("imu") == "riderlive.v1.A.r1.saddle.imu"
    assert stage.rig("r1").saddle_any() == "riderlive.*.A.r1.saddle.*"
    assert parse("riderlive.v1.A.r1.saddle.imu.x") is None and parse("riderlive.v1.A.r1.frame.imu") is None
    with pytest.raises(ValueError, match="producer"):
        stage.rig("r1").saddle("a.b")
    assert stage.subject(Kind.ESTOP, "*") == "riderlive.*.A.estop"
    assert stage.every_rig(Kind.STATUS) == "riderlive.v1.A.*.status"
    assert parse("riderlive.v1.A.r1.horse.p.extra") is None and parse("other.v1.A.r1.frame") is None


def test_the_nats_section_is_validated_with_file_and_key() -> None:
    assert ServiceConfig().nats.url is None  # brokerless by default
    ok = validate(ServiceConfig, {"nats": {"url": "nats://h:4222,nats://g:4222", "rig": "r1"}}, "svc.toml")
    assert ok.nats.stage == "stage" and ok.nats.heartbeat_timeout == 1.0
    for bad, key in (
        ({"url": "nats://h:4222"}, "nats"),  # no rig name
        ({"url": "http://h", "rig": "r1"}, "nats.url"),
        ({"url": "nats://h:4222", "rig": "r.1"}, "nats.rig"),
        ({"stage": "a stage"}, "nats.stage"),
        ({"heartbeat_timeout": -1.0}, "nats.heartbeat_timeout"),
        ({"tls_cert": "c.pem"}, "nats"),
        ({"colour": "red"}, "nats.colour"),
    ):
        with pytest.raises(ConfigError) as info:
            validate(ServiceConfig, {"nats": bad}, "svc.toml")
        assert info.value.source == "svc.toml" and info.value.key == key, (bad, info.value)


@given(st.binary(max_size=300))
def test_any_payload_is_a_dict_or_a_counted_reason(data: bytes) -> None:
    try:
        assert isinstance(parse_payload(data, 256), dict)
    except BadFrame as exc:
        assert exc.reason in ("malformed", "oversize")


def test_payloads_json_or_msgpack_and_oversize() -> None:
    import msgpack

    assert parse_payload(b' {"t": 1}', 64) == {"t": 1}
    assert parse_payload(msgpack.packb({"t": 2}), 64) == {"t": 2}
    with pytest.raises(BadFrame, match="exceeds") as info:
        parse_payload(b"{" + b" " * 100 + b"}", 64)
    assert info.value.reason == "oversize"
